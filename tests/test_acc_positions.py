"""The accelerometer's affine calibration from a sparse reference's positions (calib.acc_positions),
checked against a synthetic device whose M_a, b_a and reference origin are known: an analytic
trajectory (its exact acceleration and attitude), the IMU's specific force through the inverse of the
model plus white noise, and a 20 Hz pose reference of a point a few centimetres from the IMU with
millimetre position noise and 0.1° attitude noise, put on the IMU stamps as calibrate does (align)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_learn.calib.acc_positions import AccOptions, fit_acc_from_positions, heldout_rms, recording_spread
from imu_learn.calib.select import free_indices, select_acc_from_positions
from imu_learn.core.quat import quat_log, quat_mul, quat_rotate
from imu_learn.data.loading import AlignOptions, align
from imu_learn.data.types import GroundTruth, ImuData

M_TRUE = np.array([[1.02, 0.01, -0.005], [0.003, 0.985, 0.008], [-0.01, 0.004, 1.01]])
B_TRUE = np.array([0.1, -0.2, 0.15])
LEVER = np.array([-0.02, -0.065, 0.01])  # the reference's origin in the IMU frame (EuRoC's cam0 is about here)
G = 9.81


def rotvec_quat(r: np.ndarray) -> np.ndarray:
    a = np.linalg.norm(r, axis=-1, keepdims=True)
    k = np.where(a > 0, r / np.maximum(a, 1e-300), 0.0)
    return np.concatenate([np.cos(a / 2), np.sin(a / 2) * k], axis=-1)


def euler_quat(e: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) as w,x,y,z."""
    z = np.zeros(len(e))
    qx = rotvec_quat(np.stack([e[:, 0], z, z], 1))
    qy = rotvec_quat(np.stack([z, e[:, 1], z], 1))
    qz = rotvec_quat(np.stack([z, z, e[:, 2]], 1))
    return quat_mul(qz, quat_mul(qy, qx))


def device(seed: int, seconds: float = 240.0, pos_noise: float = 0.003, att_noise_deg: float = 0.1, tilt=(0.0, 0.0),
           m_true: np.ndarray = M_TRUE):
    """(IMU, 20 Hz reference) of a drone-like flight: sums of sines in position (analytic acceleration),
    roll and pitch within ±17°, heading sweeping ±120°; the reference world tilted by ``tilt``
    (horizontal gravity [m/s²], as a levelling error leaves it)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 0.005)
    p, a = np.zeros((len(t), 3)), np.zeros((len(t), 3))
    for i in range(3):
        for f, amp, ph in zip(rng.uniform(0.1, 0.8, 4), rng.uniform(0.1, 0.6, 4), rng.uniform(0, 2 * math.pi, 4)):
            w = 2 * math.pi * f
            p[:, i] += amp * np.sin(w * t + ph)
            a[:, i] -= amp * w * w * np.sin(w * t + ph)
    e = np.stack([0.3 * np.sin(2 * math.pi * 0.3 * t), 0.25 * np.sin(2 * math.pi * 0.23 * t + 1),
                  1.5 * np.sin(2 * math.pi * 0.05 * t) + 0.6 * np.sin(2 * math.pi * 0.4 * t)], 1)
    q = euler_quat(e)
    g = np.array([tilt[0], tilt[1], -G])
    f_true = quat_rotate(np.c_[q[:, :1], -q[:, 1:]], a - g)  # R^T (a - g)
    acc = np.linalg.solve(m_true, f_true.T).T + B_TRUE + 0.01 * rng.standard_normal(f_true.shape)
    t_ns = (1e9 + t * 1e9).astype(np.int64)
    gyro = np.zeros_like(acc)  # the rates whose zero-order hold reproduces the attitude at every sample
    gyro[:-1] = quat_log(quat_mul(np.c_[q[:-1, :1], -q[:-1, 1:]], q[1:])) / 0.005
    gyro[-1] = gyro[-2]
    imu = ImuData(t_ns=t_ns, gyro=gyro, acc=acc)
    k = np.arange(0, len(t), 10)  # 20 Hz
    p_ref = p[k] + quat_rotate(q[k], np.broadcast_to(LEVER, (len(k), 3))) + pos_noise * rng.standard_normal((len(k), 3))
    q_ref = quat_mul(q[k], rotvec_quat(math.radians(att_noise_deg) * rng.standard_normal((len(k), 3))))
    ref = GroundTruth(t_ns=t_ns[k], p=p_ref, q_wxyz=q_ref)
    return align(imu, ref, AlignOptions(max_gap_s=0.08)).segments, ref.t_ns


def z_scores(fit) -> np.ndarray:
    return np.r_[((fit.M_a - M_TRUE) / fit.M_a_std).ravel(), (fit.b_a - B_TRUE) / fit.b_a_std,
                 (fit.lever_m - LEVER) / fit.lever_std_m]


@pytest.mark.parametrize("baseline_s", [0.25, 0.5])
@pytest.mark.parametrize("attitude", ["reference", "gyro"])
def test_a_known_device_is_recovered_within_its_stated_uncertainty(baseline_s, attitude):
    """(At a 1 s baseline the cluster-robust errors understate the spread over seeds by about 40 %:
    fewer independent baselines per cluster; the default is 0.5 s.)"""
    segs, _ = device(0)
    gyros = [[s.gyro for s in segs]] if attitude == "gyro" else None
    fit = fit_acc_from_positions([segs], AccOptions(baseline_s=baseline_s), tau_samples=0.5, gyros=gyros)
    z = z_scores(fit)
    assert np.all(np.abs(z) < 4.0), z.round(2)
    # and the uncertainty says something: scales to a few parts per thousand, the origin to a centimetre
    assert np.all(np.diag(fit.M_a_std) < 3e-3) and np.all(fit.lever_std_m < 0.01)
    # the matrix is needed: with M_a = I (the bias alone) the residual is larger
    assert fit.rms < 0.8 * fit.rms_identity


def test_the_stated_uncertainty_is_the_spread_of_independent_flights():
    """Over independent flights (seeds) the errors scaled by their stated standard errors have an RMS
    near 1 (neither overstated nor understated by more than a factor of 2)."""
    z = np.concatenate([z_scores(fit_acc_from_positions([device(s, seconds=120.0)[0]], tau_samples=0.5))
                        for s in range(1, 7)])
    rms = float(np.sqrt(np.mean(z**2)))
    assert 0.5 < rms < 2.0, rms


def test_a_tilted_world_is_told_from_the_bias():
    """A world levelled 0.6° off (0.1 m/s² of horizontal gravity): with the tilt fitted, the bias is
    the device's; without, the tilt leaks into it."""
    segs, _ = device(3, tilt=(0.1, -0.06))
    with_tilt = fit_acc_from_positions([segs], AccOptions(fit_tilt=True), tau_samples=0.5)
    without = fit_acc_from_positions([segs], AccOptions(fit_tilt=False), tau_samples=0.5)
    assert np.all(np.abs(with_tilt.b_a - B_TRUE) < 4 * with_tilt.b_a_std + 1e-3)
    assert np.allclose(with_tilt.tilt[0], [0.1, -0.06], atol=0.02)
    assert np.max(np.abs(without.b_a - B_TRUE)) > np.max(np.abs(with_tilt.b_a - B_TRUE)) + 0.02


