"""A 6-DoF reference in any frame, moved into the IMU's: what ``imu-learn calibrate`` does to a
VIO/SLAM trajectory (camera frame, first-camera world) or any pose file before it fits the floor.

The chain (docs: your-device.md; design: a 6-DoF reference in an unknown frame):

1. **Lag** from the cross-correlation of the angular-rate magnitudes |ω| (a magnitude does not depend
   on the frame), over ``max_lag_s``; the peak's normalised correlation says whether the two
   rotations are the same motion at all. A lag at the search's edge or a weak peak is refused.
2. **Rotation** reference body -> IMU and the gyro bias from matched mean angular rates (Wahba's
   problem by SVD, :func:`imu_learn.eval.groundtruth.fit_offset`, searched around the lag to a
   fraction of a sample), its residual and, from blocks of windows resampled, its uncertainty.
   Motion about one axis only (a ground robot) leaves the rotation about that axis free: the
   rotation then comes from specific force in a level world (gravity and the horizontal
   accelerations), kept only where the rates agree with it and the horizontal accelerations fix it;
   otherwise refused (give ``--extrinsics``).
3. **Gravity, scale and lever arm** in the reference's world by linear least squares over windows of
   ``window_s``:  Σ R_WI f dt = s Δv_ref + Δ(R_WB (ω × r)) + g_up T,  unknowns the reference's
   scale s (metres per reference unit), the lever arm r (IMU origin in the reference body frame) and g_up (the specific force
   of rest, in the reference world). The world is then levelled (g_up to +z),
   the lever arm kept where it is significant. The scale that is applied (and reported) is
   :mod:`.metric_scale`'s, on the positions' changes of mean velocity over half-second spans less the
   lever arm's part (the joint fit's, on velocities, reads low on a noisy reference: 0.85 on a 200 Hz
   pose-only crop), applied where more than 5 % and 4 standard errors off 1 (the joint fit's scale
   where that one is not observed).
4. The reference, rotated, levelled, scaled, moved to the IMU origin and put on the IMU's clock
   (:func:`to_imu_frame`), is then an ordinary ground truth for the floor; where its velocity cannot
   resolve accelerations (:func:`resolves_acceleration`: a 20 Hz VO), the accelerometer comes from its
   positions (:mod:`imu_learn.calib.acc_positions`).

A reference that is already in the IMU frame (rotation below ``identity_deg``, lag within the floor's
own search, level, metric, no lever arm) is returned untouched, so a motion-capture profile stays
what it was. With ``--extrinsics`` (Kalibr / EuRoC ``T_BS``) the rotation and lever arm are given,
not fitted; the lag, gravity and scale still are.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.baselines.base import FitSettings
from imu_learn.calib import metric_scale
from imu_learn.calib.frames import (
    default_gap_s,
    fit_acc_rotation,
    fit_offset,
    kabsch,
    mean_rates,
    rotation_matrices,
    rotation_of_cross,
    segments,
)
from imu_learn.core.quat import quat_conj, quat_from_matrix, quat_mul, quat_rotate
from imu_learn.data.formats.extrinsics import read_t_bs
from imu_learn.data.loading import AlignOptions
from imu_learn.data.types import GroundTruth, ImuData, Segment, sample_rate_hz
from imu_learn.errors import ReferenceFrameError

G = 9.81


@dataclass(frozen=True)
class FrameOptions:
    """``max_lag_s``: the lag search of step 1; ``min_correlation``: the |ω| peak below which the
    reference is not the IMU's motion; ``identity_deg``: a rotation below this is left to the floor's
    misalignment terms (the IMU frame); ``planar_ratio``: the second over the largest spread of the
    rates below which the motion turns about one axis only (:func:`planar_ratio`), as does a rotation whose
    bootstrap spread exceeds ``max_rotation_std_deg`` (then the rotation comes from specific force); ``window_s``: step 3's windows; ``floor_lag_s``: a lag within
    this is left to the floor's own time-offset fit (its search, 3 samples at 200 Hz); an estimated lever
    arm is applied when its norm is ``lever_sigmas`` standard errors and ``min_lever_m`` or more; a
    world is levelled when it is tilted ``level_deg`` or more (below, the tilt cannot be told from the
    accelerometer's bias: 0.34 m/s^2 tilts the estimate by 2°, and the floor's acc bias absorbs it);
    the reference resolves the accelerometer's affine and the low-pass (:func:`resolves_acceleration`)
    when the span its velocity is smoothed over is at most ``acc_span_fraction`` of the floor's window
    ``floor_window_s``."""

    max_lag_s: float = 1.0
    # one rig, one clock: the recordings' lags may spread by this much (real references, one run each:
    # EuRoC's motion capture and ORB-SLAM2 within 10 ms, Fetch 15 ms, BROAD, Blackbird, TUM-VI 0)
    max_lag_spread_s: float = 0.03
    min_correlation: float = 0.6
    identity_deg: float = 1.0
    planar_ratio: float = 0.1
    max_rotation_std_deg: float = 2.0
    max_rate_residual: float = 0.5
    window_s: float = 1.0
    floor_lag_s: float = 0.015
    level_deg: float = 2.0
    # a given extrinsic's rotation may differ from the rates' by at most the larger of these
    # (:func:`check_extrinsic_rotation`)
    extrinsic_tolerance_deg: float = 0.3
    extrinsic_sigmas: float = 3.0
    lever_sigmas: float = 5.0
    min_lever_m: float = 0.02
    floor_window_s: Optional[float] = None
    acc_span_fraction: float = 0.15


@dataclass
class Extrinsics:
    """A known reference body -> IMU transform: ``r_imu_ref`` (ω_imu = R ω_ref) and the IMU origin in
    the reference body frame ``lever_m``."""

    r_imu_ref: np.ndarray
    lever_m: np.ndarray
    source: str


ROTATION_FROM_RATES = "estimated from rotation rates"  # FrameFit.method: the rotation from the rates alone


@dataclass
class FrameFit:
    """What step 1-3 found (module doc); ``in_imu_frame``: nothing to change."""

    r_imu_ref: np.ndarray
    rotation_deg: float
    rotation_std_deg: float
    rate_residual: float  # RMS [rad/s] of the rate fit, against ``rate_rms`` of the motion
    rate_rms: float
    lag_s: float
    lag_correlation: float
    gyro_bias: np.ndarray
    scale: float
    scale_std: float
    lever_m: np.ndarray
    lever_std_m: np.ndarray
    tilt_deg: float  # the largest of the reference worlds' z from up
    g_up: np.ndarray  # (recordings, 3): each recording's specific force of rest in its reference world
    rate_hz: float
    method: str = ROTATION_FROM_RATES  # or the --extrinsics file, or from specific force (planar)
    resolves_acceleration: bool = True  # the acc scale/misalignment and the low-pass are observable
    applied: Dict[str, bool] = field(default_factory=dict)
    planar_ratio: float = math.nan  # the rates' second over largest spread, the lower sensor's (:func:`planar_ratio`)
    # why the metric-scale check (:mod:`.metric_scale`) did not observe the scale ("" where it did); then
    # ``scale`` is the joint fit's (gravity, scale, lever arm), which reads low on a noisy reference, never applied
    scale_not_observed: str = ""

    @property
    def in_imu_frame(self) -> bool:
        return not any(self.applied.values())

    @property
    def turns_about_one_axis(self) -> bool:
        """A ground robot's motion: the rates leave the gyro's scale and misalignment about the other
        axes unexcited (a full floor fits their noise: Fetch's x scale 0.80)."""
        return bool(self.planar_ratio < FrameOptions.planar_ratio)

    def to_dict(self) -> Dict[str, Any]:
        """profile.json's ``reference`` entry."""
        return {
            "rotation_imu_from_reference": self.r_imu_ref.tolist(), "rotation_deg": self.rotation_deg,
            "rotation_std_deg": self.rotation_std_deg, "rate_residual_rad_s": self.rate_residual,
            "rate_rms_rad_s": self.rate_rms, "lag_s": self.lag_s, "lag_correlation": self.lag_correlation,
            "scale": self.scale, "scale_std": self.scale_std, "lever_arm_m": self.lever_m.tolist(),
            "lever_arm_std_m": self.lever_std_m.tolist(), "world_tilt_deg": self.tilt_deg,
            "gravity_in_reference_world": np.asarray(self.g_up).tolist(),
            "reference_rate_hz": self.rate_hz, "rotation_from": self.method,
            "resolves_acceleration": self.resolves_acceleration, "planar_ratio": self.planar_ratio,
            "applied": dict(self.applied),
            "scale_from": ("the joint fit of gravity, scale and lever arm (the metric-scale check did not observe it: "
                           f"{self.scale_not_observed}; not applied)" if self.scale_not_observed
                           else "the metric-scale check (calib/metric_scale.py)"),
        }


LEVER_MAX_STD_M = 0.02  # a reference origin estimated no better than this per axis is not used (zero instead)
# a joint-fit scale not 3 standard errors above zero is a reference that does not follow the accelerometer where a
# MEMS accelerometer bias (metric_scale.ACC_BIAS_CLASS) moves it by less than this; beyond, the motion cannot tell
# (a bias that moves it by a third takes a metric reference to zero at three of its moves; Fetch's steady turns
# 0.40-0.57, its varied recordings 0.05-0.07, EuRoC's flights at most 0.02)
MAX_BIAS_LEVERAGE = 1.0 / 3.0


def applied_extrinsic(entry: Dict[str, Any]) -> Optional[Tuple[np.ndarray, float, str]]:
    """From profile.json's ``reference`` entry (:meth:`FrameFit.to_dict`): (T_BS (4x4) of the reference's
    frame in the IMU's, the rotation [deg], words for its origin) where calibrate applied a rotation, else
    None. The origin: the applied lever arm, else the one the accelerometer's fit against the positions
    estimated (``accelerometer_from_positions``) where it is within :data:`LEVER_MAX_STD_M` on every axis,
    else zero. EuRoC's camera on V1_03 with a profile of MH_03 against ORB-SLAM2 (trial1): the origin at
    zero doubled the aligned RMSE (0.066 against 0.032 m with cam0_sensor.yaml); the positions' estimate
    (-0.8, -5.8, 0.3) cm, cam0's (-2.2, -6.5, 1.0)."""
    applied = entry.get("applied") or {}
    if not applied.get("rotation") or entry.get("rotation_imu_from_reference") is None:
        return None
    T = np.eye(4)
    T[:3, :3] = np.asarray(entry["rotation_imu_from_reference"], dtype=np.float64)
    T[:3, 3], where = _origin(entry)
    return T, float(entry.get("rotation_deg", math.nan)), where


def _origin(entry: Dict[str, Any]) -> Tuple[np.ndarray, str]:
    """The reference origin in the IMU frame [m] and words (:func:`applied_extrinsic`)."""
    cm = lambda v: ", ".join(f"{100 * x:.1f}" for x in v)  # noqa: E731
    if (entry.get("applied") or {}).get("lever_arm") and entry.get("lever_arm_m") is not None:
        lever = np.asarray(entry["lever_arm_m"], dtype=np.float64)
        return lever, f"origin ({cm(lever)}) cm"
    fit = entry.get("accelerometer_from_positions") or {}
    lever, std = fit.get("lever_arm_m"), fit.get("lever_arm_std_m")
    if fit.get("fit_lever") and lever is not None and std is not None:
        lever, std = np.asarray(lever, dtype=np.float64), np.asarray(std, dtype=np.float64)
        if np.all(np.isfinite(std)) and np.all(std <= LEVER_MAX_STD_M):
            return lever, f"origin ({cm(lever)}) +- ({cm(std)}) cm from the accelerometer against its positions"
    return np.zeros(3), "origin at the IMU's (not estimated: give --extrinsics with the sensor's position)"


# ---------------------------------------------------------------------------------------------
# step 1: the lag from |ω|


def _rates_on_grid(t_s: np.ndarray, q_wxyz: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The reference's angular-rate magnitude on ``grid`` (finite differences of its orientation)."""
    dq = quat_mul(quat_conj(q_wxyz[:-1]), q_wxyz[1:])
    ang = 2 * np.arctan2(np.linalg.norm(dq[:, 1:], axis=1), np.abs(dq[:, 0]))
    w = ang / np.maximum(np.diff(t_s), 1e-9)
    return np.interp(grid, 0.5 * (t_s[1:] + t_s[:-1]), w)


def glitch_cap(imu_rates: np.ndarray) -> float:
    """The highest |ω| [rad/s] a reference can show where the gyro saw ``imu_rates``: 1.5 × the gyro's
    99.9th percentile + 0.05 rad/s. Above it a reference's rate is a glitch of its own (a motion-capture
    quaternion that jumps for one frame: Fetch's reach 38 rad/s where the gyro reads 0.06), which would
    otherwise decide a correlation of a few thousand samples."""
    return float(1.5 * np.percentile(imu_rates, 99.9) + 0.05) if len(imu_rates) else math.inf


def fit_lag(imu: ImuData, ref: GroundTruth, max_lag_s: float, dt_s: float = 0.005) -> Tuple[float, float, bool]:
    """(lag [s]: the IMU at t matches the reference at t + lag, normalised correlation of the peak, at
    the search's edge) from |ω| on a common grid of ``dt_s``, the reference's glitches capped
    (:func:`glitch_cap`), both smoothed to the reference's own rate."""
    t_i, t_r = imu.t_ns * 1e-9, ref.t_ns * 1e-9
    t0, t1 = max(t_i[0], t_r[0]), min(t_i[-1], t_r[-1])
    if t1 - t0 < 4 * max_lag_s:
        raise ReferenceFrameError(f"the reference overlaps the IMU for {max(t1 - t0, 0):.1f} s; the frame check "
                                  f"needs {4 * max_lag_s:g} s: check both files' time units and clocks")
    grid = np.arange(t0, t1, dt_s)
    ref_period = float(np.median(np.diff(t_r)))
    k = max(1, int(round(ref_period / dt_s)))
    box = np.ones(k) / k
    wi = np.interp(grid, t_i, np.linalg.norm(imu.gyro, axis=1))
    wr = np.minimum(_rates_on_grid(t_r, ref.q_wxyz, grid), glitch_cap(wi))
    wi, wr = np.convolve(wi, box, "same"), np.convolve(wr, box, "same")
    wi, wr = wi - wi.mean(), wr - wr.mean()
    n = len(grid)
    size = 1 << int(math.ceil(math.log2(2 * n)))
    xc = np.fft.irfft(np.fft.rfft(wr, size) * np.conj(np.fft.rfft(wi, size)), size)
    m = int(round(max_lag_s / dt_s))
    lags = np.r_[0:m + 1, -m:0]
    vals = np.r_[xc[:m + 1], xc[size - m:]]
    overlap = n - np.abs(lags)
    vals = vals / overlap
    i = int(np.argmax(vals))
    lag = lags[i]
    a = wi[max(0, -lag):n - max(0, lag)]
    b = wr[max(0, lag):n - max(0, -lag)] if lag >= 0 else wr[:n + lag]
    corr = float(np.corrcoef(a, b)[0, 1]) if len(a) > 10 else 0.0
    return float(lag * dt_s), corr, abs(lag) >= m - 1


# ---------------------------------------------------------------------------------------------
# step 2: the rotation


def rate_window(imu_rate: float, ref_rate: float) -> int:
    """Mean rates over at least two reference periods (a 20 Hz VO: 100 ms), at least 10 samples."""
    return max(10, int(round(2 * imu_rate / max(ref_rate, 1e-9))))


Rates = Tuple[np.ndarray, np.ndarray]  # (IMU, reference) mean rates of every window, concatenated


def matched_rates(segs: Sequence[Segment], m: int) -> Rates:
    """The mean angular rates over ``m``-sample windows of every segment long enough (computed once for
    every step that matches them: the spread, the planar test, the bias, the residual)."""
    rates = [mean_rates(s, m) for s in segs if len(s) > 2 * m]
    if not rates:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.concatenate([r[0] for r in rates]), np.concatenate([r[1] for r in rates])


def rotation_spread(rates: Rates, blocks: int = 20, seed: int = 0) -> float:
    """Standard deviation [deg] of the fitted rotation over blocks of windows resampled (a bootstrap).
    Each draw's rotation is Kabsch's on the drawn blocks, from their sums (count, Σa, Σb, Σ b aᵀ per
    block, taken once): the cross-covariance of a draw is Σ S_ba − (Σ S_b)(Σ S_a)ᵀ / n."""
    a, b = rates
    if not len(a):
        return math.nan
    r0 = kabsch(a, b)[0]
    edges = np.linspace(0, len(a), blocks + 1).astype(int)
    n = np.diff(edges).astype(np.float64)
    s_a = np.stack([a[edges[j]:edges[j + 1]].sum(0) for j in range(blocks)])
    s_b = np.stack([b[edges[j]:edges[j + 1]].sum(0) for j in range(blocks)])
    s_ba = np.stack([b[edges[j]:edges[j + 1]].T @ a[edges[j]:edges[j + 1]] for j in range(blocks)])
    rng = np.random.default_rng(seed)
    angles = []
    for _ in range(30):
        pick = rng.integers(0, blocks, blocks)
        count = n[pick].sum()
        if count < 3:
            continue
        h = s_ba[pick].sum(0) - np.outer(s_b[pick].sum(0), s_a[pick].sum(0)) / count
        angles.append(_angle_deg(rotation_of_cross(h) @ r0.T))
    return float(np.sqrt(np.mean(np.square(angles)))) if angles else math.nan


def _angle_deg(r: np.ndarray) -> float:
    return math.degrees(math.acos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0)))


