"""Which ground truth does each recording's own IMU agree with, and in which body frame is it?

For every EuRoC / TUM-VI recording under the data root and every ground-truth file it has:

* bias-removed relative pose RMSE (rotation [deg], translation [m]; ``metrics.relative_pose_errors``)
  over 10 and 200 IMU samples (0.05 s, 1 s), every window. The bias: one constant gyro + accel bias
  per recording, fitted over the *whole* recording as in ``bench/label_agreement.py`` (medians of
  10-sample window residuals / Δt, pooled over the segments);
* R_off (GT body -> IMU: ω_imu ≈ R_off ω_gt + b_g) and τ (IMU sample at its stamp t ≈ GT(t + τ),
  so τ > 0: GT stamps late), fitted jointly: Kabsch (bias = centring term) on 10-sample mean rates
  for every whole-sample shift within ±100 ms, the best one refined by a parabola. The metric's
  integrator holds sample k over [t_k, t_k+1], i.e. it sees the IMU half a period late; the table
  also scores with the GT shifted by τ − dt/2, which undoes that;
* the lever arm r of the IMU origin in the GT body frame, by least squares on
  S(R a_imu) − S(p̈_gt) − g = S(R (ω̇× + ω×ω×)) r + S(R) b_a  (world frame; S: one Savitzky-Golay
  smoother on every term, so the equation stays exact), with R_off and τ applied;
* TUM-VI: mocap orientation noise σ at its own stamps (gyro vs. mocap relative rotation over
  h = 1..10 mocap samples, RMSE² = 2σ² + k h²); raw-gyro bias-removed rotation drift at 5 s / 20 s;
  mocap gaps and how much of each room survives per ``max_gap_s``.

    python bench/groundtruth_report.py [--data ../shared/data] [--out docs/groundtruth.md]
"""
from __future__ import annotations

import argparse
import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np
from scipy.signal import savgol_filter

import imu_learn as il
from imu_learn.core.quat import quat_conj, quat_mul, quat_rotate
from imu_learn.data.formats import read_recording
from imu_learn.score.metrics import fit_startup_bias, index_at, relative_pose_errors, remove_bias, rmse, with_imu
from imu_learn.util.atomic import atomic_write_text

EUROC = ("MH_01_easy", "MH_03_medium", "MH_04_difficult", "MH_05_difficult", "V1_01_easy", "V1_03_difficult",
         "V2_01_easy", "V2_02_medium", "V2_03_difficult")
TUMVI = tuple(f"dataset-room{i}_512_16" for i in range(1, 6))
EUROC_GT = ("mav0/state_groundtruth_estimate0/data.csv", "groundtruth_pose.tum", "groundtruth_state_20hz.csv",
            "groundtruth_original_euroc.csv")
TUMVI_GT = ("mav0/mocap0/data.csv",)
FETCH = ("01_square", "03_um", "04_eight", "06_right_turn", "07_left_turn", "08_origin")
FETCH_GT = ("mav0/mocap0/data.csv",)
FETCH_GAP_S = 0.1  # the Fetch mocap has gaps up to 70 ms in every recording
GAPS_S = (0.05, 0.1, 0.3, 0.5)
DRIFT_GAP_S = 0.3  # TUM-VI segments for the 5 s / 20 s drift (windows must fit inside one segment)
G = 9.81


# ---------------------------------------------------------------------------------------------
# loading


def is_fetch(root: Path) -> bool:
    return root.parent.name == "fetch"


def read(root: Path, gt_rel: str) -> Tuple[il.ImuData, il.GroundTruth]:
    fmt = "fetch" if is_fetch(root) else "euroc"
    return read_recording(root, fmt, groundtruth=root / gt_rel)


def gt_rate_hz(gt: il.GroundTruth) -> float:
    return 1e9 / float(np.median(np.diff(gt.t_ns)))


def default_gap_s(gt: il.GroundTruth) -> float:
    """0.05 s, or 1.5 ground-truth periods for sparse ground truth (the 20 Hz ASL state)."""
    return max(0.05, 1.5 / gt_rate_hz(gt))


