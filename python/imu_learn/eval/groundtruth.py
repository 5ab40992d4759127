"""Which ground truth does a recording's own IMU agree with, and in which body frame is it?

For one ground-truth file of a recording (``imu-learn groundtruth --input REC``; the report over
every EuRoC / TUM-VI / Fetch recording is experiments/groundtruth_report.py):

* bias-removed relative pose RMSE (rotation [deg], translation [m]; ``score.metrics.relative_pose_errors``)
  over 10 and 200 IMU samples (0.05 s, 1 s at 200 Hz), every window. The bias: one constant gyro +
  accel bias per recording, fitted over the *whole* recording as in experiments/label_agreement.py
  (medians of 10-sample window residuals / Δt, pooled over the segments);
* R_off (GT body -> IMU: ω_imu ≈ R_off ω_gt + b_g) and τ (IMU sample at its stamp t ≈ GT(t + τ),
  so τ > 0: GT stamps late), fitted jointly: Kabsch (bias = centring term) on 10-sample mean rates
  for every whole-sample shift within ±100 ms, the best one refined by a parabola. The metric's
  integrator holds sample k over [t_k, t_k+1], i.e. it sees the IMU half a period late; the check
  also scores with the GT shifted by τ − dt/2, which undoes that. A ground robot turns about z
  only, so the gyro leaves R_off's yaw free: where the rates turn about one axis only (calibrate's rule,
  :func:`imu_learn.calib.reference.planar_ratio`) or with ``yaw_from_acc``, R_off comes from specific
  force instead (:func:`imu_learn.calib.reference.planar_rotation`: refused where the horizontal
  accelerations cannot fix it);
* the reference world's tilt from gravity (:func:`world_up`: the specific force turned into the world,
  less the change of velocity): a world tilted ``FrameOptions.level_deg`` or more (a VO/SLAM world, the
  first camera frame; a z-down one) is levelled before every translation score and the lever arm,
  which assume gravity along the world's z (rotation scores do not depend on the world);
* the lever arm r of the IMU origin in the GT body frame, by least squares on
  S(R a_imu) − S(p̈_gt) − g = S(R (ω̇× + ω×ω×)) r + S(R) b_a  (world frame; S: one Savitzky-Golay
  smoother on every term, so the equation stays exact), with R_off and τ applied;
* motion capture: orientation noise σ at its own stamps (gyro vs. mocap relative rotation over
  h = 1..10 mocap samples, RMSE² = 2σ² + k h²); raw-gyro bias-removed rotation drift at 5 s / 20 s;
  gaps and how much of a recording survives per ``max_gap_s``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np
from scipy.signal import savgol_filter

from imu_learn.calib.frames import (  # noqa: F401  (re-exported: the check's vocabulary)
    Offset,
    bridging_gap_s,
    default_gap_s,
    fit_acc_rotation,
    fit_offset,
    gap_hint,
    gt_rate_hz,
    kabsch,
    log_q,
    mean_rates,
    rotation_matrices,
    segments,
    shifted_pairs,
)
from imu_learn.calib.reference import (
    FrameOptions,
    fit_lag,
    level_rotation,
    matched_rates,
    motion_rms,
    no_frame,
    planar_ratio,
    planar_rotation,
    reference_scale,
)
from imu_learn.core.integration import integrate_windows, window_labels
from imu_learn.core.quat import quat_conj, quat_from_matrix, quat_mul
from imu_learn.data.formats import read_recording
from imu_learn.data.loading import AlignOptions
from imu_learn.data.types import GroundTruth, ImuData, Segment, median_period_ns
from imu_learn.errors import ReferenceFrameError, TooShortError
from imu_learn.score.metrics import fit_startup_bias, index_at, relative_pose_errors, remove_bias, rmse, with_imu

MIN_SAMPLES = 200  # the longest scored window (n=200): a shorter recording cannot be checked
KEPT_NOTE = 0.8  # a check keeping less of the IMU samples inside the reference's span says so (kept_note)
DRIFT_GAP_S = 0.3  # segments for the 5 s / 20 s drift (windows must fit inside one segment)
G = 9.81


@dataclass(frozen=True)
class CheckOptions:
    """``max_gap_s``: split the ground truth at gaps longer than this (None: :func:`default_gap_s`);
    ``yaw_from_acc``: fit R_off on specific force (a ground robot, turning about z only)."""

    max_gap_s: Optional[float] = None
    yaw_from_acc: bool = False


# ---------------------------------------------------------------------------------------------
# loading


def read(root: Path, groundtruth: Optional[Path] = None, fmt: str = "auto", imu_topic: Optional[str] = None,
         groundtruth_topic: Optional[str] = None) -> Tuple[ImuData, GroundTruth]:
    """The IMU and one ground truth of a recording (``groundtruth``: a file, else the format's own)."""
    return read_recording(Path(root), fmt, groundtruth=groundtruth, imu_topic=imu_topic,
                          groundtruth_topic=groundtruth_topic)


# ---------------------------------------------------------------------------------------------
# bias and scores


def exp_q(v: np.ndarray) -> np.ndarray:
    a = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.concatenate([np.cos(a / 2), np.sinc(a / (2 * np.pi)) * v / 2], -1)


def fit_bias(segs: List[Segment], n: int = 10) -> Tuple[np.ndarray, np.ndarray]:
    """Whole-recording constant (gyro, accel) bias: medians of n-sample window residuals / Δt over
    all segments, the accelerometer one with the gyro bias removed (label_agreement's fit)."""
    rg, ra = [], []
    for s in segs:
        lab = window_labels(s, window=n, stride=n, fractions=[1.0])
        imu = integrate_windows(s, lab.starts, lab.horizons)
        rg.append(log_q(quat_mul(quat_conj(lab.dq_wxyz[:, 0]), imu.dq_wxyz[:, 0])) / lab.dt[:, :1])
    bg = np.median(np.concatenate(rg), axis=0)
    for s in segs:
        lab = window_labels(s, window=n, stride=n, fractions=[1.0])
        imu = integrate_windows(with_imu(s, s.gyro - bg, s.acc), lab.starts, lab.horizons)
        ra.append((imu.dv[:, 0] - lab.dv[:, 0]) / lab.dt[:, :1])
    return bg, np.median(np.concatenate(ra), axis=0)


def pooled_errors(segs: List[Segment], n: int, stride: int = 1, from_s: float = 0.0) -> Tuple[float, float]:
    """(rotation RMSE [deg], translation RMSE [m]) over all windows of n samples that start at least
    ``from_s`` after the first segment's start."""
    t0 = segs[0].t_ns[0]
    rot, trans = [], []
    for s in segs:
        first = index_at(s, max(0.0, (t0 - s.t_ns[0]) * 1e-9 + from_s))
        e = relative_pose_errors(s, n, stride, first=first)
        rot.append(e["rot_rad"])
        trans.append(e["trans_m"])
    return math.degrees(rmse(np.concatenate(rot))), rmse(np.concatenate(trans))


def bias_removed(segs: List[Segment], bg: np.ndarray, ba: np.ndarray) -> List[Segment]:
    return [remove_bias(s, bg, ba) for s in segs]


def bias_removed_score(segs: List[Segment], n: int) -> Tuple[float, float]:
    """(rot [deg], trans [m]) RMSE over n samples with the whole-recording bias removed."""
    return pooled_errors(bias_removed(segs, *fit_bias(segs)), n)


# ---------------------------------------------------------------------------------------------
# rotation / time offset


def angle_axis(r: np.ndarray) -> Tuple[float, np.ndarray]:
    angle = math.acos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0))
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return math.degrees(angle), axis / max(np.linalg.norm(axis), 1e-12)


