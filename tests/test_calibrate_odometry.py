"""Planar wheel odometry as a calibration reference (calib.odometry): a synthetic ground robot whose
IMU has a known bias and scale about its (tilted) vertical axis, its odometry in a frame turned 119°
about the vertical and 0.091 s late: the bias, the scale, the lag and the forward axis are recovered,
the profile says what was observed, and what the odometry cannot give is refused."""
from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from imu_learn.calib.odometry import OdometrySource, is_odometry_reference, is_planar_odometry, vertical_axis
from imu_learn.calib.reference import check_not_odometry, level_rotation
from imu_learn.calib.run import CalibOptions, calibrate
from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import ReferenceFrameError

RATE = 100.0
B_U, SCALE, LAG = 0.02, 1.03, 0.091  # the gyro's bias [rad/s] and scale about its vertical; the odometry's lag [s]
B_PERP = np.array([0.004, -0.003, 0.0])  # a gyro bias across the vertical: not observed, left at 0


def rz(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def robot(seconds=120.0, seed=0, turning=True, mount_deg=119.0):
    """The IMU of a ground robot (still 5 s, then driving and turning) mounted Rz(mount)·tilt in its
    base frame, and the base's planar odometry (yaw, x, y; z = 0) at 50 Hz, ``LAG`` late. Returns
    (imu, odometry, the IMU's true up in its own coordinates, R_base_imu)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE)) / RATE
    moving = np.clip((t - 5.0) / 2.0, 0.0, 1.0)
    w = np.zeros_like(t)
    if turning:
        for f in (0.05, 0.13, 0.31):
            w += rng.uniform(0.15, 0.3) * np.sin(2 * math.pi * f * t + rng.uniform(0, 6))
    w *= moving
    v = moving * (0.5 + 0.3 * np.sin(2 * math.pi * 0.07 * t))
    dt = 1.0 / RATE
    yaw = np.concatenate([[0.0], np.cumsum(w[:-1]) * dt])
    p = np.stack([np.concatenate([[0.0], np.cumsum((v * np.cos(yaw))[:-1]) * dt]),
                  np.concatenate([[0.0], np.cumsum((v * np.sin(yaw))[:-1]) * dt]), np.zeros_like(t)], 1)
    a_b = np.stack([np.gradient(v, dt), v * w, np.full_like(t, 9.81)], 1)  # specific force in the base frame
    tilt = level_rotation(np.array([0.03, -0.02, 1.0])).T  # the IMU's up is (0.03, -0.02, 1) in its frame
    r_base_imu = rz(mount_deg) @ tilt
    u = r_base_imu.T @ [0, 0, 1.0]
    gyro = np.outer(w, u) * SCALE + B_U * u + B_PERP + rng.normal(0, 0.003, (len(t), 3))
    acc = a_b @ r_base_imu + rng.normal(0, 0.03, (len(t), 3))
    t_ns = (1_000_000_000 + np.round(t * 1e9)).astype(np.int64)
    imu = ImuData(t_ns, gyro, acc)
    k = np.arange(0, len(t), 2)
    h = 0.5 * yaw[k]
    q = np.stack([np.cos(h), np.zeros_like(h), np.zeros_like(h), np.sin(h)], 1)
    odo = GroundTruth(t_ns[k] + int(LAG * 1e9), p[k], q)
    return imu, odo, u, r_base_imu


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    imu, odo, u, r_base_imu = robot()
    src = OdometrySource([], [])
    inp = src.read_pairs([(imu, odo)], ["synthetic"])
    res = calibrate(inp, tmp_path_factory.mktemp("odo"), CalibOptions(plot=False))
    return res.profile, src, u, r_base_imu


def test_the_planar_rule_and_the_refusal_of_the_6dof_path():
    _, odo, _, _ = robot(seconds=30)
    assert is_planar_odometry(odo)
    tilted = GroundTruth(odo.t_ns, odo.p + [0, 0, 0.01], odo.q_wxyz)
    assert is_planar_odometry(odo) and not is_planar_odometry(
        GroundTruth(odo.t_ns, np.c_[odo.p[:, :2], np.linspace(0, 1, len(odo.p))], odo.q_wxyz))
    assert is_planar_odometry(tilted)  # a constant height other than 0 is still planar
    with pytest.raises(ReferenceFrameError, match="reads it as odometry"):
        check_not_odometry(odo, "odo")


def test_the_yaw_bias_scale_lag_and_forward_axis_are_recovered(calibrated):
    prof, src, u, r_base_imu = calibrated
    assert np.degrees(np.arccos(np.clip(src.u @ u, -1, 1))) < 0.5
    assert abs(prof.reference["lag_s"] - LAG) < 0.003, prof.reference["lag_s"]
    b = np.asarray(prof.gyro.bias)
    assert abs(b @ u - B_U) < 1e-3, b @ u
    assert np.linalg.norm(b - (b @ u) * u) < 1e-4  # across the vertical: the prior 0, not B_PERP
    m = np.asarray(prof.gyro.matrix)
    assert abs(u @ m @ u - 1 / SCALE) < 0.005  # the scale about the vertical applied (significant)
    perp = np.cross(u, [1.0, 0, 0])
    perp /= np.linalg.norm(perp)
    assert abs(perp @ m @ perp - 1) < 1e-9  # across it the identity
    fwd = np.asarray(prof.reference["forward_axis_in_imu"])
    assert np.degrees(np.arccos(np.clip(fwd @ (r_base_imu.T @ [1.0, 0, 0]), -1, 1))) < 3
    assert np.allclose(prof.acc.bias, 0) and np.allclose(prof.acc.matrix, np.eye(3))
    assert abs(prof.floor.params.time_offset - 0.5) < 1e-12  # the prior: the lag and the IMU's offset are one
    held = prof.fit_log["odometry"]["held_back_yaw"]
    assert held["profile_yaw_deg"] < held["raw_yaw_deg"]
    assert not prof.checks["failed"]


def test_the_profile_says_what_the_odometry_observed(calibrated):
    prof, _, _, _ = calibrated
    obs = prof.observed
    assert obs["gyroscope.bias"]["observed"] and "vertical axis" in obs["gyroscope.bias"]["why"]
    assert obs["gyroscope.matrix"]["observed"]  # the scale was significant
    for k in ("time_offset", "g_sensitivity", "accelerometer.matrix", "accelerometer.bias", "cutoff_gyro", "cutoff_acc"):
        assert obs[k]["observed"] is False and obs[k]["why"], k
    assert prof.reference["kind"] == "odometry"
    assert len(prof.reference["vertical_axis_in_imu"]) == 3


def test_a_reference_without_yaw_motion_is_refused():
    imu, odo, _, _ = robot(seconds=40, turning=False)
    with pytest.raises(ReferenceFrameError, match="does not turn"):
        OdometrySource([], []).read_pairs([(imu, odo)], ["straight"])


def test_no_vertical_axis_is_refused():
    rng = np.random.default_rng(1)
    t_ns = (np.arange(4000) * 1e7).astype(np.int64)
    ang = np.cumsum(rng.normal(0, 0.05, (4000, 2)), 0)  # tumbling: gravity wanders over the whole sphere
    acc = 9.81 * np.stack([np.cos(ang[:, 0]) * np.cos(ang[:, 1]), np.sin(ang[:, 0]) * np.cos(ang[:, 1]),
                           np.sin(ang[:, 1])], 1) + rng.normal(0, 0.5, (4000, 3))
    gyro = rng.normal(0, 1.0, (4000, 3))
    with pytest.raises(ReferenceFrameError, match="vertical axis cannot be found"):
        vertical_axis(ImuData(t_ns, gyro, acc))


def test_the_command_picks_the_odometry_source(tmp_path):
    from imu_learn.cli.calibrate import source_of

    _, odo, _, _ = robot(seconds=20)
    path = tmp_path / "odom.tum"
    with open(path, "w") as f:
        for t, p, q in zip(odo.t_ns, odo.p, odo.q_wxyz):
            f.write(f"{t * 1e-9:.9f} {p[0]:.6f} {p[1]:.6f} 0 {q[1]:.9f} {q[2]:.9f} {q[3]:.9f} {q[0]:.9f}\n")
    assert is_odometry_reference(path)
    args = argparse.Namespace(config=None, imu_only=False, input=[tmp_path / "imu.csv"], groundtruth=[path],
                              format="auto", max_gap_s=None, val_fraction=0.15, device=None, extrinsics=None,
                              columns=None, time_unit=None)
    assert isinstance(source_of(args), OdometrySource)
