"""The ``--bias`` estimators' device prior takes the profile's gyro bias spread *between recordings*:
a profile's ``gyroscope.bias_std`` is the standard error of the floor's mean over its groups
(calib.fit: the per-group values' spread over sqrt(groups)), so the prior's std is that spread,
bias_std × sqrt(groups) (floored at BIAS_SPREAD_FLOOR, capped at MEMS_BIAS_BOUND), in refine's builder
(calib.correction) and navigate's (fuse.navigate.bias_prior) alike; a profile fitted on one recording
(time blocks of it as groups) or without groups keeps bias_std as it is."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_learn.calib.correction import _prior
from imu_learn.calib.profile import NoiseTerm, Profile, noise_only
from imu_learn.core.still import BIAS_SPREAD_FLOOR, MEMS_BIAS_BOUND

# per-recording gyro biases of four recordings [rad/s] (one row each): their spread, not the profile's
# standard error, is what a new recording's bias departs from the device's mean by
PER_GROUP = np.array([[0.004, -0.001, 0.030], [-0.006, 0.002, -0.020], [0.010, -0.003, 0.010], [-0.002, 0.001, -0.015]])


def profile_with(path, names, bias_std):
    prof = noise_only("test-imu", 200.0, {"gyroscope_noise_density": NoiseTerm(np.full(3, 1e-4), 1e-4, 1e-5, "", "residuals")})
    prof.gyro.bias_std = np.asarray(bias_std, dtype=np.float64)
    prof.fit_log = {"groups": [{"group": n, "b_g": [0.0] * 3, "b_a": [0.0] * 3} for n in names]}
    prof.save(path)
    return Profile.load(path)


def test_four_recordings_give_the_groups_spread_floored(tmp_path):
    spread = PER_GROUP.std(axis=0, ddof=1)  # the oracle: the four recordings' own spread
    se = spread / math.sqrt(len(PER_GROUP))  # what calib.fit writes as bias_std
    prof = profile_with(tmp_path / "p.json", ["MH_01", "MH_02", "V1_01", "V2_01"], se)
    want = np.clip(spread, BIAS_SPREAD_FLOOR, MEMS_BIAS_BOUND)
    assert want[0] > BIAS_SPREAD_FLOOR and want[1] == BIAS_SPREAD_FLOOR  # one axis above the floor, one on it
    assert se[0] < BIAS_SPREAD_FLOOR < spread[0]  # where today's bias_std (floored) differs
    np.testing.assert_allclose(_prior(prof, "p").std, want, rtol=1e-12)
    np.testing.assert_allclose(_prior(prof, "p").std, np.maximum(2 * se, BIAS_SPREAD_FLOOR), rtol=1e-12)
    s, why = prof.bias_spread("gyro")
    np.testing.assert_allclose(s, spread, rtol=1e-12)
    assert "sqrt(4 groups)" in why


@pytest.mark.parametrize("names", [["block1", "block2", "block3", "block4"], ["r1"], []])
def test_one_recording_keeps_bias_std(tmp_path, names):
    se = np.array([0.008, 0.001, 0.02])
    prof = profile_with(tmp_path / "p.json", names, se)
    assert prof.bias_spread("gyro")[0] is None
    np.testing.assert_allclose(_prior(prof, "p").std, [0.008, BIAS_SPREAD_FLOOR, 0.02], rtol=1e-12)


def test_navigate_builds_the_same_prior(tmp_path):
    pytest.importorskip("gtsam")
    from imu_learn.fuse.navigate import Imu, bias_prior

    spread = PER_GROUP.std(axis=0, ddof=1)
    profile_with(tmp_path / "p.json", ["a", "b", "c", "d"], spread / 2.0)
    z = np.zeros((2, 3))
    imu = Imu(np.array([0, 1]), z, z, None, "imu.csv", floor=str(tmp_path / "p.json"))
    np.testing.assert_allclose(bias_prior(imu).std, np.clip(spread, BIAS_SPREAD_FLOOR, MEMS_BIAS_BOUND), rtol=1e-12)
    rotated = Imu(np.array([0, 1]), z, z, None, "imu.csv", mounting=np.eye(3), floor=str(tmp_path / "p.json"))
    np.testing.assert_allclose(bias_prior(rotated).std, [spread.max()] * 3, rtol=1e-12)  # the largest on every axis