def planar_ratio(rates: Rates) -> float:
    """The one rule for "turns about one axis only" (below :attr:`FrameOptions.planar_ratio`): the second
    over the largest spread of the centred rates along their principal axes, the lower of the two
    sensors' (a 90 Hz motion capture's rates carry its noise on every axis: Fetch's 07_left_turn reads
    0.22 in the reference, 0.07 in the gyro). Rates about two axes fix a rotation; about one they do not."""
    out = []
    for x in rates:
        sv = np.linalg.svd(x - x.mean(0), compute_uv=False) if len(x) > 2 else np.zeros(2)
        out.append(float(sv[1] / max(sv[0], 1e-12)))
    return min(out)


# ---------------------------------------------------------------------------------------------
# step 3: gravity, scale, lever arm


def _window_rows(s: Segment, r_imu_ref: np.ndarray, gyro_bias: np.ndarray, n: int
                 ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows of step 3's least squares over non-overlapping windows of ``n`` samples of one segment:
    unknowns (s, r(3), g_up(3)); and each row's ``∫ R_wi dt`` (3 columns: what an accelerometer bias along
    each IMU axis adds to it)."""
    dt = np.diff(s.t_ns) * 1e-9
    r_wb = rotation_matrices(s.q_wxyz)
    r_wi = r_wb @ r_imu_ref.T
    f_w = np.einsum("nij,nj->ni", r_wi, s.acc)[:-1] * dt[:, None]
    c_f = np.concatenate([np.zeros((1, 3)), np.cumsum(f_w, 0)])
    c_r = np.concatenate([np.zeros((1, 3, 3)), np.cumsum(r_wi[:-1] * dt[:, None, None], 0)])
    w_b = (s.gyro - gyro_bias) @ r_imu_ref  # in the reference body frame
    lever_v = r_wb @ _skew(w_b)  # v_lever = R_WB (ω × r) = R_WB [ω]x r
    starts = np.arange(0, len(s) - n, n)
    ends = starts + n
    rows, ys = [], []
    for i0, i1 in zip(starts, ends):
        t = (s.t_ns[i1] - s.t_ns[i0]) * 1e-9
        a = np.zeros((3, 7))
        a[:, 0] = s.v[i1] - s.v[i0]
        a[:, 1:4] = lever_v[i1] - lever_v[i0]
        a[:, 4:7] = np.eye(3) * t
        rows.append(a)
        ys.append(c_f[i1] - c_f[i0])
    if not rows:
        return np.zeros((0, 7)), np.zeros(0), np.zeros((0, 3))
    return np.concatenate(rows), np.concatenate(ys), (c_r[ends] - c_r[starts]).reshape(-1, 3)


def _skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], -1), np.stack([v[:, 2], z, -v[:, 0]], -1),
                     np.stack([-v[:, 1], v[:, 0], z], -1)], 1)


def fit_gravity_scale_lever(recordings: Sequence[Sequence[Segment]], r_imu_ref: np.ndarray, gyro_bias: np.ndarray,
                            window_s: float) -> Dict[str, np.ndarray]:
    """Step 3 (module doc): x = (s, r, g_up of each recording: each has its own world) with standard
    errors, robust (Huber reweighting). The acc bias is left to the floor: on a platform that stays
    near level it is collinear with g_up (body z stays along world up), and |b_a| / g tilts the world
    by a fraction of a degree at most. Its leverage on s is measured: ``scale_bias_std``, how far an
    accelerometer bias of :data:`.metric_scale.ACC_BIAS_CLASS` moves s (a steady turn: 0.5 and more)."""
    k = len(recordings)
    rows, ys, bias_cols = [], [], []
    for i, segs in enumerate(recordings):
        for s in segs:
            n = int(round(window_s / (np.median(np.diff(s.t_ns)) * 1e-9)))
            if len(s) > n + 1:
                a, y, b = _window_rows(s, r_imu_ref, gyro_bias, n)
                bias_cols.append(b)
                wide = np.zeros((len(a), 4 + 3 * k))
                wide[:, :4] = a[:, :4]
                wide[:, 4 + 3 * i:7 + 3 * i] = a[:, 4:7]
                rows.append(wide)
                ys.append(y)
    if not rows:
        raise ReferenceFrameError(f"no stretch of the reference is longer than {window_s:g} s without a gap: "
                                  "raise --max-gap-s")
    a = np.concatenate(rows)
    y = np.concatenate(ys)
    if np.any(np.abs(a[:, 4:]).sum(0) == 0):
        raise ReferenceFrameError(f"a recording has no stretch of the reference longer than {window_s:g} s without a "
                                  "gap: raise --max-gap-s")
    w = np.ones(len(y))
    for _ in range(5):  # Huber on 3-vectors: a window with a loop-closure jump pulls only linearly
        sw = np.sqrt(w)
        x, *_ = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)
        res = (y - a @ x).reshape(-1, 3)
        norm = np.linalg.norm(res, axis=1)
        cap = 1.5 * np.median(norm) + 1e-12
        w = np.repeat(np.minimum(1.0, cap / np.maximum(norm, 1e-12)), 3)
    res = y - a @ x
    s2 = float(np.sum(w * res**2) / max(1, len(y) - a.shape[1]))
    normal_inv = np.linalg.pinv((a * w[:, None]).T @ a)
    cov = s2 * normal_inv
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    leverage = (normal_inv @ (a * w[:, None]).T @ np.concatenate(bias_cols))[0]
    return {"scale": x[0], "scale_std": se[0], "lever": x[1:4], "lever_std": se[1:4],
            "g_up": x[4:].reshape(k, 3),
            "scale_bias_std": metric_scale.ACC_BIAS_CLASS * float(np.linalg.norm(leverage))}


def reference_scale(recordings: Sequence[Sequence[Segment]], r_imu_ref: np.ndarray, ref_rate_hz: float,
                    lever_m: np.ndarray) -> metric_scale.ScaleFit:
    """The reference's metric scale (:mod:`.metric_scale`): its positions, interpolated on the IMU's stamps,
    at rows of its own rate (at most 40 Hz), against the IMU's specific force turned into its world by
    its own attitude (``R_ref r_imu_refᵀ``) at every IMU sample, less what the lever arm ``lever_m`` (the
    IMU origin in the reference's body frame [m]) adds to the IMU origin's change of mean velocity;
    each segment's gravity its own, no accelerometer bias (navigate's model,
    :func:`imu_learn.fuse.noise_fit.fit_scale`): a multirotor's specific force lies along its thrust axis
    at about g, so a bias there is nearly the scale's own column (R^2 0.83-0.87 on EuRoC's VO) and took
    the VO's noise into the scale: +9 % on V1_03's ORB-SLAM2 poses, 1.103 against 1.026 without."""
    parts, bias_rows, stride, span = [], [], 1, float("nan")
    for segs in recordings:
        for s in segs:
            t = (s.t_ns - s.t_ns[0]) * 1e-9
            imu_rate = sample_rate_hz(s.t_ns)
            step = max(1, int(round(imu_rate / min(ref_rate_hz, 40.0))))
            rows = np.arange(0, len(s), step)
            tau = t[rows]
            stride = metric_scale.stride_of(step / imu_rate)
            span = stride * step / imu_rate
            a = np.arange(max(len(rows) - 2 * stride, 0))
            if not len(a):
                continue
            dt = np.r_[np.diff(t), 0.0]
            F = quat_rotate(s.q_wxyz, s.acc @ r_imu_ref) * dt[:, None]  # R_ref r_imu_refᵀ f dt
            d_vo, d1, d2 = metric_scale.triples(tau, s.p[rows], a, stride)
            arm, _, _ = metric_scale.triples(tau, quat_rotate(s.q_wxyz[rows], np.broadcast_to(lever_m, (len(rows), 3))),
                                             a, stride)
            imu = metric_scale.kernel_integral(metric_scale.running_integrals(t, F), tau, a, stride)
            parts.append((d_vo, imu - arm, 0.5 * (d1 + d2)))
            # ∫ k R ds of a unit bias along each IMU axis: the leverage of an accelerometer bias on the scale
            bias_rows.append(np.stack([metric_scale.kernel_integral(metric_scale.running_integrals(
                t, quat_rotate(s.q_wxyz, np.broadcast_to(r_imu_ref[j], (len(t), 3))) * dt[:, None]), tau, a, stride)
                for j in range(3)], axis=2))
    return metric_scale.fit(parts, stride, span, bias_rows)


def level_rotation(g_up: np.ndarray) -> np.ndarray:
    """The smallest rotation taking ``g_up``'s direction to +z."""
    return smallest_rotation(g_up, np.array([0.0, 0.0, 1.0]))


