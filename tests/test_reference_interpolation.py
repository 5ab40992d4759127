"""A sparse pose reference (a 20 Hz VO) put on the IMU's stamps by slerp low-passes the motion; the
floor fitted against it sees the IMU through the same low-pass (calib.sources.interpolation_kernel).

Checked against independent oracles: the kernel's gain against slerp's, measured on a sinusoid
interpolated by the project's own alignment; and a synthetic device whose gyro matrix and bias are
known, moving with rotation up to 4 Hz, seen by an exact 20 Hz pose reference: fitted on the raw IMU
the gyro's scales come out low (the attenuation), on the matched IMU they are the device's."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_learn.baselines.base import FitSettings
from imu_learn.calib import fit as ff
from imu_learn.calib.reference import FrameFit
from imu_learn.calib.sources import (
    TRAIN,
    VAL,
    CalibInputs,
    PosesSource,
    Recording,
    interpolation_kernel,
    matched,
    smoothed,
)
from imu_learn.core.quat import quat_log, quat_mul, quat_rotate
from imu_learn.data.loading import AlignOptions, align
from imu_learn.data.types import GroundTruth, ImuData

DT, EVERY = 0.005, 10  # a 200 Hz IMU, a reference every 10th stamp (20 Hz)
M_TRUE = np.array([[1.004, 0.002, -0.001], [0.0, 0.996, 0.003], [0.001, -0.002, 1.002]])
B_TRUE = np.array([0.01, -0.02, 0.03])
SEED = 1


def rotvec_quat(r: np.ndarray) -> np.ndarray:
    a = np.linalg.norm(r, axis=-1, keepdims=True)
    k = np.where(a > 0, r / np.maximum(a, 1e-300), 0.0)
    return np.concatenate([np.cos(a / 2), np.sin(a / 2) * k], axis=-1)


def test_the_kernel_is_the_triangle_of_one_reference_period():
    k = interpolation_kernel(0.05, DT)
    assert len(k) == 19 and k.sum() == pytest.approx(1.0) and np.allclose(k, k[::-1])
    assert k[9] == pytest.approx(0.1) and k[0] == pytest.approx(0.01)
    assert np.array_equal(interpolation_kernel(DT, DT), [1.0])  # a reference as dense as the IMU: nothing
    assert np.array_equal(interpolation_kernel(1 / 120, DT), [1.0])  # 120 Hz motion capture: nothing


@pytest.mark.parametrize("f_hz", [1.0, 3.0, 6.0])
def test_the_kernels_gain_is_what_slerp_does_to_the_motion(f_hz):
    """A rotation about z of frequency f sampled at 20 Hz, aligned onto 200 Hz stamps (the Rust slerp):
    its regression on the true angle is the kernel's gain at f (sinc²(f h)) within 1 %, and the angle
    smoothed by the kernel regresses on the interpolated one with gain 1."""
    t = np.arange(0.0, 60.0, DT)
    ang = 0.4 * np.sin(2 * math.pi * f_hz * t + 0.3)
    q = rotvec_quat(np.c_[np.zeros((len(t), 2)), ang])
    t_ns = (1e9 + t * 1e9).astype(np.int64)
    imu = ImuData(t_ns=t_ns, gyro=np.zeros((len(t), 3)), acc=np.tile([0, 0, 9.81], (len(t), 1)))
    k = np.arange(0, len(t), EVERY)
    ref = GroundTruth(t_ns=t_ns[k], p=np.zeros((len(k), 3)), q_wxyz=q[k])
    seg = align(imu, ref, AlignOptions(max_gap_s=0.08)).segments[0]
    i0 = int(np.searchsorted(t_ns, seg.t_ns[0]))
    truth = ang[i0:i0 + len(seg)]
    seen = 2 * np.arctan2(seg.q_wxyz[:, 3], seg.q_wxyz[:, 0])
    kern = interpolation_kernel(EVERY * DT, DT)
    gain = float(np.sum(kern * np.cos(2 * math.pi * f_hz * DT * (np.arange(len(kern)) - len(kern) // 2))))
    # slerp's gain averaged over the 10 places a stamp falls between two poses is exactly the sampled
    # triangle's (Fejér's kernel); the continuous triangle's sinc²(f h) within 0.5 % up to 6 Hz
    lam = np.arange(EVERY) / EVERY
    w = 2 * math.pi * f_hz * EVERY * DT
    assert gain == pytest.approx(np.mean((1 - lam) * np.cos(w * lam) + lam * np.cos(w * (1 - lam))), rel=1e-9)
    assert gain == pytest.approx(np.sinc(f_hz * EVERY * DT) ** 2, rel=5e-3)
    inner = slice(100, -100)
    assert np.dot(seen[inner], truth[inner]) / np.dot(truth[inner], truth[inner]) == pytest.approx(gain, rel=0.01)
    sm = smoothed(truth[:, None], kern)[:, 0]
    assert np.dot(seen[inner], sm[inner]) / np.dot(sm[inner], sm[inner]) == pytest.approx(1.0, abs=0.01)


def device(seed: int, seconds: float = 90.0):
    """Segments of a device (M_TRUE, B_TRUE) rotating with content from 0.05 to 4 Hz, seen by an exact
    20 Hz pose reference (slerped onto the IMU stamps as calibrate does)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, DT)
    rv = np.zeros((len(t), 3))
    for i in range(3):  # slow large turns, and faster small ones (rates up to about 0.3 rad/s each)
        for f in np.r_[rng.uniform(0.03, 0.3, 2), rng.uniform(0.5, 4.0, 4)]:
            rv[:, i] += min(0.5, 0.05 / f) * np.sin(2 * math.pi * f * t + rng.uniform(0, 2 * math.pi))
    q = rotvec_quat(rv)
    p = np.stack([np.sin(0.3 * t), np.cos(0.2 * t), 0.1 * np.sin(0.5 * t)], 1)
    a = np.stack([-0.09 * np.sin(0.3 * t), -0.04 * np.cos(0.2 * t), -0.025 * np.sin(0.5 * t)], 1)
    f_body = quat_rotate(np.c_[q[:, :1], -q[:, 1:]], a + np.array([0, 0, 9.81]))
    omega = np.zeros((len(t), 3))  # the rates whose zero-order hold reproduces the attitude at every sample
    omega[:-1] = quat_log(quat_mul(np.c_[q[:-1, :1], -q[:-1, 1:]], q[1:])) / DT
    omega[-1] = omega[-2]
    gyro = np.linalg.solve(M_TRUE, omega.T).T + B_TRUE + 2e-3 * rng.standard_normal(omega.shape)
    t_ns = (1e9 + t * 1e9).astype(np.int64)
    imu = ImuData(t_ns=t_ns, gyro=gyro, acc=f_body + 0.01 * rng.standard_normal(f_body.shape))
    k = np.arange(0, len(t), EVERY)
    ref = GroundTruth(t_ns=t_ns[k], p=p[k], q_wxyz=q[k])
    return align(imu, ref, AlignOptions(max_gap_s=0.08)).segments