# ---------------------------------------------------------------------------------------------
# lever arm


def skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], -1), np.stack([v[:, 2], z, -v[:, 0]], -1),
                     np.stack([-v[:, 1], v[:, 0], z], -1)], 1)


def lever_rows(seq: Segment, gyro_bias: np.ndarray, half: int) -> Tuple[np.ndarray, np.ndarray]:
    """Rows of  S(R a_imu) − S(p̈) − g = S(R (ω̇× + ω×ω×)) r + S(R) b_a  in the world frame, S one
    smoothing filter applied to every term alike (the equation stays exact); edges dropped."""
    dt = median_period_ns(seq.t_ns) * 1e-9
    smooth = lambda x: savgol_filter(x, 2 * half + 1, 2, axis=0)  # noqa: E731
    rot = rotation_matrices(seq.q_wxyz)
    w = seq.gyro - gyro_bias
    sw = skew(w)
    a_gt = np.gradient(np.gradient(smooth(seq.p), dt, axis=0), dt, axis=0)
    y = smooth(np.einsum("nij,nj->ni", rot, seq.acc)) - a_gt - np.array([0.0, 0.0, G])
    design = np.concatenate([rot @ (skew(np.gradient(w, dt, axis=0)) + sw @ sw), rot], axis=2)
    design = smooth(design.reshape(len(seq), 18)).reshape(-1, 3, 6)
    keep = slice(2 * half, len(seq) - 2 * half, half)  # every half window: roughly independent rows
    return design[keep].reshape(-1, 6), y[keep].reshape(-1)