def smallest_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking ``a``'s direction to ``b``'s."""
    u, z = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = np.cross(u, z), float(u @ z)
    if np.linalg.norm(v) < 1e-12:
        if c > 0:
            return np.eye(3)
        e = np.eye(3)[int(np.argmin(np.abs(z)))]  # half a turn about an axis normal to b (+z: about x)
        n = e - (e @ z) * z
        n /= np.linalg.norm(n)
        return 2 * np.outer(n, n) - np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


# ---------------------------------------------------------------------------------------------
# the whole chain


def check_one_clock(lags: Sequence[float], names: Sequence[str], spread_s: float) -> None:
    """One lag is applied to every recording (one rig): refused where the recordings' own lags spread
    by more than ``spread_s`` (a reference on another clock), each recording's lag named."""
    if len(lags) < 2 or max(lags) - min(lags) <= spread_s:
        return
    each = ", ".join(f"{n} {x * 1e3:+.0f} ms" for n, x in zip(names, lags))
    raise ReferenceFrameError(
        f"the references' lags behind their IMUs disagree ({each}; spread above {spread_s * 1e3:.0f} ms): a "
        "reference on another clock; put every reference on its IMU's clock, or calibrate them in separate runs")


def motion_rms(segs: Sequence[Segment], gyro_bias: np.ndarray) -> float:
    """The RMS [rad/s] of the bias-removed gyro over ``segs``: the motion a rate fit's residual is judged
    against (``FrameOptions.max_rate_residual``: above that share, the rates match in no frame)."""
    return float(np.sqrt(np.mean(np.concatenate([np.sum(np.square(s.gyro - gyro_bias), 1) for s in segs]))))


