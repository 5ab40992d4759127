"""The noise a profile carries, on synthetic recordings of known noise: the Allan deviation of a
still recording (the core's standard slope fits), the residuals against a reference (the
power-law fit, with and without noise in the reference), the still-stretch finder, the choice and
its upper bounds, and Kalibr's imu.yaml."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from imu_learn.calib import noise as nz
from imu_learn.calib.kalibr import kalibr_yaml
from imu_learn.calib.profile import CLASS_DEFAULT_SOURCE, CLASS_DEFAULTS, NOISE_KEYS, NoiseTerm, Profile, noise_only
from imu_learn.calib.run import noise_terms
from imu_learn.data import synthetic as syn
from imu_learn.data.types import Segment

G = 9.81


def sensor_noise(n: int, rate: float, density: float, walk: float, rng) -> np.ndarray:
    """(n, 3) white noise of ``density`` [unit/sqrt(Hz)] plus a bias random walk of ``walk``
    [unit/s/sqrt(Hz)], sampled at ``rate``."""
    dt = 1.0 / rate
    white = rng.standard_normal((n, 3)) * density / math.sqrt(dt)
    bias = np.cumsum(rng.standard_normal((n, 3)) * walk * math.sqrt(dt), axis=0)
    return white + bias


def exact_imu(seg: Segment) -> Segment:
    """The IMU that the zero-order hold integrates exactly into ``seg``'s reference."""
    from imu_learn.core.quat import quat_conj, quat_log, quat_mul, quat_rotate

    dt = (np.diff(seg.t_ns) * 1e-9)[:, None]
    w = quat_log(quat_mul(quat_conj(seg.q_wxyz[:-1]), seg.q_wxyz[1:])) / dt
    a = quat_rotate(quat_conj(seg.q_wxyz[:-1]), np.diff(seg.v, axis=0) / dt - np.array([0.0, 0.0, -G]))
    w, a = np.vstack([w, w[-1:]]), np.vstack([a, a[-1:]])
    return Segment(seg.name, seg.t_ns, w, a, seg.p, seg.v, seg.q_wxyz)


# -- Allan deviation of a still recording: the core's slope fits ------------------------------------

@pytest.fixture(scope="module")
def still_hour():
    rng = np.random.default_rng(7)
    rate, n = 100.0, 360_000  # one hour
    t = 10**18 + np.arange(n, dtype=np.int64) * 10_000_000
    gyro = sensor_noise(n, rate, 1e-3, 1e-4, rng) + np.array([0.01, -0.02, 0.003])
    acc = sensor_noise(n, rate, 2e-2, 1e-3, rng) + np.array([0.0, 0.0, G])
    return t, gyro, acc


def test_allan_of_a_still_hour_recovers_density_and_random_walk(still_hour):
    t, gyro, acc = still_hour
    an = nz.allan_noise([("still", t, gyro, acc)])
    assert an is not None and an.seconds == pytest.approx(3600, abs=1)
    f = an.fit
    np.testing.assert_allclose(f.white.value[:3], 1e-3, rtol=0.10)
    np.testing.assert_allclose(f.white.value[3:], 2e-2, rtol=0.10)
    np.testing.assert_allclose(f.random_walk.value[:3], 1e-4, rtol=0.35)
    np.testing.assert_allclose(f.random_walk.value[3:], 1e-3, rtol=0.35)
    cands = nz.candidates(None, an, min_still_s=10.0)
    chosen = nz.choose(cands, NOISE_KEYS)
    est, value, std = chosen["gyroscope_noise_density"]
    assert est.source == "allan" and est.kind == "standard slope fit"
    assert value == pytest.approx(1e-3, rel=0.10) and 0 < std < 0.1 * value
    assert chosen["accelerometer_random_walk"][1] == pytest.approx(1e-3, rel=0.35)