def segments(imu: il.ImuData, gt: il.GroundTruth, max_gap_s: float, shift_s: float = 0.0,
             r_off: Optional[np.ndarray] = None) -> List[il.Segment]:
    """Aligned gap-free segments; optionally GT stamps moved by −shift_s and the IMU rotated into
    the GT body frame (ω_gt = R_offᵀ ω_imu)."""
    if shift_s:
        gt = replace(gt, t_ns=gt.t_ns - int(round(shift_s * 1e9)))
    if r_off is not None:
        imu = replace(imu, gyro=imu.gyro @ r_off, acc=imu.acc @ r_off)
    return il.align(imu, gt, il.AlignOptions(max_gap_s=max_gap_s)).segments


# ---------------------------------------------------------------------------------------------
# bias and scores


def log_q(q: np.ndarray) -> np.ndarray:
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    n = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    return q[..., 1:] * (2 * np.arctan2(n, q[..., :1]) / np.maximum(n, 1e-300))


def exp_q(v: np.ndarray) -> np.ndarray:
    a = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.concatenate([np.cos(a / 2), np.sinc(a / (2 * np.pi)) * v / 2], -1)


def fit_bias(segs: List[il.Segment], n: int = 10) -> Tuple[np.ndarray, np.ndarray]:
    """Whole-recording constant (gyro, accel) bias: medians of n-sample window residuals / Δt over
    all segments, the accelerometer one with the gyro bias removed (label_agreement's fit)."""
    rg, ra = [], []
    for s in segs:
        lab = il.window_labels(s, window=n, stride=n, fractions=[1.0])
        imu = il.integrate_windows(s, lab.starts, lab.horizons)
        rg.append(log_q(quat_mul(quat_conj(lab.dq_wxyz[:, 0]), imu.dq_wxyz[:, 0])) / lab.dt[:, :1])
    bg = np.median(np.concatenate(rg), axis=0)
    for s in segs:
        lab = il.window_labels(s, window=n, stride=n, fractions=[1.0])
        imu = il.integrate_windows(with_imu(s, s.gyro - bg, s.acc), lab.starts, lab.horizons)
        ra.append((imu.dv[:, 0] - lab.dv[:, 0]) / lab.dt[:, :1])
    return bg, np.median(np.concatenate(ra), axis=0)


def pooled_errors(segs: List[il.Segment], n: int, stride: int = 1, from_s: float = 0.0) -> Tuple[float, float]:
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


def bias_removed(segs: List[il.Segment], bg: np.ndarray, ba: np.ndarray) -> List[il.Segment]:
    return [remove_bias(s, bg, ba) for s in segs]


def bias_removed_score(segs: List[il.Segment], n: int) -> Tuple[float, float]:
    """(rot [deg], trans [m]) RMSE over n samples with the whole-recording bias removed."""
    return pooled_errors(bias_removed(segs, *fit_bias(segs)), n)


# ---------------------------------------------------------------------------------------------
# rotation / time offset


def mean_rates(seq: il.Segment, m: int) -> Tuple[np.ndarray, np.ndarray]:
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
    u, _, vt = np.linalg.svd((b - bm).T @ (a - am))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    r = vt.T @ d @ u.T
    c = am - r @ bm
    return r, c, float(np.mean(np.sum((a - b @ r.T - c) ** 2, axis=1)))


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


def fit_offset(segs: List[il.Segment], m: int = 10, max_shift: int = 20) -> Offset:
    """Constant rotation + gyro bias (Kabsch) and time offset (shift grid + parabola) between the
    gyro and the ground truth's angular rate. The rates are compared under the integrator's
    zero-order hold (sample k held on [t_k, t_k+1]); τ adds back the half period, so it is the
    offset of IMU samples taken at their stamps. R_off is re-fitted at the sub-sample shift (a
    misalignment of half a sample alone tilts it by ~0.1°)."""
    rates = [mean_rates(s, m) for s in segs if len(s) > m + 2 * max_shift + 2]
    costs = np.array([kabsch(*shifted_pairs(rates, s))[2] for s in range(-max_shift, max_shift + 1)])
    i = int(np.clip(np.argmin(costs), 1, len(costs) - 2))
    c_m, c_0, c_p = costs[i - 1: i + 2]
    shift = i - max_shift + (0.5 * (c_m - c_p) / (c_m - 2 * c_0 + c_p) if c_m - 2 * c_0 + c_p > 0 else 0.0)
    dt = float(np.median(np.concatenate([np.diff(s.t_ns) for s in segs]))) * 1e-9
    r, c, cost = kabsch(*shifted_pairs(rates, shift))
    return Offset(r, c, (shift + 0.5) * dt, 0.5 * dt, math.sqrt(cost))