def resolve_frame(pairs: Sequence[Tuple[ImuData, GroundTruth]], options: FrameOptions = FrameOptions(),
                  extrinsics: Optional[Extrinsics] = None, max_gap_s: Optional[float] = None,
                  names: Optional[Sequence[str]] = None) -> FrameFit:
    """Steps 1-3 over every (IMU, reference) pair of one device and one reference kind (one rig)."""
    names = list(names or [f"recording {i + 1}" for i in range(len(pairs))])
    lags = []
    for (imu, ref), name in zip(pairs, names):
        check_orientation(ref, name)
        check_not_odometry(ref, name)
        try:
            lag, corr, edge = fit_lag(imu, ref, options.max_lag_s)
        except ReferenceFrameError as e:  # which pair, with several
            raise ReferenceFrameError(f"{name}: {e}") from None
        if corr < options.min_correlation:
            raise ReferenceFrameError(
                f"{name}: the reference's rotation does not follow the IMU's (|w| correlation {corr:.2f} at its best "
                f"lag, within +-{options.max_lag_s:g} s): a reference of another recording, a time unit off, or a "
                "lag beyond the search; check the files (imu-learn groundtruth)")
        if edge:
            raise ReferenceFrameError(f"{name}: the reference lags the IMU by {lag:+.2f} s or more (the search's edge, "
                                      f"+-{options.max_lag_s:g} s): put both on one clock")
        lags.append((lag, corr))
    lag = float(np.median([x[0] for x in lags]))
    corr = float(min(x[1] for x in lags))
    check_one_clock([x[0] for x in lags], names, options.max_lag_spread_s)
    imu_rate = sample_rate_hz(pairs[0][0].t_ns)
    ref_rate = float(np.median([sample_rate_hz(ref.t_ns) for _, ref in pairs]))
    coarse = lag if abs(lag) > options.floor_lag_s else 0.0
    per: List[List[Segment]] = []
    for (imu, ref), name in zip(pairs, names):
        gap = max_gap_s if max_gap_s is not None else default_gap_s(ref)
        per.append(segments(imu, ref, gap, shift_s=coarse, name=name))
    segs = [s for p in per for s in p]
    if not segs:
        raise ReferenceFrameError("no stretch of IMU samples with the reference: check --max-gap-s and the clocks")
    m = rate_window(imu_rate, ref_rate)
    rates = matched_rates(segs, m)
    ratio = planar_ratio(rates)
    off = fit_offset(segs, m=m, max_shift=max(3, int(round(0.02 * imu_rate))), trim=True)
    w_rms = motion_rms(segs, off.gyro_bias)
    method = extrinsics.source if extrinsics is not None else ROTATION_FROM_RATES
    if off.rms > options.max_rate_residual * w_rms:  # the file itself, whatever --extrinsics says
        raise ReferenceFrameError(f"the reference's {no_frame(off.rms, w_rms)}")
    if extrinsics is None:
        r_imu_ref, lever0 = off.r_off, np.zeros(3)
        rot_std = rotation_spread(rates)
        if ratio < options.planar_ratio or rot_std > options.max_rotation_std_deg:
            r_imu_ref = planar_rotation(segs, rates, off.rms, ratio)
            rot_std, method = math.nan, "from specific force: the motion turns about one axis only"
    else:
        check_extrinsic_rotation(extrinsics, off.r_off, rates, ratio, options)
        r_imu_ref, lever0 = extrinsics.r_imu_ref, extrinsics.lever_m
        rot_std = 0.0
    gyro_bias = off.gyro_bias if method == "estimated from rotation rates" else _bias_given(rates, r_imu_ref)
    sol = fit_gravity_scale_lever(per, r_imu_ref, gyro_bias, options.window_s)
    g_up = sol["g_up"]
    tilt = max(math.degrees(math.acos(np.clip(g[2] / max(np.linalg.norm(g), 1e-12), -1, 1))) for g in g_up)
    rot_deg = _angle_deg(r_imu_ref)
    if sol["scale"] < 3 * sol["scale_std"] or sol["scale"] <= 0.05:
        if sol["scale_bias_std"] > MAX_BIAS_LEVERAGE:
            # a MEMS bias moves the scale (metres per unit) by a third or more: the motion cannot check the
            # translation (a reference in mm or cm moves it 1000 or 100 times less), and a frame from specific force
            # is then unchecked too (Fetch's 06_right_turn alone: 6.4° from it, the profile's gyro bias 0.03 rad/s
            # and acc bias 0.75 m/s² off the other recordings'); refused, naming the cause
            raise ReferenceFrameError(
                f"the reference's translation cannot be checked against the accelerometer (scale {sol['scale']:.3f} ± "
                f"{sol['scale_std']:.3f}; a {metric_scale.ACC_BIAS_CLASS:g} m/s^2 accelerometer bias moves it by "
                f"±{sol['scale_bias_std']:.2f}): the motion keeps its acceleration fixed in the body (a steady turn) "
                "or barely accelerates; calibrate on recordings of varied motion together (several --input)")
        unit = _unit_off(float(sol["scale"]), float(sol["scale_std"]))
        if unit:
            raise ReferenceFrameError(
                f"the reference's positions are x{1 / sol['scale']:.4g} the distances the accelerometer measures "
                f"(scale {sol['scale']:.4g} +- {sol['scale_std']:.2g} m per unit): {unit}? give them in metres")
        raise ReferenceFrameError(
            f"the reference's translation does not follow the accelerometer (scale {sol['scale']:.3f} ± "
            f"{sol['scale_std']:.3f}): " + (f"--extrinsics {extrinsics.source} in the wrong direction (T_BS is the "
                                              "sensor's pose in the IMU frame), " if extrinsics is not None else "")
            + "a mirrored axis, positions of another recording, or a reference that barely moves; check the file "
            "(imu-learn groundtruth)")
    lever_sig = (np.linalg.norm(sol["lever"]) > options.lever_sigmas * np.linalg.norm(sol["lever_std"])
                 and np.linalg.norm(sol["lever"]) > options.min_lever_m)
    lever = lever0 if extrinsics is not None else (sol["lever"] if lever_sig else np.zeros(3))
    metric = reference_scale(per, r_imu_ref, ref_rate, lever)
    scale_off = metric.off  # the scale applied is metric_scale's (the joint fit's reads low on a noisy velocity)
    applied = {"rotation": rot_deg >= options.identity_deg or extrinsics is not None, "lag": coarse != 0.0,
               "level": tilt >= options.level_deg, "scale": bool(scale_off),
               "lever_arm": bool(np.linalg.norm(lever) > 0)}
    return FrameFit(r_imu_ref, rot_deg, rot_std, off.rms, w_rms, coarse if coarse else lag, corr, gyro_bias,
                    *((1.0 / metric.scale, metric.std / metric.scale ** 2) if metric.observed
                      else (float(sol["scale"]), float(sol["scale_std"]))), lever,
                    np.zeros(3) if extrinsics is not None else sol["lever_std"], tilt, g_up, ref_rate, method,
                    resolves_acceleration(ref_rate, options.floor_window_s or FitSettings().window / imu_rate,
                                          options.acc_span_fraction), applied, ratio,
                    "" if metric.observed else (metric.reason or "no estimate"))


