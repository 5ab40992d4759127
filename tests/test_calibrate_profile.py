"""The device profile: JSON round trip, typed errors naming the file and field, and ``apply`` giving
the model its conventions document (checked against :func:`documented_floor`, written here in plain
numpy from calib/profile.py's module doc) and exactly what ``traditional+timing``'s ``refine``
gives (bit for bit)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from imu_learn.calib.profile import Affine, NoiseTerm, Profile, noise_only
from imu_learn.data import synthetic as syn
from imu_learn.data.types import Segment
from imu_learn.errors import ProfileError


def documented_floor(prof: Profile, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray):
    """The oracle: ``prof``'s floor from the documented conventions alone, not the package's code.
    corrected(t) = recorded(t + time_offset_s) by linear interpolation (ends held); then
    w = M_g (LP_g(w_m) - b_g) - G LP_g(a_m) and a = M_a (LP_a(a_m) - b_a) with M, b, G the profile's
    ``gyroscope``/``accelerometer``/``g_sensitivity`` entries, LP a zero-phase Butterworth low-pass of
    the floor's cut-offs (transfer-function form and scipy's ``filtfilt``, not the package's sos)."""
    from scipy.signal import butter, filtfilt

    fl = prof.floor
    ts = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    fs = 1.0 / np.median(np.diff(ts))

    def shifted(x):
        return np.stack([np.interp(ts + prof.time_offset_s, ts, x[:, i]) for i in range(3)], axis=1)

    def lp(x, cutoff):
        if cutoff is None:
            return x
        b, a = butter(int(fl.get("filter_order", 2)), cutoff / (fs / 2))
        return filtfilt(b, a, x, axis=0)

    w_m, a_m = shifted(np.asarray(gyro, dtype=np.float64)), shifted(np.asarray(acc, dtype=np.float64))
    M_g, b_g, G = prof.gyro.matrix, prof.gyro.bias, prof.g_sensitivity
    M_a, b_a = prof.acc.matrix, prof.acc.bias
    w = np.array([M_g @ (wi - b_g) - G @ ai for wi, ai in zip(lp(w_m, fl["cutoff_gyro"]), lp(a_m, fl["cutoff_gyro"]))])
    a = np.array([M_a @ (ai - b_a) for ai in lp(a_m, fl["cutoff_acc"])])
    return w, a


def assert_documented(prof: Profile, t_ns, gyro, acc, g, a, atol: float = 1e-9) -> None:
    """(g, a) is what the conventions give for ``prof`` on the raw (gyro, acc), to ``atol``."""
    want_g, want_a = documented_floor(prof, t_ns, gyro, acc)
    assert np.abs(g - want_g).max() < atol, np.abs(g - want_g).max()
    assert np.abs(a - want_a).max() < atol, np.abs(a - want_a).max()


def floor_method(seed: int = 0, tau: float = 0.37, cutoffs=(20.0, 10.0)):
    from imu_learn.baselines.traditional import TraditionalTiming

    rng = np.random.default_rng(seed)
    m = TraditionalTiming()
    p = m.params
    p.M_g = np.eye(3) + 0.01 * rng.standard_normal((3, 3))
    p.b_g = 0.01 * rng.standard_normal(3)
    p.G = 1e-3 * rng.standard_normal((3, 3))
    p.M_a = np.eye(3) + 0.01 * rng.standard_normal((3, 3))
    p.b_a = 0.1 * rng.standard_normal(3)
    p.cutoff_gyro, p.cutoff_acc = cutoffs
    p.time_offset = tau
    return m


def noisy_spin(seed: int = 1) -> Segment:
    rng = np.random.default_rng(seed)
    s = syn.spin(6.0)
    return Segment(s.name, s.t_ns, s.gyro + 0.01 * rng.standard_normal(s.gyro.shape),
                   s.acc + 0.1 * rng.standard_normal(s.acc.shape), s.p, s.v, s.q_wxyz)


def make_profile(floor: dict) -> Profile:
    nan3 = np.full(3, np.nan)
    return Profile(
        device="test-imu", sample_rate_hz=200.0, time_offset_s=floor["time_offset"] / 200, time_offset_s_std=1e-4,
        gyro=Affine(np.asarray(floor["M_g"]), np.asarray(floor["b_g"]), "rad/s", np.full((3, 3), 1e-4), nan3.copy()),
        acc=Affine(np.asarray(floor["M_a"]), np.asarray(floor["b_a"]), "m/s^2"),
        g_sensitivity=np.asarray(floor["G"]), gravity_mps2=9.81, gravity_mps2_std=math.nan, floor=floor,
        noise={"gyroscope_noise_density": NoiseTerm(np.array([1e-4, 2e-4, np.nan]), 1.6e-4, 2e-5, "rad/s/sqrt(Hz)",
                                                    "residuals", {"tau_s": [0.01, 1.0]})},
        sources=[{"recording": "spin", "span_s": [0.0, 6.0]}],
        unobservable=[{"what": "accelerometer_random_walk", "why": "too short"}],
    )