def fit_acc_rotation(segs: List[il.Segment], half: int = 15) -> np.ndarray:
    """GT body -> IMU rotation from specific force (Kabsch, bias = centring term): the smoothed
    accelerometer vs. R_gtᵀ (p̈_gt + g). For a ground robot, which turns about z only, the gyro fixes
    the tilt but not the yaw of R_off; gravity and the horizontal accelerations fix both."""
    a, b = [], []
    for s in segs:
        if len(s) <= 4 * half:
            continue
        dt = float(np.median(np.diff(s.t_ns))) * 1e-9
        smooth = lambda x: savgol_filter(x, 2 * half + 1, 2, axis=0)  # noqa: E731
        f_world = np.gradient(np.gradient(smooth(s.p), dt, axis=0), dt, axis=0) + np.array([0.0, 0.0, G])
        f_body = np.einsum("nji,nj->ni", rotation_matrices(s.q_wxyz), f_world)
        keep = slice(2 * half, len(s) - 2 * half)
        a.append(smooth(s.acc)[keep])
        b.append(f_body[keep])
    return kabsch(np.concatenate(a), np.concatenate(b))[0]


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


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of w,x,y,z quaternions."""
    return np.stack([quat_rotate(q, np.broadcast_to(e, (len(q), 3))) for e in np.eye(3)], axis=2)


def lever_rows(seq: il.Segment, gyro_bias: np.ndarray, half: int) -> Tuple[np.ndarray, np.ndarray]:
    """Rows of  S(R a_imu) − S(p̈) − g = S(R (ω̇× + ω×ω×)) r + S(R) b_a  in the world frame, S one
    smoothing filter applied to every term alike (the equation stays exact); edges dropped."""
    dt = float(np.median(np.diff(seq.t_ns))) * 1e-9
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


def fit_lever_arm(segs: List[il.Segment], gyro_bias: np.ndarray, half: int = 20) -> Tuple[np.ndarray, np.ndarray]:
    """Lever arm r [m] of the IMU in the (IMU-aligned) GT body frame and its standard error."""
    rows = [lever_rows(s, gyro_bias, half) for s in segs if len(s) > 4 * half]
    a, y = np.concatenate([r[0] for r in rows]), np.concatenate([r[1] for r in rows])
    x, *_ = np.linalg.lstsq(a, y, rcond=None)
    s2 = np.sum((y - a @ x) ** 2) / max(1, len(y) - 6)
    return x[:3], np.sqrt(np.diag(s2 * np.linalg.inv(a.T @ a)))[:3]


# ---------------------------------------------------------------------------------------------
# TUM-VI noise floor and gaps


def mocap_noise(imu: il.ImuData, gt: il.GroundTruth, off: Offset, hs=tuple(range(1, 11))) -> Tuple[float, List[float], float]:
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


def gap_stats(gt: il.GroundTruth) -> Tuple[int, int, float, float]:
    """(gaps > 50 ms, gaps > 0.3 s, longest gap [s], time in gaps > 50 ms [s])."""
    d = np.diff(gt.t_ns) * 1e-9
    return int((d > 0.05).sum()), int((d > 0.3).sum()), float(d.max()), float(d[d > 0.05].sum())


def survival(imu: il.ImuData, gt: il.GroundTruth, max_gap_s: float) -> Tuple[float, int, float, float, float]:
    """(fraction of IMU samples kept, segments, longest segment [s], bias-removed rot [deg] / trans [m] at n=200)."""
    segs = segments(imu, gt, max_gap_s)
    kept = sum(len(s) for s in segs) / len(imu)
    return (kept, len(segs), max(s.duration_s for s in segs), *bias_removed_score(segs, 200))


def drift(imu: il.ImuData, gt: il.GroundTruth) -> dict:
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
class Row:
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

    @property
    def verdict(self) -> str:
        frame = "IMU frame" if self.off_deg < 0.5 else f"rotated {self.off_deg:.1f}° off the IMU"
        lag = "" if abs(self.tau_ms) < 2.5 else f", GT {self.tau_ms:+.0f} ms late"
        arm = np.linalg.norm(self.lever_cm)
        lever = f", lever arm {arm:.1f} cm" if arm > max(2.0, 3 * np.max(self.lever_se_cm)) else ""
        return frame + lag + lever


def gt_label(gt_rel: str) -> str:
    """``mav0/mocap0/data.csv`` -> ``mocap0``; a file beside ``mav0`` keeps its name."""
    parts = Path(gt_rel).parts
    return parts[1] if parts[0] == "mav0" else parts[-1]


def score_gt(root: Path, gt_rel: str) -> Tuple[Row, il.ImuData, il.GroundTruth, Offset]:
    """Everything the main table says about one ground-truth file (plus what the TUM-VI part needs)."""
    imu, gt = read(root, gt_rel)
    gap = FETCH_GAP_S if is_fetch(root) else default_gap_s(gt)
    segs = segments(imu, gt, gap)
    off = fit_offset(segs)
    if is_fetch(root):  # the gyro leaves the yaw of R_off free (rotation about z only): take the accelerometer's
        off = replace(off, r_off=fit_acc_rotation(segs))
    rotated = segments(imu, gt, gap, r_off=off.r_off)
    held = segments(imu, gt, gap, shift_s=off.integrator_shift_s, r_off=off.r_off)
    lever, lever_se = fit_lever_arm(segments(imu, gt, gap, shift_s=off.tau_s, r_off=off.r_off),
                                    off.r_off.T @ off.gyro_bias)
    angle, axis = angle_axis(off.r_off)
    row = Row(root.name, gt_label(gt_rel), gt_rate_hz(gt), sum(len(s) for s in segs), len(segs),
              bias_removed_score(segs, 10), bias_removed_score(segs, 200), angle, axis, 1e3 * off.tau_s,
              bias_removed_score(rotated, 200), bias_removed_score(held, 200), 100 * lever, 100 * lever_se)
    return row, imu, gt, off


# ---------------------------------------------------------------------------------------------
# report


def fmt_vec(v: np.ndarray, p: int = 2) -> str:
    return "(" + ", ".join(f"{x:+.{p}f}" for x in v) + ")"


def main_table(rows: List[Row], best: dict) -> List[str]:
    out = ["| recording | GT file | rate [Hz] | samples (segs) | n=10 rot [°] / trans [m] | n=200 rot [°] / trans [m] "
           "| R_off [°] (axis) | τ [ms] | n=200 after R_off | n=200 after R_off + shift τ − dt/2 "
           "| lever arm [cm] ± se | verdict |", "|" + "---|" * 12]
    for r in rows:
        mark = " **best**" if best[r.recording] is r else ""
        out.append(f"| {r.recording} | {r.gt} | {r.rate_hz:.0f} | {r.samples} ({r.n_segments}) | "
                   f"{r.n10[0]:.4f} / {r.n10[1]:.5f} | {r.n200[0]:.3f} / {r.n200[1]:.4f} | "
                   f"{r.off_deg:.2f} {fmt_vec(r.off_axis)} | {r.tau_ms:+.1f} | "
                   f"{r.after_rot[0]:.3f} / {r.after_rot[1]:.4f} | {r.after_hold[0]:.3f} / {r.after_hold[1]:.4f} | "
                   f"{fmt_vec(r.lever_cm, 1)} ± {np.max(r.lever_se_cm):.1f} | {r.verdict}{mark} |")
    return out


def pick_best(rows: List[Row]) -> dict:
    """Per recording, the GT file with the lowest bias-removed rotation RMSE over 1 s (a later
    candidate must beat an earlier one by 2 %: ties go to the ASL layout's own file)."""
    best: dict = {}
    for r in rows:
        if r.recording not in best or r.n200[0] < 0.98 * best[r.recording].n200[0]:
            best[r.recording] = r
    return best


def summary_line(rec: str, rows: List[Row], best: Row) -> str:
    others = "; ".join(f"{r.gt}: {r.n200[0]:.3f}°" for r in rows if r.recording == rec and r is not best)
    return (f"{rec}: use {best.gt} ({best.verdict}; 1 s rot {best.n200[0]:.3f}°, trans {best.n200[1]:.4f} m)"
            + (f" — others {others}" if others else ""))


def tumvi_frame(rows: List[Row]) -> str:
    """One line: which body frame mocap0 is, from the fitted rotation, lever arm and time offset."""
    offs = [r.off_deg for r in rows]
    arms = [float(np.linalg.norm(r.lever_cm)) for r in rows]
    taus = [r.tau_ms for r in rows]
    frame = "the IMU frame" if max(offs) < 0.5 and max(arms) < 2 else "NOT the IMU frame"
    return (f"TUM-VI mocap0 is {frame}: R_off {min(offs):.2f}–{max(offs):.2f}°, lever arm |r| {min(arms):.1f}–"
            f"{max(arms):.1f} cm, τ {min(taus):+.1f}…{max(taus):+.1f} ms over {len(rows)} rooms.")


def fetch_frame(rows: List[Row]) -> List[str]:
    """The Fetch mocap body frame against the IMU, in a few lines."""
    if not rows:
        return []
    offs = [r.off_deg for r in rows]
    taus = [r.tau_ms for r in rows]
    return ["", "## Fetch mocap0 body frame", "",
            f"Fetch (Debias_IMU) mocap0 against the IMU over {len(rows)} recordings, segments at max_gap_s = "
            f"{FETCH_GAP_S} (the mocap has gaps up to 70 ms): R_off {min(offs):.2f}–{max(offs):.2f}° "
            f"(fitted on specific force: the robot turns about z only, so the gyro leaves R_off's yaw free), "
            f"τ {min(taus):+.1f}…{max(taus):+.1f} ms. The pose is used as it is (no rotation, no time offset)."]


def noise_table(tum: List[Tuple[Row, il.ImuData, il.GroundTruth, Offset]]) -> List[str]:
    out = ["", "## TUM-VI mocap0: noise floor", "",
           "σ: mocap orientation noise at the mocap's own 120 Hz stamps (RMSE of gyro vs. mocap relative rotation "
           "over h = 1..10 samples, fitted as RMSE² = 2σ² + k h²). Drift: raw gyro, bias removed, rotation RMSE "
           f"over 5 s / 20 s, windows every 10 samples from 10 s on, segments at max_gap_s = {DRIFT_GAP_S}.", "",
           "| room | σ mocap [°] | RMSE h=1 / 2 / 5 / 10 [°] | lag-1 autocorr. h=1 (white: −0.5) "
           "| 5 s start-up bias [°] | 20 s start-up bias [°] | 5 s whole-rec. bias [°] | 20 s whole-rec. bias [°] |",
           "|" + "---|" * 8]
    for row, imu, gt, off in tum:
        sigma, errs, lag1 = mocap_noise(imu, gt, off)
        d = drift(imu, gt)
        out.append(f"| {row.recording} | {sigma:.4f} | {errs[0]:.4f} / {errs[1]:.4f} / {errs[4]:.4f} / {errs[9]:.4f} "
                   f"| {lag1:+.2f} | {d['startup_5s']:.3f} | {d['startup_20s']:.3f} | {d['whole_5s']:.3f} "
                   f"| {d['whole_20s']:.3f} |")
    return out


def gap_table(tum: List[Tuple[Row, il.ImuData, il.GroundTruth, Offset]]) -> List[str]:
    out = ["", "## TUM-VI mocap0: gaps and what survives per max_gap_s", "",
           "kept = IMU samples inside segments (min_segment_s = 1); score = bias-removed rot [°] / trans [m] at n=200 "
           "on those segments (gaps bridged by interpolation show up here).", "",
           "| room | gaps > 50 ms | gaps > 0.3 s | longest [s] | time in gaps [s] | "
           + " | ".join(f"max_gap {g} s: kept, segs, longest seg [s], score" for g in GAPS_S) + " |",
           "|" + "---|" * (5 + len(GAPS_S))]
    ok = dict.fromkeys(GAPS_S, True)
    for row, imu, gt, _ in tum:
        n50, n300, longest, total = gap_stats(gt)
        cells = [survival(imu, gt, g) for g in GAPS_S]
        for g, c in zip(GAPS_S, cells):
            ok[g] &= c[3] <= 1.05 * cells[0][3]
        out.append(f"| {row.recording} | {n50} | {n300} | {longest:.2f} | {total:.2f} | " + " | ".join(
            f"{100 * kept:.1f} %, {nseg}, {seg_s:.0f}, {rot:.3f} / {trans:.4f}" for kept, nseg, seg_s, rot, trans in cells)
            + " |")
    good = max(g for g in GAPS_S if ok[g])
    return out + ["", f"Largest max_gap_s whose 1 s rotation score stays within 5 % of max_gap 0.05's in every room: "
                  f"**{good}**."]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path(os.environ.get("IMU_LEARN_DATA", "../shared/data")))
    ap.add_argument("--out", type=Path, default=Path("docs/groundtruth.md"))
    args = ap.parse_args()
    start = time.time()
    jobs = [(args.data / "euroc" / r, EUROC_GT) for r in EUROC] + [(args.data / "tum-vi" / r, TUMVI_GT) for r in TUMVI]
    jobs += [(args.data / "fetch" / r, FETCH_GT) for r in FETCH]
    results = []
    for root, cands in jobs:
        for gt_rel in cands:
            if (root / gt_rel).is_file():
                results.append(score_gt(root, gt_rel))
                r = results[-1][0]
                print(f"{r.recording} / {r.gt}: n=200 rot {r.n200[0]:.3f}°, R_off {r.off_deg:.2f}°, "
                      f"τ {r.tau_ms:+.1f} ms, lever {fmt_vec(r.lever_cm, 1)} cm ({time.time() - start:.0f} s)", flush=True)
    rows = [x[0] for x in results]
    best = pick_best(rows)
    tum = [x for x in results if x[0].recording in TUMVI]
    tum_lines = ["", "## TUM-VI body frame", "", tumvi_frame([x[0] for x in tum])] + noise_table(tum) + gap_table(tum)
    tum_lines += fetch_frame([x[0] for x in results if x[0].recording in FETCH])
    lines = ["# Ground truth vs. own IMU", "",
             f"Generated by `bench/groundtruth_report.py` in {time.time() - start:.0f} s (method: its docstring).", "",
             "Bias: one constant gyro + accelerometer bias per recording, fitted on the whole recording (medians "
             "of 10-sample window residuals, as bench/label_agreement.py). Relative pose RMSE over every window "
             "(stride 1) of n IMU samples. R_off maps GT-body vectors to the IMU frame (axis in either frame); "
             "τ > 0: GT stamps late (IMU(t) ≈ GT(t + τ)). Segments at max_gap_s = 0.05 (0.075 for the 20 Hz "
             "state). Lever arm: IMU origin in the GT body frame. Best = lowest rot n=200 per recording (ties to "
             "the ASL layout's own file). The metric's integrator holds IMU sample k over [t_k, t_k+1], half a "
             "period after it was taken; the column 'after R_off + shift τ − dt/2' undoes that.", ""]
    lines += main_table(rows, best) + tum_lines
    lines += ["", "## Per recording", ""] + [f"- {summary_line(rec, rows, b)}" for rec, b in best.items()]
    text = "\n".join(lines) + "\n"
    atomic_write_text(args.out, text)
    print(text)
    print(f"wrote {args.out} in {time.time() - start:.0f} s")


if __name__ == "__main__":
    main()