def no_frame(residual: float, motion: float) -> str:
    """The words for rotation rates that no rotation maps onto the gyro's (the fit's ``residual`` against the
    ``motion``'s RMS, rad/s), and their usual causes: one text for calibrate, groundtruth and navigate."""
    return (f"rotation rates do not match the IMU's in any frame (residual {residual:.3f} rad/s against {motion:.3f} "
            "rad/s of motion): a gyro unit, a mirrored or swapped axis, another recording (or a clock off), or its "
            "quaternions in another order (a TUM row is t x y z qx qy qz qw, scalar last)")


def check_extrinsic_rotation(extrinsics: Extrinsics, r_rates: np.ndarray, rates: Rates, ratio: float,
                             options: FrameOptions) -> None:
    """A given extrinsic whose rotation the rates contradict is refused: more than
    ``options.extrinsic_tolerance_deg`` and ``options.extrinsic_sigmas`` bootstrap spreads
    (:func:`rotation_spread`) from the rotation the rates give (step 2). The reference is then in
    another frame than the file's (ORB-SLAM2's stereo poses are the rectified left camera's, 0.6° off
    EuRoC's cam0), and the floor's gyroscope matrix would take up the difference: a misalignment
    that holds for that reference and harms every other recording. Not checked where the rates
    cannot fix the rotation (motion about one axis)."""
    if ratio < options.planar_ratio:
        return
    spread = rotation_spread(rates)
    off = _angle_deg(r_rates @ extrinsics.r_imu_ref.T)
    if spread <= options.max_rotation_std_deg and off > max(options.extrinsic_tolerance_deg,
                                                            options.extrinsic_sigmas * spread):
        inverted = _angle_deg(r_rates @ extrinsics.r_imu_ref)  # the file's rotation taken the other way
        if inverted < max(options.extrinsic_tolerance_deg, options.extrinsic_sigmas * spread, 1.0):
            raise ReferenceFrameError(
                f"--extrinsics {extrinsics.source}: its rotation is {off:.2f}° off the one the rotation rates give, "
                f"its inverse {inverted:.2f}°: the file holds T_SB (the IMU in the sensor's frame), not T_BS (the "
                "sensor's pose in the IMU frame, Kalibr's and EuRoC's sensor.yaml); invert it, or leave --extrinsics "
                "out to have the rotation estimated")
        raise ReferenceFrameError(
            f"--extrinsics {extrinsics.source}: its rotation is {off:.2f}° off the one the rotation rates give "
            f"(± {spread:.2f}°): the reference is in another frame than the file's (a rectified camera's?); leave "
            "--extrinsics out to have the rotation estimated, or give the frame the poses are in")