def fit_lever_arm(segs: List[Segment], gyro_bias: np.ndarray, half: int = 20) -> Tuple[np.ndarray, np.ndarray]:
    """Lever arm r [m] of the IMU in the (IMU-aligned) GT body frame and its standard error: the larger of
    the least-squares one and the spread of the same fit on four time blocks / 2 (the rows' errors are
    correlated over the smoother's span and the motion: on ORB-SLAM2's flights the least-squares one read
    1.7-3.1 cm where the estimates sat 5-11 cm off the camera's 6.9 cm)."""
    rows = [lever_rows(s, gyro_bias, half) for s in segs if len(s) > 4 * half]
    a, y = np.concatenate([r[0] for r in rows]), np.concatenate([r[1] for r in rows])
    x, *_ = np.linalg.lstsq(a, y, rcond=None)
    s2 = np.sum((y - a @ x) ** 2) / max(1, len(y) - 6)
    se = np.sqrt(np.diag(s2 * np.linalg.inv(a.T @ a)))[:3]
    k = len(y) // 3
    cuts = np.linspace(0, k, 5).astype(int) * 3  # whole 3-vector rows, in time order
    blocks = [np.linalg.lstsq(a[i:j], y[i:j], rcond=None)[0][:3] for i, j in zip(cuts[:-1], cuts[1:]) if j - i > 18]
    if len(blocks) == 4:
        se = np.maximum(se, np.std(blocks, axis=0, ddof=1) / 2)
    return x[:3], se


# ---------------------------------------------------------------------------------------------
# the reference world's gravity