def test_still_stretches_are_found_between_motions():
    rng = np.random.default_rng(3)
    rate, n = 200.0, 200 * 60
    t = 10**18 + np.arange(n, dtype=np.int64) * 5_000_000
    gyro = rng.standard_normal((n, 3)) * 1e-3 * math.sqrt(rate)
    acc = rng.standard_normal((n, 3)) * 2e-3 * math.sqrt(rate) + [0, 0, G]
    moving = np.zeros(n, bool)
    moving[4000:8000] = True  # 20 s..40 s: a swinging motion
    tt = np.arange(n) / rate
    gyro[moving] += np.sin(2 * np.pi * 0.7 * tt[moving])[:, None] * [1.0, 0.5, 0.2]
    acc[moving] += np.cos(2 * np.pi * 1.3 * tt[moving])[:, None] * [2.0, 1.0, 0.5]
    got = nz.still_stretches(t, gyro, acc)
    assert len(got) == 2
    (a0, a1), (b0, b1) = got
    assert a0 <= 50 and 3700 <= a1 <= 4000 and 8000 <= b0 <= 8300 and b1 >= n - 50  # 0.25 s trimmed


# -- residuals against a reference: the power-law fit ------------------------------------------------

@pytest.fixture(scope="module")
def moving_reference():
    return exact_imu(syn.moving(600.0))


@pytest.mark.parametrize("ref_noise", [0.0, 2e-4])
def test_residuals_recover_density_and_random_walk(moving_reference, ref_noise):
    """A moving recording of known noise against its exact reference (and against a reference whose
    attitude and velocity carry their own white noise): the residuals' power-law fit."""
    rng = np.random.default_rng(11)
    s = moving_reference
    n = len(s)
    gyro = s.gyro + sensor_noise(n, 200.0, 2e-3, 5e-4, rng) + [0.02, -0.01, 0.005]
    acc = s.acc + sensor_noise(n, 200.0, 2e-2, 5e-3, rng) + [0.1, 0.0, -0.05]
    q, v = s.q_wxyz, s.v
    if ref_noise:
        r = rng.standard_normal((n, 3)) * ref_noise  # a small rotation of each reference attitude
        half = np.linalg.norm(r, axis=1, keepdims=True) / 2
        q = syn.qmul(q, np.hstack([np.cos(half), np.sin(half) * r / (2 * half)]))
        v = v + rng.standard_normal((n, 3)) * ref_noise * 10
    ref = Segment("m", s.t_ns, s.gyro, s.acc, s.p, v, q)
    r = nz.residual_noise([ref], [(gyro, acc)], G)
    np.testing.assert_allclose(r.gyro.white, 2e-3, rtol=0.15)
    np.testing.assert_allclose(r.acc.white, 2e-2, rtol=0.15)
    np.testing.assert_allclose(r.gyro.random_walk, 5e-4, rtol=0.5)
    np.testing.assert_allclose(r.acc.random_walk, 5e-3, rtol=0.5)
    assert np.all(r.gyro.white_std < 0.2 * r.gyro.white)
    if ref_noise:  # the reference's own error goes to the τ^-2 term, not to the density
        assert np.all(np.isfinite(r.gyro.reference)) and np.all(np.isfinite(r.acc.reference))
    chosen = nz.choose(nz.candidates(r, None, 10.0), NOISE_KEYS)
    for key in NOISE_KEYS:
        assert chosen[key][0].source == "residuals" and chosen[key][0].kind == "fit", key


def test_upper_bounds_hold_and_are_used_when_nothing_is_observed():
    """White noise alone (no random walk in it): the random walk is an upper bound above zero, and
    the density's bound is above the density."""
    rng = np.random.default_rng(5)
    n = 20_000
    t = 10**18 + np.arange(n, dtype=np.int64) * 5_000_000
    gyro = rng.standard_normal((n, 3)) * 1e-3 * math.sqrt(200.0)
    acc = rng.standard_normal((n, 3)) * 1e-2 * math.sqrt(200.0) + [0, 0, G]
    an = nz.allan_noise([("still", t, gyro, acc)])
    assert np.all(nz.upper_bound(an.dev, 1.0, slice(0, 3)) >= 0.97e-3)  # tight here: white noise is on its line everywhere
    chosen = nz.choose(nz.candidates(None, an, 10.0), NOISE_KEYS)
    est, value, std = chosen["gyroscope_random_walk"]
    assert est.kind == "upper bound" and value > 0 and math.isnan(std)
    assert chosen["gyroscope_noise_density"][1] == pytest.approx(1e-3, rel=0.15)