@pytest.mark.parametrize("tau,cutoffs", [(0.37, (20.0, 10.0)), (0.0, (None, None)), (-1.2, (40.0, None))])
def test_apply_is_the_floor_bit_for_bit(tau, cutoffs, tmp_path):
    """``apply`` is the documented model (the numpy oracle above: a transposed matrix, a negated
    offset or a swapped cut-off fails it), and the same bits as the floor's ``refine``."""
    m = floor_method(tau=tau, cutoffs=cutoffs)
    s = noisy_spin()
    want_g, want_a = m.refine(s)
    prof = make_profile(m.to_dict())
    prof.save(tmp_path / "profile.json")
    back = Profile.load(tmp_path / "profile.json")  # through JSON: float64 survives repr exactly
    for p in (prof, back):
        g, a = p.apply(s.t_ns, s.gyro, s.acc)
        assert_documented(p, s.t_ns, s.gyro, s.acc, g, a)
        assert np.array_equal(g, want_g) and np.array_equal(a, want_a)
    assert np.abs(g - s.gyro).max() > 1e-3 and np.abs(a - s.acc).max() > 1e-2  # the floor does something


def test_round_trip_keeps_every_field(tmp_path):
    prof = make_profile(floor_method().to_dict())
    prof.save(tmp_path / "p.json")
    back = Profile.load(tmp_path / "p.json")
    assert back.to_dict() == json.loads(json.dumps(prof.to_dict()))
    assert back.device == "test-imu" and back.noise["gyroscope_noise_density"].source == "residuals"
    assert np.isnan(back.noise["gyroscope_noise_density"].per_axis[2])
    assert np.isnan(back.gyro.bias_std).all() and back.gyro.matrix_std[0, 0] == 1e-4
    assert back.kalibr()["gyroscope_noise_density"] == 1.6e-4 and back.kalibr()["accelerometer_random_walk"] is None
    d = json.loads((tmp_path / "p.json").read_text())
    assert d["conventions"]["quaternion"].startswith("Hamilton") and d["format"] == "imu-learn device profile"


def test_noise_only_profile_applies_nothing(tmp_path):
    p = noise_only("still", 100.0, {})
    p.save(tmp_path / "p.json")
    back = Profile.load(tmp_path / "p.json")
    s = noisy_spin()
    g, a = back.apply(s.t_ns, s.gyro, s.acc)
    assert not back.has_floor and np.array_equal(g, s.gyro) and np.array_equal(a, s.acc)


def edit(tmp_path, change) -> str:
    d = make_profile(floor_method().to_dict()).to_dict()
    change(d)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(d))
    return str(path)


@pytest.mark.parametrize("change,field", [
    (lambda d: d.pop("sample_rate_hz"), "sample_rate_hz"),
    (lambda d: d.update(sample_rate_hz="fast"), "sample_rate_hz"),
    (lambda d: d["gyroscope"].update(matrix=[[1, 0], [0, 1]]), "gyroscope.matrix"),
    (lambda d: d["accelerometer"].pop("bias"), "accelerometer.bias"),
    (lambda d: d["floor"].update(method="traditional"), "floor.method"),
    (lambda d: d["floor"].update(M_g="eye"), "floor.M_g"),
    (lambda d: d["floor"].update(cutoff_acc=-3), "floor.cutoff_acc"),
    (lambda d: d["noise"]["gyroscope_noise_density"].update(source="guess"), "noise.gyroscope_noise_density.source"),
    (lambda d: d.update(version=99), "version"),
    (lambda d: d.update(format="something else"), "format"),
])
def test_bad_profile_names_file_and_field(tmp_path, change, field):
    path = edit(tmp_path, change)
    with pytest.raises(ProfileError) as e:
        Profile.load(path)
    assert e.value.field == field and e.value.path == path
    assert path in str(e.value) and field.split(".")[-1] in str(e.value)


def test_not_json_and_missing_file(tmp_path):
    bad = tmp_path / "x.json"
    bad.write_text("{not json")
    with pytest.raises(ProfileError, match="x.json:1: not JSON"):
        Profile.load(bad)
    with pytest.raises(FileNotFoundError):
        Profile.load(tmp_path / "absent.json")
