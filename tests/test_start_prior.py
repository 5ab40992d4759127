"""The first state's bias prior from a device profile (``imu_learn.fuse.start.prior``): the profile's
``bias_std`` is a standard error over its groups, so the per-recording spread is bias_std ×
sqrt(groups), per axis (the largest on every axis for an IMU rotated into the body frame); time
blocks of one recording give no spread between recordings (the defaults stay).
And ``imu-learn navigate`` with a floor-applied profile puts that sigma into the graph's prior factor
on the first bias (on the synthetic car of tests/test_navigate_gnss.py), the defaults without one."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from imu_learn.calib.profile import Profile, per_recording_spread
from imu_learn.fuse.settings import PriorSigmas
from imu_learn.fuse.start.prior import ACC_SPREAD_FLOOR, GYRO_SPREAD_FLOOR, profile_bias_sigmas

pytest.importorskip("gtsam")

from test_navigate_geodetic import car_args, write_profile  # noqa: E402
from test_navigate_gnss import run, synthetic_car  # noqa: E402

GYRO_STD = np.array([0.001, 0.004, 0.002])  # rad/s, a standard error over the groups
ACC_STD = np.array([0.02, 0.05, 0.03])  # m/s^2


def profile_with(tmp_path, names, gyro_std=GYRO_STD, acc_std=ACC_STD, floor=None):
    """A noise-only profile (tests/test_navigate_geodetic.py's) given bias_std and fit_log groups."""
    path = write_profile(tmp_path / "calib" / "profile.json", floor=floor)
    prof = Profile.load(path)
    prof.gyro.bias_std = np.asarray(gyro_std, dtype=np.float64)
    prof.acc.bias_std = np.asarray(acc_std, dtype=np.float64)
    prof.fit_log = {"groups": [{"group": n, "b_g": [0.0] * 3, "b_a": [0.0] * 3} for n in names]}
    prof.save(path)
    return path


def test_the_sigma_is_the_standard_error_times_sqrt_groups(tmp_path):
    # independent arithmetic: 4 groups -> x2 per axis; the gyro's x axis (0.002) floored at 0.005
    prof = Profile.load(profile_with(tmp_path, ["MH_01", "MH_02", "V1_01", "V2_01"]))
    sig, entry = profile_bias_sigmas(prof)
    assert sig is not None
    np.testing.assert_allclose(sig[0], [max(0.002, GYRO_SPREAD_FLOOR), 0.008, max(0.004, GYRO_SPREAD_FLOOR)])
    np.testing.assert_allclose(sig[1], [0.04, 0.10, 0.06])
    assert entry["groups"] == 4 and "sqrt(4 groups)" in entry["source"]
    np.testing.assert_allclose(entry["acc_per_recording_mps2"], [0.04, 0.10, 0.06])
    iso, _ = profile_bias_sigmas(prof, isotropic=True)  # a mounting mixes the axes: the largest on every one
    np.testing.assert_allclose(iso[0], [0.008] * 3)
    np.testing.assert_allclose(iso[1], [0.10] * 3)
    # the spread of per-group values over sqrt(groups) (calib.fit.spread) undone: the groups' own spread
    vals = np.random.default_rng(0).normal(0.0, 0.07, (9, 3))
    se = vals.std(axis=0, ddof=1) / math.sqrt(9)
    np.testing.assert_allclose(per_recording_spread(se, 9), vals.std(axis=0, ddof=1))


def test_floors_caps_and_when_the_defaults_stay(tmp_path):
    d = PriorSigmas()
    tiny = Profile.load(profile_with(tmp_path / "a", ["r1", "r2", "r3"], gyro_std=[1e-5] * 3, acc_std=[1e-4] * 3))
    assert profile_bias_sigmas(tiny)[0] == ((GYRO_SPREAD_FLOOR,) * 3, (ACC_SPREAD_FLOOR,) * 3)
    huge = Profile.load(profile_with(tmp_path / "b", ["r1", "r2"], gyro_std=[1.0] * 3, acc_std=[9.0] * 3))
    assert profile_bias_sigmas(huge)[0] == ((d.bias_gyro,) * 3, (d.bias_acc,) * 3)  # never looser than the defaults
    blocks = Profile.load(profile_with(tmp_path / "c", ["block1", "block2", "block3", "block4"]))
    sig, entry = profile_bias_sigmas(blocks)
    assert sig is None and "time blocks" in entry["source"]
    one = Profile.load(profile_with(tmp_path / "d", ["r1"]))
    assert profile_bias_sigmas(one)[0] is None
    nan = Profile.load(profile_with(tmp_path / "e", ["r1", "r2"], acc_std=[np.nan] * 3))
    assert profile_bias_sigmas(nan)[0] is None


def _graph_prior_sigmas(monkeypatch):
    """Record the sigmas of the prior factor on the first bias in every graph navigate builds."""
    from imu_learn.fuse import navigate

    seen = []

    class Recording(navigate.IncrementalFusion):
        def _start_with_prior(self, start_pose, prior, bias0):
            out = super()._start_with_prior(start_pose, prior, bias0)
            f = self._graph.at(2)
            assert "ConstantBias" in type(f).__name__
            seen.append(np.asarray(f.noiseModel().sigmas()))  # GTSAM's order: acc, then gyro
            return out

    monkeypatch.setattr(navigate, "IncrementalFusion", Recording)
    return seen


def test_navigate_puts_the_profiles_spread_into_the_graphs_bias_prior(tmp_path, capsys, monkeypatch):
    from imu_learn.baselines.traditional import TraditionalTiming

    seen = _graph_prior_sigmas(monkeypatch)
    imu, pos, _ = synthetic_car(tmp_path, seconds=10.0)
    m = TraditionalTiming()
    m.params.cutoff_gyro = m.params.cutoff_acc = None
    m.params.time_offset = 0.0
    prof = profile_with(tmp_path, ["r1", "r2", "r3", "r4"], floor=m.to_dict())
    rc, _out, err = run(car_args(imu, pos, tmp_path / "prof") + ["--quiet", "--profile", prof], capsys)
    assert rc == 0, err
    s = json.loads((tmp_path / "prof" / "summary.json").read_text())
    assert s["profile_floor"] is True
    # the car's IMU is rotated into its body frame (--imu-rotation-rpy-deg): the largest axis on every one
    np.testing.assert_allclose(s["init"]["prior"]["bias_acc"], [0.10] * 3)
    np.testing.assert_allclose(s["init"]["prior"]["bias_gyro"], [0.008] * 3)
    assert "sqrt(4 groups)" in s["init"]["bias_prior"]["source"] and "largest axis" in s["init"]["bias_prior"]["source"]
    assert seen, "no graph built"
    np.testing.assert_allclose(seen[-1], [0.10] * 3 + [0.008] * 3)
    # without a profile: the defaults, in the summary and in the graph
    seen.clear()
    rc, _out, err = run(car_args(imu, pos, tmp_path / "raw") + ["--quiet", "--imu-noise", "1e-4,1e-3,1e-5,1e-4"],
                        capsys)
    assert rc == 0, err
    s = json.loads((tmp_path / "raw" / "summary.json").read_text())
    d = PriorSigmas()
    assert s["init"]["prior"]["bias_acc"] == d.bias_acc and s["init"]["bias_prior"]["source"].startswith("defaults")
    np.testing.assert_allclose(seen[-1], [d.bias_acc] * 3 + [d.bias_gyro] * 3)


def test_prior_sigmas_per_axis_in_gtsams_order():
    assert PriorSigmas(bias_gyro=0.1, bias_acc=0.5).bias_sigmas().tolist() == [0.5] * 3 + [0.1] * 3
    per_axis = PriorSigmas(bias_gyro=(0.001, 0.002, 0.003), bias_acc=(0.04, 0.05, 0.06))
    assert per_axis.bias_sigmas().tolist() == [0.04, 0.05, 0.06, 0.001, 0.002, 0.003]  # acc first, as GTSAM
