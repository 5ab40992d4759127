"""The rotation and clock between a reference trajectory and an IMU, from their own signals: mean
angular rates over windows matched by Wahba's problem (Kabsch, the gyro bias as the centring term) at
every whole-sample shift and a parabola through the best (:func:`fit_offset`), the rotation from
specific force for motion about one axis (:func:`fit_acc_rotation`), and the aligned segments these
work on. Used by ``imu-learn groundtruth`` (:mod:`imu_learn.eval.groundtruth`) and calibrate's
reference check (:mod:`imu_learn.calib.reference`)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import List, Optional, Tuple

import numpy as np

from imu_learn.core.quat import quat_conj, quat_mul, quat_rotate
from imu_learn.data.loading import AlignOptions, align
from imu_learn.data.types import GroundTruth, ImuData, Segment, median_period_ns, sample_rate_hz
from imu_learn.errors import AlignmentError

G = 9.81


def gt_rate_hz(gt: GroundTruth) -> float:
    return sample_rate_hz(gt.t_ns)


def default_gap_s(gt: GroundTruth) -> float:
    """0.05 s, or 1.5 ground-truth periods for sparse ground truth (the 20 Hz ASL state)."""
    return max(0.05, 1.5 / gt_rate_hz(gt))


def segments(imu: ImuData, gt: GroundTruth, max_gap_s: float, shift_s: float = 0.0,
             r_off: Optional[np.ndarray] = None, name: str = "") -> List[Segment]:
    """Aligned gap-free segments; optionally GT stamps moved by −shift_s and the IMU rotated into
    the GT body frame (ω_gt = R_offᵀ ω_imu). A reference whose dropouts leave no segment long enough
    is refused naming the recording and the ``--max-gap-s`` that bridges them (:func:`gap_hint`)."""
    if shift_s:
        gt = replace(gt, t_ns=gt.t_ns - int(round(shift_s * 1e9)))
    if r_off is not None:
        imu = replace(imu, gyro=imu.gyro @ r_off, acc=imu.acc @ r_off)
    try:
        return align(imu, gt, AlignOptions(max_gap_s=max_gap_s)).segments
    except AlignmentError as e:
        hint = gap_hint(gt, max_gap_s)
        if hint is None:
            raise
        raise AlignmentError(f"{name + ': ' if name else ''}{hint}", getattr(e, "path", None),
                             getattr(e, "imu_path", None)) from e


def bridging_gap_s(gt: GroundTruth, max_gap_s: float) -> Optional[float]:
    """The gap that keeps a reference with frequent dropouts whole where ``max_gap_s`` splits it: 1.1 × its
    99th-percentile spacing, to 10 ms (a motion-capture system dropping a frame or five, Fetch's up to 66 ms);
    None where its spacing is not the cause (no gap above ``max_gap_s``, or the spacing itself above 0.5 s)."""
    d = np.diff(np.asarray(gt.t_ns, dtype=np.int64)) * 1e-9
    if len(d) == 0 or not np.any(d > max_gap_s):
        return None
    s = math.ceil(110 * float(np.percentile(d, 99))) / 100
    return None if s <= max_gap_s or s > 0.5 else s


def gap_hint(gt: GroundTruth, max_gap_s: float, option: str = "--max-gap-s") -> Optional[str]:
    """Why a reference with frequent dropouts leaves no stretch long enough at ``max_gap_s``, and the
    ``option`` value that keeps it (:func:`bridging_gap_s`); None where its spacing is not the cause."""
    s = bridging_gap_s(gt, max_gap_s)
    if s is None:
        return None
    d = np.diff(np.asarray(gt.t_ns, dtype=np.int64)) * 1e-9
    return (f"the reference has {int(np.sum(d > max_gap_s))} gaps longer than {max_gap_s:g} s (the longest "
            f"{1e3 * float(d.max()):.0f} ms), which leave no stretch long enough; {option} {s:g} bridges 99 % of its "
            "spacing by interpolation (fine for a slow platform; a fast one wants a reference without dropouts)")


def log_q(q: np.ndarray) -> np.ndarray:
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    n = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    return q[..., 1:] * (2 * np.arctan2(n, q[..., :1]) / np.maximum(n, 1e-300))


def mean_rates(seq: Segment, m: int) -> Tuple[np.ndarray, np.ndarray]:
    """Mean angular rates over m-sample windows (stride 1): IMU (Σ ω dt / Σ dt) and ground truth
    (Log(q_kᵀ q_k+m) / Δt), both in their own body frames; rows k = 0 .. len − m − 1."""
    dt = np.diff(seq.t_ns) * 1e-9
    c = np.concatenate([np.zeros((1, 3)), np.cumsum(seq.gyro[:-1] * dt[:, None], axis=0)])
    span = (seq.t_ns[m:] - seq.t_ns[:-m])[:, None] * 1e-9
    w_imu = (c[m:] - c[:-m]) / span
    w_gt = log_q(quat_mul(quat_conj(seq.q_wxyz[:-m]), seq.q_wxyz[m:])) / span
    return w_imu, w_gt


def kabsch(a: np.ndarray, b: np.ndarray) -> Tuple[np.ndarray, np.ndarray, float]:
    """R (proper rotation), c minimising Σ|a − R b − c|²; returns (R, c, mean squared residual)."""
    am, bm = a.mean(0), b.mean(0)
    r = rotation_of_cross((b - bm).T @ (a - am))
    c = am - r @ bm
    return r, c, float(np.mean(np.sum((a - b @ r.T - c) ** 2, axis=1)))


def trimmed_kabsch(a: np.ndarray, b: np.ndarray, sigmas: float = 3.0, passes: int = 3,
                   start: Optional[Tuple[np.ndarray, np.ndarray]] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`kabsch` refitted ``passes`` times on the pairs whose residual norm is within ``sigmas``
    robust standard deviations (1.4826 MAD) of the last fit's: a VO's relocalisations and glitches, a few
    per cent of its pairs, tilted a flight's rotation by up to 0.5° (EuRoC's ORB-SLAM2 runs; 0.1-0.2° once
    trimmed). ``start``: the plain fit's (R, c) where the caller has it. Returns (R, c, the pairs kept)."""
    keep = np.ones(len(a), dtype=bool)
    r, c = start if start is not None else kabsch(a, b)[:2]
    for _ in range(passes):
        res = np.linalg.norm(a - b @ r.T - c, axis=1)
        new = res <= sigmas * 1.4826 * np.median(res[keep])
        if new.sum() < 3 or np.array_equal(new, keep):
            break
        keep = new
        r, c = kabsch(a[keep], b[keep])[:2]
    return r, c, keep


def rotation_of_cross(h: np.ndarray) -> np.ndarray:
    """The proper rotation R maximising tr(R H) for the cross-covariance H = Σ (b − b̄)(a − ā)ᵀ (Kabsch)."""
    u, _, vt = np.linalg.svd(h)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    return vt.T @ d @ u.T


def shifted_pairs(rates: List[Tuple[np.ndarray, np.ndarray]], shift: float) -> Tuple[np.ndarray, np.ndarray]:
    """IMU rate k paired with GT rate k + shift (linearly interpolated) inside every segment."""
    s, f = math.floor(shift), shift - math.floor(shift)
    a, b = [], []
    for w_imu, w_gt in rates:
        k = np.arange(max(0, -s), len(w_imu) - max(0, s + 1))
        a.append(w_imu[k])
        b.append((1 - f) * w_gt[k + s] + f * w_gt[k + s + 1])
    return np.concatenate(a), np.concatenate(b)


@dataclass
class Offset:
    r_off: np.ndarray  # GT body -> IMU frame: ω_imu ≈ r_off ω_gt + gyro_bias
    gyro_bias: np.ndarray
    tau_s: float  # IMU sample at its stamp t ≈ GT(t + tau_s)
    hold_s: float  # half an IMU period: the shift the zero-order-hold integrator adds (see module doc)
    rms: float  # residual RMS [rad/s] of the rate fit

    @property
    def integrator_shift_s(self) -> float:
        """GT shift that best matches the metric's zero-order-hold integration of the IMU."""
        return self.tau_s - self.hold_s


def fit_offset(segs: List[Segment], m: int = 10, max_shift: int = 20, trim: bool = False) -> Offset:
    """Constant rotation + gyro bias (Kabsch) and time offset (shift grid + parabola) between the
    gyro and the ground truth's angular rate. The rates are compared under the integrator's
    zero-order hold (sample k held on [t_k, t_k+1]); τ adds back the half period, so it is the
    offset of IMU samples taken at their stamps. R_off is re-fitted at the sub-sample shift (a
    misalignment of half a sample alone tilts it by ~0.1°); with ``trim`` on the windows within 3
    robust sigmas (:func:`trimmed_kabsch`: a VO's glitches), ``rms`` staying the plain fit's."""
    rates = [mean_rates(s, m) for s in segs if len(s) > m + 2 * max_shift + 2]
    costs = np.array([kabsch(*shifted_pairs(rates, s))[2] for s in range(-max_shift, max_shift + 1)])
    i = int(np.clip(np.argmin(costs), 1, len(costs) - 2))
    c_m, c_0, c_p = costs[i - 1: i + 2]
    shift = i - max_shift + (0.5 * (c_m - c_p) / (c_m - 2 * c_0 + c_p) if c_m - 2 * c_0 + c_p > 0 else 0.0)
    dt = float(np.median(np.concatenate([np.diff(s.t_ns) for s in segs]))) * 1e-9
    a, b = shifted_pairs(rates, shift)
    r, c, cost = kabsch(a, b)
    if trim:
        r, c, _ = trimmed_kabsch(a, b, start=(r, c))
    return Offset(r, c, (shift + 0.5) * dt, 0.5 * dt, math.sqrt(cost))


def fit_acc_rotation(segs: List[Segment], half: int = 15) -> np.ndarray:
    """GT body -> IMU rotation from specific force (Kabsch, bias = centring term): the smoothed
    accelerometer vs. R_gtᵀ (p̈_gt + g). For a ground robot, which turns about z only, the gyro fixes
    the tilt but not the yaw of R_off; gravity and the horizontal accelerations fix both."""
    from scipy.signal import savgol_filter  # here only: importing scipy.signal costs ~1 s of CPU

    a, b = [], []
    for s in segs:
        if len(s) <= 4 * half:
            continue
        dt = median_period_ns(s.t_ns) * 1e-9
        smooth = lambda x: savgol_filter(x, 2 * half + 1, 2, axis=0)  # noqa: E731
        f_world = np.gradient(np.gradient(smooth(s.p), dt, axis=0), dt, axis=0) + np.array([0.0, 0.0, G])
        f_body = np.einsum("nji,nj->ni", rotation_matrices(s.q_wxyz), f_world)
        keep = slice(2 * half, len(s) - 2 * half)
        a.append(smooth(s.acc)[keep])
        b.append(f_body[keep])
    return kabsch(np.concatenate(a), np.concatenate(b))[0]


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of w,x,y,z quaternions."""
    return np.stack([quat_rotate(q, np.broadcast_to(e, (len(q), 3))) for e in np.eye(3)], axis=2)