def test_an_unobserved_random_walk_is_written_as_the_class_default_with_its_bound_beside(tmp_path):
    """profile.json never holds a bound as a value: the unobserved random walks' value is the device-class
    default, the bound the data gave sits in detail.upper_bound; read back (and from a profile written
    before, whose value was the bound), imu.yaml and navigate get the class default."""
    rng = np.random.default_rng(5)
    n = 20_000
    t = 10**18 + np.arange(n, dtype=np.int64) * 5_000_000
    gyro = rng.standard_normal((n, 3)) * 1e-3 * math.sqrt(200.0)
    acc = rng.standard_normal((n, 3)) * 1e-2 * math.sqrt(200.0) + [0, 0, G]
    chosen = nz.choose(nz.candidates(None, nz.allan_noise([("still", t, gyro, acc)]), 10.0), NOISE_KEYS)
    bound = chosen["gyroscope_random_walk"][1]
    terms = noise_terms(chosen)
    rw = terms["gyroscope_random_walk"]
    assert rw.value == CLASS_DEFAULTS["gyroscope_random_walk"] != bound and rw.source == "class_default"
    assert rw.bound == pytest.approx(bound) and rw.bounded_only and np.isnan(rw.per_axis).all()
    assert not terms["gyroscope_noise_density"].bounded_only  # observed: its own value
    prof = noise_only("my-imu", 200.0, terms)
    prof.save(tmp_path / "profile.json")
    back = Profile.load(tmp_path / "profile.json")
    assert back.noise["gyroscope_random_walk"].bound == pytest.approx(bound)
    assert back.kalibr()["gyroscope_random_walk"] == CLASS_DEFAULTS["gyroscope_random_walk"]
    assert f"upper bound {bound:.4e}" in kalibr_yaml(back)
    old = dict(terms, gyroscope_random_walk=NoiseTerm(np.full(3, bound), bound, math.nan, rw.unit, "allan",
                                                      {"kind": "upper bound"}))
    assert noise_only("my-imu", 200.0, old).kalibr()["gyroscope_random_walk"] == CLASS_DEFAULTS["gyroscope_random_walk"]


def test_a_bound_below_the_class_default_is_the_value(tmp_path):
    """Where the data bound an unobserved figure below the class default, the default would contradict
    them: the value is the bound (BROAD's accelerometer random walk: 7.7e-4 against 3e-3); a bound above
    the default never is (the test above)."""
    from imu_learn.calib.profile import unobserved_term

    d = CLASS_DEFAULTS["accelerometer_random_walk"]
    low = unobserved_term("accelerometer_random_walk", np.full(3, 0.25 * d), 0.25 * d, "allan", {})
    high = unobserved_term("accelerometer_random_walk", np.full(3, 4 * d), 4 * d, "allan", {})
    assert low.value == pytest.approx(0.25 * d) and low.bounded_only and "upper bound" in low.detail["value_from"]
    assert high.value == d
    prof = noise_only("my-imu", 200.0, {"accelerometer_random_walk": low})
    prof.save(tmp_path / "profile.json")
    back = Profile.load(tmp_path / "profile.json")
    assert back.kalibr()["accelerometer_random_walk"] == pytest.approx(0.25 * d)
    assert f"below the {CLASS_DEFAULT_SOURCE}" in kalibr_yaml(back)


# -- Kalibr's imu.yaml -------------------------------------------------------------------------------

def test_imu_yaml_parses_and_has_kalibrs_keys():
    noise = {k: NoiseTerm(np.array([1e-4, 2e-4, 3e-4]), 2.2e-4, 1e-5, "u", "allan", {"kind": "standard slope fit"})
             for k in NOISE_KEYS[:3]}
    text = kalibr_yaml(noise_only("my-imu", 200.0, noise))
    d = yaml.safe_load(text)
    assert set(d) == {*NOISE_KEYS, "rostopic", "update_rate"}
    assert d["gyroscope_noise_density"] == pytest.approx(2.2e-4) and d["update_rate"] == 200.0
    # not measured: the device-class default, said in its comment (a .nan stopped Kalibr's readers)
    assert d["accelerometer_random_walk"] == CLASS_DEFAULTS["accelerometer_random_walk"]
    assert "not measured (no reference, no still stretch)" in text and d["rostopic"] == "/imu0"