def inputs(segs) -> CalibInputs:
    recs = []
    for i, s in enumerate(segs):
        n = int(0.85 * len(s))
        cut = [type(s)(name=f"r{i}", **{k: getattr(s, k)[a:b] for k in ("t_ns", "gyro", "acc", "p", "v", "q_wxyz")})
               for a, b in ((0, n), (n, len(s)))]
        recs += [Recording(f"r{i}", TRAIN, [cut[0]]), Recording(f"r{i}", VAL, [cut[1]])]
    return CalibInputs(recordings=recs, settings=FitSettings())


def test_a_known_gyro_is_recovered_from_a_20_hz_reference_only_through_its_interpolation():
    inp = inputs([device(SEED)[0], device(SEED + 1)[0]])
    src = PosesSource([])
    src.frame = FrameFit(r_imu_ref=np.eye(3), rotation_deg=0.0, rotation_std_deg=0.0, rate_residual=0.0,
                         rate_rms=1.0, lag_s=0.0, lag_correlation=1.0, gyro_bias=np.zeros(3), scale=1.0,
                         scale_std=0.0, lever_m=np.zeros(3), lever_std_m=np.zeros(3), tilt_deg=0.0,
                         g_up=np.zeros((2, 3)), rate_hz=20.0, resolves_acceleration=False)
    kern = src.match_kernel(inp)
    assert len(kern) == 19
    terms = {"cutoffs_hz": (None,), "held": ("acc",)}

    def gyro_of(x: CalibInputs):
        m, _ = ff.fit_once(x.train, x.val, x.settings, terms=terms)
        return m.params.M_g, m.params.b_g

    m_raw, _ = gyro_of(inp)
    m_fit, b_fit = gyro_of(matched(inp, kern))
    scale_err_raw = np.diag(m_raw) - np.diag(M_TRUE)
    assert np.all(scale_err_raw < -1e-3), scale_err_raw  # the slerp's low-pass: the scales come out low
    assert np.all(np.abs(m_fit - M_TRUE) < 5e-4), m_fit - M_TRUE
    assert np.all(np.abs(b_fit - B_TRUE) < 5e-4), b_fit - B_TRUE