UNITS = {"millimetres": 1e-3, "centimetres": 1e-2}  # what a scale below 0.05 (refused) points at


def _unit_off(scale: float, std: float) -> str:
    """The length unit a well-determined scale [m per reference unit] points at ("" where none: within
    10 % and 5 standard errors of one of :data:`UNITS`). Larger scales are a monocular VO's or feet,
    which :mod:`.metric_scale` reads and applies."""
    if not (scale > 10 * std > 0):
        return ""
    near = [u for u, k in UNITS.items() if abs(scale - k) < max(0.1 * k, 5 * std)]
    return f"positions in {near[0]}" if near else ""


def resolves_acceleration(ref_rate_hz: float, window_s: float, fraction: float = FrameOptions.acc_span_fraction) -> bool:
    """Whether a reference at ``ref_rate_hz`` can tell the accelerometer's scale and misalignment and
    choose a low-pass: the velocity of a pose-only reference comes from a local quadratic over
    2·h + 1 poses (:class:`imu_learn.data.loading.AlignOptions`, h = ``velocity_half_window``), which
    attenuates every acceleration faster than that span; where the span is more than ``fraction`` of
    the floor's window ``window_s`` (a 20 Hz VO: 0.45 s against 1 s) the smoothed reference
    favours an accelerometer scaled down and low-passed, an artefact of the reference, not the IMU.
    EuRoC's 200 Hz, TUM-VI's 120 Hz and Fetch's 90 Hz motion capture resolve it (0.05-0.1 s). Where
    it does not, the floor fits no low-pass and the acc bias only, and calibrate then fits the
    accelerometer's matrix and bias from the reference's positions instead, which no smoothing
    attenuates (:mod:`imu_learn.calib.acc_positions`, :meth:`imu_learn.calib.sources.PosesSource.acc_from_positions`)."""
    span_s = (2 * AlignOptions().velocity_half_window + 1) / max(ref_rate_hz, 1e-9)
    return span_s <= fraction * window_s