def world_up(segs: List[Segment]) -> np.ndarray:
    """Gravity's up direction in the reference world (``segs`` with the IMU in the reference's body
    frame): the specific force turned into the world, R a = p̈ + g up to noise and bias, summed over each
    segment, less its change of velocity (the reference's positions over half a second at each end)."""
    total, seconds = np.zeros(3), 0.0
    for s in segs:
        dt = np.diff(s.t_ns) * 1e-9
        f = np.einsum("nij,nj->ni", rotation_matrices(s.q_wxyz[:-1]), s.acc[:-1])
        k = max(1, min(len(s) // 4, int(round(0.5 / float(np.median(dt))))))
        v0, v1 = ((s.p[i + k] - s.p[i]) / ((s.t_ns[i + k] - s.t_ns[i]) * 1e-9) for i in (0, len(s) - 1 - k))
        total += (f * dt[:, None]).sum(axis=0) - (v1 - v0)
        seconds += float(dt.sum())
    g = total / max(seconds, 1e-12)
    return g / max(float(np.linalg.norm(g)), 1e-12)


def tilt_deg(up: np.ndarray) -> float:
    """The angle of ``up`` from the world's +z [deg]."""
    return math.degrees(math.acos(float(np.clip(up[2], -1.0, 1.0))))


def levelled(gt: GroundTruth, up: np.ndarray) -> GroundTruth:
    """``gt`` in its world turned by the smallest rotation taking ``up`` to +z (poses and velocities)."""
    r = level_rotation(up)
    q = quat_mul(np.broadcast_to(quat_from_matrix(r), gt.q_wxyz.shape), gt.q_wxyz)
    return replace(gt, p=np.ascontiguousarray(gt.p @ r.T), q_wxyz=np.ascontiguousarray(q),
                   v=None if gt.v is None else np.ascontiguousarray(gt.v @ r.T))


# ---------------------------------------------------------------------------------------------
# motion-capture noise floor and gaps


def mocap_noise(imu: ImuData, gt: GroundTruth, off: Offset, hs=tuple(range(1, 11))) -> Tuple[float, List[float], float]:
    """σ of the mocap orientation [deg] at its own stamps: relative rotation over h mocap samples vs.
    the bias-removed gyro (midpoint rule, time offset and R_off applied); RMSE(h)² = 2σ² + k h².
    Also the lag-1 autocorrelation of the h = 1 errors: −0.5 for white orientation noise."""
    t = gt.t_ns * 1e-9
    dt = np.diff(t)
    t_imu = imu.t_ns * 1e-9
    mid = t[:-1] + dt / 2 - off.tau_s
    w = np.stack([np.interp(mid, t_imu, imu.gyro[:, i]) for i in range(3)], 1)
    step = exp_q(((w - off.gyro_bias) @ off.r_off) * dt[:, None])
    ok = (dt < 1.5 * np.median(dt)) & (mid > t_imu[0]) & (mid < t_imu[-1])
    pred, good, errs, lag1 = step.copy(), ok.copy(), [], float("nan")
    for h in range(1, max(hs) + 1):
        if h > 1:
            pred = quat_mul(pred[:-1], step[h - 1:])
            good = good[:-1] & ok[h - 1:]
        if h in hs:
            rel = quat_mul(quat_conj(gt.q_wxyz[:-h]), gt.q_wxyz[h:])
            e = log_q(quat_mul(quat_conj(rel), pred))
            errs.append(math.degrees(rmse(np.linalg.norm(e, axis=1)[good])))
        if h == 1:
            pair = good[:-1] & good[1:]
            lag1 = float(np.mean([np.corrcoef(e[:-1][pair, i], e[1:][pair, i])[0, 1] for i in range(3)]))
    h = np.asarray(hs, dtype=float)
    slope_fit = np.polyfit(h**2, np.square(errs), 1)
    return math.sqrt(max(slope_fit[1], 0.0) / 2), errs, lag1


def gap_stats(gt: GroundTruth) -> Tuple[int, int, float, float]:
    """(gaps > 50 ms, gaps > 0.3 s, longest gap [s], time in gaps > 50 ms [s])."""
    d = np.diff(gt.t_ns) * 1e-9
    return int((d > 0.05).sum()), int((d > 0.3).sum()), float(d.max()), float(d[d > 0.05].sum())


def kept_note(imu: ImuData, gt: GroundTruth, kept: int, max_gap_s: float, option: str = "--max-gap-s") -> Optional[str]:
    """What a check (or labels) says when its segments keep less than :data:`KEPT_NOTE` of the IMU samples
    inside the reference's span: how many, the gaps that split it and the ``option`` value that keeps more
    (:func:`bridging_gap_s`); None where it keeps enough."""
    t = np.asarray(imu.t_ns, dtype=np.int64)
    spanned = int(np.count_nonzero((t >= gt.t_ns[0]) & (t <= gt.t_ns[-1]))) if len(gt.t_ns) else 0
    if spanned == 0 or kept >= KEPT_NOTE * spanned:
        return None
    d = np.diff(np.asarray(gt.t_ns, dtype=np.int64)) * 1e-9
    n_gaps = int(np.sum(d > max_gap_s))
    keeps = bridging_gap_s(gt, max_gap_s)
    fix = (f"{option} {keeps:g} keeps more, bridging 99 % of its spacing by interpolation (fine for a slow platform)"
           if keeps is not None else f"a larger {option} keeps more, bridging them by interpolation (fine only "
           "where the motion is slow across them)")
    return (f"kept {kept} of the {spanned} IMU samples inside the reference's span ({100 * kept / spanned:.0f} %): "
            f"its {n_gaps} gaps longer than {max_gap_s:g} s (the longest {1e3 * float(d.max()):.0f} ms) split it "
            f"into stretches, those under {AlignOptions.min_segment_s:g} s dropped; {fix}")


def survival(imu: ImuData, gt: GroundTruth, max_gap_s: float) -> Tuple[float, int, float, float, float]:
    """(fraction of IMU samples kept, segments, longest segment [s], bias-removed rot [deg] / trans [m] at n=200)."""
    segs = segments(imu, gt, max_gap_s)
    kept = sum(len(s) for s in segs) / len(imu)
    return (kept, len(segs), max(s.duration_s for s in segs), *bias_removed_score(segs, 200))


def drift(imu: ImuData, gt: GroundTruth) -> dict:
    """Bias-removed raw-gyro rotation RMSE [deg] at 5 s and 20 s (windows every 10 samples from
    10 s on), bias from the first 10 s (fit_startup_bias) and from the whole recording."""
    segs = segments(imu, gt, DRIFT_GAP_S)
    startup = fit_startup_bias(segs[0], 10.0)
    whole = fit_bias(segs)
    out = {}
    for name, (bg, ba) in (("startup", startup), ("whole", whole)):
        for n, secs in ((1000, 5), (4000, 20)):
            out[f"{name}_{secs}s"] = pooled_errors(bias_removed(segs, bg, ba), n, stride=10, from_s=10.0)[0]
    return out


# ---------------------------------------------------------------------------------------------
# one ground-truth file


@dataclass
class GroundTruthCheck:
    """What the check found for one ground truth of a recording (scores: bias-removed relative pose
    RMSE, (rotation [deg], translation [m])); ``verdict`` says it in words."""

    recording: str
    gt: str
    rate_hz: float
    samples: int
    n_segments: int
    n10: Tuple[float, float]  # bias-removed (rot [deg], trans [m]) over 10 samples
    n200: Tuple[float, float]  # ... over 200 samples
    off_deg: float
    off_axis: np.ndarray
    tau_ms: float
    after_rot: Tuple[float, float]  # n=200 with R_off applied
    after_hold: Tuple[float, float]  # n=200 with R_off applied and GT shifted by τ − dt/2
    lever_cm: np.ndarray
    lever_se_cm: np.ndarray
    rotation_from: str = "from the gyro"  # how R_off was found (a ground robot's: specific force)
    about_turning_axis_observed: bool = True  # False: a ground robot whose specific force cannot fix it
    # the reference world's z from up (gravity from the specific force); from FrameOptions.level_deg on, the world
    # was levelled before every translation score and the lever arm (a VO/SLAM world, a z-down one)
    world_tilt_deg: float = 0.0
    # the rate fit's residual against the motion's rates [rad/s] (calibrate's rule, FrameOptions.max_rate_residual)
    # and the IMU's rates over the reference's (least squares on |ω|: 1 for one unit)
    rate_residual: float = 0.0
    rate_rms: float = math.inf
    rate_ratio: float = 1.0
    # the positions' units per metre the accelerometer measures (calib.metric_scale; NaN: not observed) and
    # whether it is off metric (more than 5 % and 4 standard errors: mm, cm, a monocular VO)
    scale: float = math.nan
    scale_std: float = math.nan
    scale_off: bool = False
    scale_not_observed: str = ""  # why the scale is NaN (calib.metric_scale's reason)
    imu_rate_hz: float = math.nan  # the IMU's: the scores' horizons are IMU samples

    @property
    def levelled(self) -> bool:
        return self.world_tilt_deg >= FrameOptions().level_deg

    @property
    def rates_match(self) -> bool:
        return self.rate_residual <= FrameOptions().max_rate_residual * self.rate_rms

    @property
    def verdict(self) -> str:
        if not self.rates_match:
            unit = next((f"; the IMU reads x{self.rate_ratio:.3g} the reference's rates: {what}?" for k, what in
                         ((math.pi / 180, "deg/s read as rad/s (--gyro-unit)"),
                          (180 / math.pi, "rad/s read as deg/s (--gyro-unit)"))
                         if abs(self.rate_ratio / k - 1) < 0.1), "")
            return f"its {no_frame(self.rate_residual, self.rate_rms)}{unit}"
        if self.scale_off:
            return (f"its positions are x{self.scale:.4g} (± {self.scale_std:.2g}) the distances the accelerometer "
                    "measures: millimetres or centimetres, or a monocular VO without metric scale? (translation and "
                    "lever arm below are in its units)")
        frame = "IMU frame" if self.off_deg < 0.5 else f"rotated {self.off_deg:.1f}° off the IMU"
        if not self.about_turning_axis_observed:
            frame += " (its part about the turning axis not observable)"
        lag = "" if abs(self.tau_ms) < 2.5 else f", GT {abs(self.tau_ms):.0f} ms {'late' if self.tau_ms > 0 else 'early'}"
        arm = np.linalg.norm(self.lever_cm)
        lever = f", lever arm {arm:.1f} cm" if arm > max(2.0, 3 * np.max(self.lever_se_cm)) else ""
        world = f", its world tilted {self.world_tilt_deg:.0f}° from gravity" if self.levelled else ""
        return frame + lag + lever + world


def gt_label(gt_rel: str) -> str:
    """``mav0/mocap0/data.csv`` -> ``mocap0``; a file beside ``mav0`` keeps its name."""
    parts = Path(gt_rel).parts
    return parts[1] if parts[0] == "mav0" and len(parts) > 1 else parts[-1]


def check(imu: ImuData, gt: GroundTruth, recording: str, label: str,
          options: CheckOptions = CheckOptions()) -> Tuple[GroundTruthCheck, Offset]:
    """Everything the check says about one ground truth of a recording (the module doc), and the
    fitted offset (the mocap noise needs it)."""
    gap = options.max_gap_s if options.max_gap_s is not None else default_gap_s(gt)
    coarse = coarse_lag(imu, gt)  # beyond the fine search's +-20 samples (a clock set by hand): calibrate's step 1
    gt = replace(gt, t_ns=gt.t_ns - int(round(coarse * 1e9))) if coarse else gt
    segs = segments(imu, gt, gap, name=recording)
    longest = max((len(s) for s in segs), default=0)
    if longest <= MIN_SAMPLES:
        raise TooShortError(f"{recording}: the longest stretch of IMU samples with ground truth ({label}) holds "
                            f"{longest} samples; the check needs more than {MIN_SAMPLES} (1 s windows): "
                            + (gap_hint(gt, gap) or f"raise --max-gap-s (now {gap:g} s) if the ground truth has gaps"),
                            samples=longest, needed=MIN_SAMPLES + 1)
    off = fit_offset(segs)
    up = world_up(segments(imu, gt, gap, r_off=off.r_off))  # the rates fix R_off in any world; gravity the world's up
    tilt = tilt_deg(up)
    if tilt >= FrameOptions().level_deg:  # a VO/SLAM world: translation and lever arm need gravity along its z
        gt = levelled(gt, up)
        segs = segments(imu, gt, gap, name=recording)
    rates = matched_rates(segs, 10)
    ratio = planar_ratio(rates)
    yaw, observed = "from the gyro", True
    if options.yaw_from_acc:  # the gyro leaves the yaw of R_off free (rotation about z only): take the accelerometer's
        off, yaw = replace(off, r_off=fit_acc_rotation(segs)), "from specific force (--yaw-from-acc)"
    elif ratio < FrameOptions().planar_ratio:  # calibrate's rule (calib.reference)
        try:
            off = replace(off, r_off=planar_rotation(segs, rates, off.rms, ratio))
            yaw = f"from specific force: the motion turns about one axis only (rate spread ratio {ratio:.3f})"
        except ReferenceFrameError:  # a check reports, where calibrate refuses
            observed = False
            yaw = (f"from the gyro, its part about the turning axis NOT observable: the motion turns about one axis "
                   f"only (rate spread ratio {ratio:.3f}) and specific force does not fix it")
    rotated = segments(imu, gt, gap, r_off=off.r_off)
    held = segments(imu, gt, gap, shift_s=off.integrator_shift_s, r_off=off.r_off)
    lever, lever_se = fit_lever_arm(segments(imu, gt, gap, shift_s=off.tau_s, r_off=off.r_off),
                                    off.r_off.T @ off.gyro_bias)
    angle, axis = angle_axis(off.r_off)
    imu_w, ref_w = (np.linalg.norm(x, axis=1) for x in rates)
    ratio = float(imu_w @ ref_w / max(float(ref_w @ ref_w), 1e-300))
    w_rms = motion_rms(segs, off.gyro_bias)
    row = GroundTruthCheck(recording, label, gt_rate_hz(gt), sum(len(s) for s in segs), len(segs),
              bias_removed_score(segs, 10), bias_removed_score(segs, 200), angle, axis, 1e3 * off.tau_s,
              bias_removed_score(rotated, 200), bias_removed_score(held, 200), 100 * lever, 100 * lever_se, yaw, observed,
              tilt, off.rms, w_rms, ratio, imu_rate_hz=1e9 / median_period_ns(imu.t_ns))
    metric = reference_scale([segs], off.r_off, gt_rate_hz(gt), np.zeros(3))
    if metric.observed:
        row = replace(row, scale=float(metric.scale), scale_std=float(metric.std), scale_off=bool(metric.off))
    else:
        row = replace(row, scale_not_observed=metric.reason or "no estimate")
    if coarse:  # the stamps moved by the coarse lag first: the offset is against the file as read
        off = replace(off, tau_s=off.tau_s + coarse)
        row = replace(row, tau_ms=1e3 * off.tau_s)
    return row, off


def coarse_lag(imu: ImuData, gt: GroundTruth) -> float:
    """The reference's lag [s] from the cross-correlation of |ω| over +-1 s (calibrate's step 1,
    :func:`imu_learn.calib.reference.fit_lag`) where it is beyond calibrate's ``floor_lag_s`` and the peak
    is clear (inside the search, correlation at least ``min_correlation``); else 0: the fine search of
    :func:`fit_offset` (+-20 samples) covers it, or nothing does."""
    opts = FrameOptions()
    try:
        with np.errstate(invalid="ignore", divide="ignore"):  # a flat |ω| correlates with nothing: NaN, no lag
            lag, corr, edge = fit_lag(imu, gt, opts.max_lag_s)
    except ReferenceFrameError:
        return 0.0
    return float(lag) if abs(lag) > opts.floor_lag_s and not edge and corr >= opts.min_correlation else 0.0


def pick_best(rows: List[GroundTruthCheck]) -> dict:
    """Per recording, the GT file with the lowest bias-removed rotation RMSE over 1 s once its rotation
    and lag are applied (``after_hold``: what calibrate makes of it, as it estimates both; a later
    candidate must beat an earlier one by 2 %: ties go to the first, the layout's own file); a file whose
    rates match the IMU's in some frame before any that match in none."""
    best: dict = {}
    for r in rows:
        b = best.get(r.recording)
        if b is None or (r.rates_match, -r.after_hold[0]) > (b.rates_match, -0.98 * b.after_hold[0]):
            best[r.recording] = r
    return best


def summary_line(rec: str, rows: List[GroundTruthCheck], best: GroundTruthCheck) -> str:
    """The recommendation, quoting the figures over 200 samples (1 s at 200 Hz; the span is said) once the
    reference's rotation and lag are applied (a
    camera-frame VO read 11.3° before its 89° rotation, 0.22° after: the former beside "use" misled)."""
    others = "; ".join(f"{r.gt}: {r.after_hold[0]:.3f}°" for r in rows if r.recording == rec and r is not best)
    return (f"{rec}: use {best.gt} ({best.verdict}; over 200 samples ({200 / best.imu_rate_hz:.2g} s) rot "
            f"{best.after_hold[0]:.3f}°, trans {best.after_hold[1]:.4f} m "
            "after its rotation and lag)" + (f" — others {others}" if others else ""))


def fmt_vec(v: np.ndarray, p: int = 2) -> str:
    return "(" + ", ".join(f"{x:+.{p}f}" for x in v) + ")"