def test_a_residual_white_noise_the_imus_own_samples_do_not_allow_is_the_references(moving_reference):
    """The density the IMU's own samples allow (second differences) recovers a moving IMU's white noise; a
    residual fit far above it (TUM-VI: the motion capture's noise, 8e-3 rad/s/sqrt(Hz) where the BMI160's
    samples allow 1e-4) is a bound, and the profile holds the class default with the reason."""
    rng = np.random.default_rng(3)
    s = moving_reference
    gyro = s.gyro + sensor_noise(len(s), 200.0, 2e-3, 0.0, rng)
    own = nz.own_density([s.t_ns], [gyro])
    np.testing.assert_allclose(own, 2e-3, rtol=0.15)
    r = nz.residual_noise([s], [(gyro, s.acc + sensor_noise(len(s), 200.0, 2e-2, 0.0, rng))], G)
    kept = nz.choose(nz.candidates(r, None, 10.0), NOISE_KEYS)["gyroscope_noise_density"][0]
    assert kept.kind == "fit"  # the residuals' density is the IMU's own: kept
    quiet = replace(r, gyro_own=r.gyro.white / (2 * nz.OWN_MARGIN))  # an IMU whose samples are far quieter
    chosen = nz.choose(nz.candidates(quiet, None, 10.0), NOISE_KEYS)
    est, value, _ = chosen["gyroscope_noise_density"]
    assert est.kind == "upper bound" and "reference's noise" in est.detail["why"]
    term = noise_terms(chosen)["gyroscope_noise_density"]
    assert term.value == CLASS_DEFAULTS["gyroscope_noise_density"] and term.source == "class_default"
    assert term.bound == pytest.approx(value) and term.bounded_only
    assert chosen["accelerometer_noise_density"][0].kind == "fit"  # each sensor judged on its own samples


def test_a_reference_below_the_imus_band_bounds_the_residual_white_noise(moving_reference):
    """A reference smoothed below the IMU's rate (a positions reference's keyframes, a 20 Hz VO, wheel
    odometry: :meth:`Source.band_limit`) leaves the motion above its band in the residuals: their white noise
    is a bound whatever the IMU's own samples allow, and the profile holds the class default with the
    source's reason (the car drive's positions profile wrote acc 0.037 m/s^2/sqrt(Hz), 2.4x what the
    navigator's innovations fit in motion). The same residuals against a reference that resolves the band: a fit."""
    rng = np.random.default_rng(4)
    s = moving_reference
    gyro = s.gyro + sensor_noise(len(s), 200.0, 2e-3, 0.0, rng)
    r = nz.residual_noise([s], [(gyro, s.acc + sensor_noise(len(s), 200.0, 2e-2, 0.0, rng))], G)
    assert all(nz.choose(nz.candidates(r, None, 10.0), NOISE_KEYS)[k][0].kind == "fit"
               for k in ("gyroscope_noise_density", "accelerometer_noise_density"))
    why = "a positions reference: its motion is the navigator's smoothed keyframes (10 Hz)"
    chosen = nz.choose(nz.candidates(r, None, 10.0, band_limit=why), NOISE_KEYS)
    terms = noise_terms(chosen)
    for key in ("gyroscope_noise_density", "accelerometer_noise_density"):
        est = chosen[key][0]
        assert est.kind == "upper bound" and est.detail["why"] == why
        assert terms[key].value == CLASS_DEFAULTS[key] and terms[key].bounded_only
    assert chosen["gyroscope_random_walk"][0].source == "residuals"  # the long-τ terms are not the band's


def test_each_reference_source_says_whether_its_residuals_resolve_the_imus_band():
    from imu_learn.calib.odometry import OdometrySource
    from imu_learn.calib.sources import Source
    from imu_learn.fuse.calibrate_positions import PositionsSource

    assert Source().band_limit() is None  # a reference as given (motion capture)
    assert "keyframes (10 Hz)" in PositionsSource(Path("imu.csv"), Path("rover.pos")).band_limit()
    assert "wheel odometry" in OdometrySource([Path("a")], [Path("b")]).band_limit()