def planar_rotation(segs: Sequence[Segment], rates: Rates, rate_rms: float, ratio: float) -> np.ndarray:
    """Motion about one axis (a ground robot) leaves the rotation about it free in the rates: the
    rotation from specific force instead (gravity and the horizontal accelerations, in a level reference
    world; :func:`imu_learn.eval.groundtruth.fit_acc_rotation`), kept only if the rates agree with it."""
    horizontal = _horizontal_acc_rms(segs)
    if horizontal < MIN_HORIZONTAL_ACC:
        raise ReferenceFrameError(
            f"the reference turns about one axis only (rate spread ratio {ratio:.3f}) with too little horizontal "
            f"acceleration to fix the rest ({horizontal:.3f} m/s^2 RMS): the rotation between its frame and the IMU is "
            "not observable from this motion; give --extrinsics FILE (planar wheel odometry observes yaw rate and "
            "speed only)")
    r = turn_axis_on_gyro(fit_acc_rotation(list(segs)), rates)
    bias = _bias_given(rates, r)
    res = _rate_residual(rates, r, bias)
    if res > 2 * rate_rms + 0.01:
        raise ReferenceFrameError(
            f"the reference turns about one axis only (rate spread ratio {ratio:.3f}) and its specific force does not "
            f"fix the rest (rate residual {res:.3f} rad/s with it): the rotation between its frame and the IMU is not "
            "observable from this motion; give --extrinsics FILE (planar wheel odometry observes yaw rate and speed "
            "only)")
    return r


def turn_axis_on_gyro(r_acc: np.ndarray, rates: Rates) -> np.ndarray:
    """``r_acc`` (reference body -> IMU from specific force) turned by the smallest rotation that puts the
    reference's turning axis on the gyro's (each the principal axis of its mean rates, centred: no bias
    enters). The rates fix that axis to a fraction of a degree; specific force fixes the rotation about it
    (the horizontal accelerations) but tilts it as far as the accelerometer couples its axes or the
    reference's accelerations are noisy (the plane of the turns, centred: gravity does not enter). On
    Fetch the specific force alone was 1-6° off, and the rotation worse for the turns' own rates than
    none: 1 s rotation 1.21° against 1.01°; with the gyro's axis 0.92°."""
    a, b = (x - x.mean(0) for x in rates)
    ax_imu, ax_ref = (np.linalg.svd(x, full_matrices=False)[2][0] for x in (a, b))
    if float((a @ ax_imu) @ (b @ ax_ref)) < 0:
        ax_ref = -ax_ref
    return smallest_rotation(r_acc @ ax_ref, ax_imu) @ r_acc


MIN_HORIZONTAL_ACC = 0.05  # [m/s^2] RMS of the reference's horizontal acceleration that fixes a yaw


def _horizontal_acc_rms(segs: Sequence[Segment]) -> float:
    """RMS of the reference's horizontal acceleration (its velocity differentiated over 0.2 s)."""
    out = []
    for s in segs:
        dt = np.median(np.diff(s.t_ns)) * 1e-9
        k = max(1, int(round(0.2 / dt)))
        if len(s) > 2 * k:
            out.append((s.v[k:, :2] - s.v[:-k, :2]) / (k * dt))
    return float(np.sqrt(np.mean(np.sum(np.concatenate(out) ** 2, axis=1)))) if out else 0.0


def _rate_residual(rates: Rates, r: np.ndarray, bias: np.ndarray) -> float:
    a, b = rates
    return float(np.sqrt(np.mean(np.sum((a - bias - b @ r.T) ** 2, axis=1))))


def _bias_given(rates: Rates, r_imu_ref: np.ndarray) -> np.ndarray:
    a, b = rates
    return np.median(a - b @ r_imu_ref.T, axis=0)


