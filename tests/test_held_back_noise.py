"""The held-back check against the block's own noise (calib.plausible, calib.run.plausibility): a
profile whose fitted gyroscope terms raise the held-back rotation error by less than the noise of a
noisy reference can tell is written with those terms at their prior (identity, zero bias) and says
so; one that raises it beyond that noise is refused. Synthetic device with an exact IMU (so the raw
IMU is the right answer), its held-back reference's attitude noisy as a VO's."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_learn.baselines.affine import Floor, TraditionalParams
from imu_learn.calib import plausible as pl
from imu_learn.core.quat import quat_mul
from imu_learn.data.types import Segment
from imu_learn.errors import ImplausibleProfileError

pytest.importorskip("torch")
from imu_learn.calib.profile import Profile  # noqa: E402
from imu_learn.calib.run import CalibInputs, CalibOptions, plausibility  # noqa: E402
from test_profile_select import BIAS_A, BIAS_G, SETTINGS, device  # noqa: E402  (calib.select: torch)

REF_NOISE_RAD = math.radians(0.3)  # per pose, white, each axis


def noisy_attitude(s: Segment, rng: np.random.Generator) -> Segment:
    v = rng.normal(scale=REF_NOISE_RAD / 2, size=(len(s), 3))  # half-angle vector: small rotations
    dq = np.column_stack([np.sqrt(1 - (v ** 2).sum(1)), v])
    return Segment(s.name, s.t_ns, s.gyro, s.acc, s.p, s.v, quat_mul(s.q_wxyz, dq))


@pytest.fixture(scope="module")
def inputs() -> CalibInputs:
    """The bias-only synthetic device with its biases taken out (the raw IMU exact up to white noise),
    the held-back blocks' attitude noisy."""
    train, val, groups, val_groups = device(False)
    rng = np.random.default_rng(7)
    exact = [Segment(s.name, s.t_ns, s.gyro - BIAS_G, s.acc - BIAS_A, s.p, s.v, s.q_wxyz) for s in train + val]
    train, val = exact[:len(train)], [noisy_attitude(s, rng) for s in exact[len(train):]]
    return CalibInputs(train, val, groups, val_groups, settings=SETTINGS, device="synthetic")


def profile_with_gyro_bias(b_g: np.ndarray) -> Profile:
    floor = Floor(TraditionalParams.biases(b_g, np.zeros(3)))
    return Profile.of_floor("synthetic", 200.0, 0.005, floor, TraditionalParams.unknown(), 9.81, math.nan)


def test_a_raise_within_the_blocks_noise_keeps_the_gyroscope_at_its_prior(inputs):
    prof = profile_with_gyro_bias(np.full(3, 2.5e-3) * [1, -1, 1])  # 0.25 deg over the 1 s window
    checks = plausibility(prof, inputs, CalibOptions(), lambda s: None)
    [kept] = checks["kept_at_prior"]
    assert kept["sensor"] == "gyroscope" and "within the block's noise" in kept["why"]
    assert np.array_equal(prof.floor.params.b_g, np.zeros(3)) and np.array_equal(prof.gyro.bias, np.zeros(3))
    assert np.all(np.isnan(prof.gyro.bias_std)) and prof.observed["gyroscope.bias"]["observed"] is False
    assert checks["failed"] == [] and checks["held_back"]["profile_rot_deg"] == checks["held_back"]["raw_rot_deg"]


def test_a_raise_beyond_the_blocks_noise_is_refused(inputs):
    prof = profile_with_gyro_bias(np.array([0.02, -0.02, 0.02]))  # 2 deg over the window, 0.3 deg noise
    with pytest.raises(ImplausibleProfileError, match="held_back.rotation.*beyond the block's noise"):
        plausibility(prof, inputs, CalibOptions(), lambda s: None)
    assert np.array_equal(prof.floor.params.b_g, [0.02, -0.02, 0.02])  # nothing kept at the prior


def test_force_writes_the_fitted_terms_and_says_what_failed(inputs):
    prof = profile_with_gyro_bias(np.full(3, 2.5e-3) * [1, -1, 1])
    checks = plausibility(prof, inputs, CalibOptions(force=True), lambda s: None)
    assert "kept_at_prior" not in checks and checks["forced"] and checks["failed"][0].startswith("held_back.rotation")
    assert np.array_equal(prof.floor.params.b_g, np.full(3, 2.5e-3) * [1, -1, 1])


def test_the_paired_z_of_windows():
    rng = np.random.default_rng(0)
    raw = [np.abs(rng.normal(size=200))]
    assert pl._paired_z(raw, raw) == 0.0
    assert pl._paired_z(raw, [raw[0] + 1.0]) > 10  # every window worse
    assert abs(pl._paired_z(raw, [np.abs(rng.normal(size=200))])) < 3  # the same distribution
    assert math.isnan(pl._paired_z([raw[0][:5]], [raw[0][:5] + 1]))  # too few windows: cannot tell
    base = {"window_samples": 200, "raw_rot_deg": 1.0, "raw_trans_m": 0.1, "profile_trans_m": 0.1}
    [f] = pl.held_back_findings({**base, "profile_rot_deg": 1.01, "z_rot": 0.5})
    assert f.within_noise and "within the block's noise" in f.message
    [f] = pl.held_back_findings({**base, "profile_rot_deg": 1.01, "z_rot": math.nan})
    assert not f.within_noise and "too few" in f.message


def test_the_terms_are_chosen_by_default_for_every_poses_reference():
    """Dense motion capture too (BROAD's every-term profile lost to raw on unseen trials); positions and
    odometry fit what they observe; the option overrides."""
    from imu_learn.calib.run import selects
    from imu_learn.calib.sources import Source

    class Sparse(Source):  # a 20 Hz VO: its source restricts the floor's terms
        def floor_terms(self):
            return {"cutoffs_hz": (None,)}

    class Positions(Sparse):
        kind = "positions"

    sparse, dense, positions = (CalibInputs([], [], [], [], source=s()) for s in (Sparse, Source, Positions))
    assert selects(None, sparse) and selects(None, dense) and not selects(None, positions)
    assert not selects(False, sparse) and not selects(False, dense) and selects(True, dense)