def test_the_lever_arm_matters_and_is_fitted():
    """Left out, the reference origin's few centimetres bias the matrix beyond its uncertainty."""
    segs, _ = device(4)
    free = fit_acc_from_positions([segs], AccOptions(fit_lever=False), tau_samples=0.5)
    fitted = fit_acc_from_positions([segs], AccOptions(fit_lever=True), tau_samples=0.5)
    assert np.max(np.abs(fitted.M_a - M_TRUE) / fitted.M_a_std) < 4.0
    assert np.max(np.abs(free.M_a - M_TRUE) / free.M_a_std) > 4.0


def test_the_spread_over_recordings_is_the_floors_convention():
    recs = [device(s, seconds=90.0)[0] for s in (5, 6, 7)]
    m_std, b_std, fits = recording_spread(recs, AccOptions(), 0.5)
    assert len(fits) == 3
    expected = np.std(np.stack([f.M_a for f in fits]), axis=0, ddof=1) / math.sqrt(3)
    assert np.allclose(m_std, expected)
    assert recording_spread(recs[:1], AccOptions(), 0.5) is None


def test_too_short_a_reference_is_refused():
    segs, _ = device(8, seconds=1.5)
    with pytest.raises(ValueError, match="baseline"):
        fit_acc_from_positions([segs], AccOptions(baseline_s=1.0))


@pytest.mark.parametrize("matrix, level", [(np.eye(3), "bias"), (M_TRUE, "affine")])
def test_the_level_chosen_on_held_out_recordings_is_the_devices(matrix, level):
    """Three recordings of one device, each held out in turn (calib.select.select_acc_from_positions):
    a device with a bias alone gets `bias` (no matrix fitted to the reference's noise), one with a
    scale and a misalignment gets `affine`; the chosen level's held-out residual is never above a
    simpler level's by more than the rule's 0.5 %."""
    recs = [device(s, seconds=90.0, m_true=matrix)[0] for s in (11, 12, 13)]
    gyros = [[s.gyro for s in segs] for segs in recs]
    chosen, table, steps = select_acc_from_positions(["a", "b", "c"], recs, gyros, AccOptions(), 0.5, G)
    assert chosen == level, steps
    levels = list(table)
    for simpler in levels[: levels.index(chosen)]:
        for rec, cells in table[chosen].items():
            for cell, v in cells.items():
                assert v <= 1.005 * table[simpler][rec][cell], (simpler, rec, cell)


def test_a_level_holds_the_terms_it_does_not_fit_at_their_prior():
    """`free`: at `bias` the matrix is the identity exactly and the bias is the device's; scored on a
    recording it was not fitted on, the full fit of a scaled device beats the bias alone."""
    segs = device(3, seconds=120.0)[0]
    fit_b = fit_acc_from_positions([segs], AccOptions(), 0.5, free=free_indices("acc", "bias"))
    assert np.array_equal(fit_b.M_a, np.eye(3))
    fit_a = fit_acc_from_positions([segs], AccOptions(), 0.5)
    other = device(4, seconds=120.0)[0]
    assert heldout_rms(fit_a, other, 0.5) < heldout_rms(fit_b, other, 0.5)