def check_orientation(ref: GroundTruth, name: str) -> None:
    """A reference whose orientation never changes holds positions only (e.g. GNSS written as TUM)."""
    dq = quat_mul(quat_conj(ref.q_wxyz[:1]), ref.q_wxyz)
    spread = 2 * np.arcsin(np.clip(np.linalg.norm(dq[:, 1:], axis=1), 0, 1))
    if float(np.max(spread)) < math.radians(0.5):
        raise ReferenceFrameError(
            f"{name}: the reference's orientation never changes (positions only, e.g. GNSS): calibrate needs "
            "6-DoF poses to fit the affine floor; use imu-learn navigate with the positions as aiding, or "
            "calibrate --imu-only for the noise")


PLANAR_TILT_DEG = 0.01  # the planar rule: no orientation tilted more than this from the world's z ...
PLANAR_HEIGHT_M = 1e-6  # ... and a height constant within this


def is_planar_odometry(ref: GroundTruth) -> bool:
    """The planar rule: every orientation a yaw about the world's z and the height constant (wheel
    odometry in ``base_link``)."""
    if len(ref.t_ns) < 2:
        return False
    up = quat_rotate(ref.q_wxyz, np.broadcast_to([0.0, 0.0, 1.0], (len(ref.q_wxyz), 3)))
    tilt = np.degrees(np.arccos(np.clip(up[:, 2], -1.0, 1.0)))
    return bool(float(np.max(tilt)) < PLANAR_TILT_DEG and float(np.ptp(ref.p[:, 2])) < PLANAR_HEIGHT_M)


def check_not_odometry(ref: GroundTruth, name: str) -> None:
    """Planar wheel odometry (every orientation a yaw about the world's z, the height constant;
    :func:`imu_learn.calib.odometry.is_planar_odometry`, the rule calibrate's source selection uses)
    observes yaw rate and forward speed only: the 6-DoF path would fit the IMU's roll and pitch axes
    against zero, so it is not taken here; :class:`imu_learn.calib.odometry.OdometrySource` fits what it
    observes (``imu-learn calibrate --groundtruth`` picks it for such a file)."""
    if is_planar_odometry(ref):
        raise ReferenceFrameError(
            f"{name}: the reference is planar (no roll, no pitch, a constant height: wheel odometry); it observes "
            "yaw rate and forward speed only, not a 6-DoF frame: calibrate reads it as odometry (OdometrySource: the "
            "gyro bias and scale about the vertical axis)")


def to_imu_frame(ref: GroundTruth, fit: FrameFit, index: int) -> GroundTruth:
    """The reference of recording ``index`` (in :func:`resolve_frame`'s order) as the IMU's pose in a
    levelled, metric world on the IMU's clock (what the floor fits against); untouched when nothing
    was applied."""
    if fit.in_imu_frame:
        return ref
    ap = fit.applied
    r_level = level_rotation(fit.g_up[index]) if ap.get("level") else np.eye(3)
    q_level = quat_from_matrix(r_level)
    q_ref_imu = quat_from_matrix(fit.r_imu_ref.T) if ap.get("rotation") else np.array([1.0, 0, 0, 0])
    s = fit.scale if ap.get("scale") else 1.0
    p_w = s * ref.p + (quat_rotate(ref.q_wxyz, np.broadcast_to(fit.lever_m, ref.p.shape)) if ap.get("lever_arm") else 0.0)
    p = p_w @ r_level.T
    q = quat_mul(q_level[None], quat_mul(ref.q_wxyz, q_ref_imu[None]))
    t_ns = ref.t_ns - int(round(fit.lag_s * 1e9)) if ap.get("lag") else ref.t_ns
    v = None if ref.v is None else (s * ref.v) @ r_level.T
    return GroundTruth(t_ns=np.asarray(t_ns, dtype=np.int64), p=np.ascontiguousarray(p),
                       q_wxyz=np.ascontiguousarray(q / np.linalg.norm(q, axis=1, keepdims=True)),
                       v=None if ap.get("lever_arm") else v)


# ---------------------------------------------------------------------------------------------
# --extrinsics


def read_extrinsics(path: Path) -> Extrinsics:
    """A Kalibr / EuRoC ``sensor.yaml``'s ``T_BS`` (the reference sensor's frame in the IMU body frame:
    x_imu = R x_ref + t; :func:`imu_learn.data.formats.extrinsics.read_t_bs`): the rotation, and the
    IMU origin in the reference body frame, R^T (0 - t)."""
    t = read_t_bs(path)
    r, p = t[:3, :3], t[:3, 3]
    return Extrinsics(r, -r.T @ p, f"{path} (T_BS)")


def frame_lines(fit: FrameFit) -> List[str]:
    """What the check found, for the user (one line each)."""
    ap = fit.applied
    unchecked = (f"reference: scale {fit.scale:.4f} ± {fit.scale_std:.4f} from the joint fit alone, not applied (the "
                 f"metric-scale check did not observe it: {fit.scale_not_observed})" if fit.scale_not_observed else "")
    if fit.in_imu_frame:
        return [f"reference: in the IMU frame (rotation {fit.rotation_deg:.2f}°, lag {fit.lag_s * 1e3:+.1f} ms, "
                f"tilt {fit.tilt_deg:.2f}°, scale {fit.scale:.4f} ± {fit.scale_std:.4f})"] + ([unchecked] if unchecked else [])
    spread = f" ± {fit.rotation_std_deg:.2f}°" if math.isfinite(fit.rotation_std_deg) else " (no spread measured)"
    out = [f"reference: rotation to the IMU {fit.rotation_deg:.2f}°{spread} "
           f"({fit.method}; rate residual {fit.rate_residual:.3f} rad/s)"]
    out.append(f"reference: lag {fit.lag_s * 1e3:+.1f} ms (|w| correlation {fit.lag_correlation:.2f})"
               + ("; moved onto the IMU's clock" if ap.get("lag") else "; left to the floor's time offset"))
    out.append(f"reference: world tilted {fit.tilt_deg:.2f}° from gravity" + ("; levelled" if ap.get("level") else ""))
    out.append(unchecked or f"reference: scale {fit.scale:.4f} ± {fit.scale_std:.4f}"
               + ("; applied" if ap.get("scale") else "; metric"))
    if ap.get("lever_arm"):
        out.append(f"reference: IMU origin at ({', '.join(f'{x * 100:+.1f}' for x in fit.lever_m)}) cm in its body frame")
    return out
