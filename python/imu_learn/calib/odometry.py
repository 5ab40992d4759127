"""Planar wheel odometry as a calibration reference: what it observes and nothing else.

A planar odometry trajectory (every orientation a yaw about the world's z, the height constant: wheel
odometry in ``base_link``; :func:`is_planar_odometry`) observes the robot's yaw rate and forward speed.
It says nothing of roll and pitch, of the IMU's axes across the vertical, of the accelerometer's scale
or of a low-pass, so the affine floor cannot be fitted against it (it would fit the IMU's roll and pitch
axes against zero). :class:`OdometrySource` fits what it does observe:

1. **The IMU's vertical axis** ``u`` (IMU coordinates, up) from gravity: the mean specific force of the
   still stretches (:func:`imu_learn.calib.noise.still_stretches`), else, where the specific force is
   steady (its 1 s means within ``steady_deg`` of their mean, the mean within 10 % of 9.81 m/s^2: a
   ground robot), the mean specific force of the recording; neither: refused (one line).
2. **The lag** from the cross-correlation of |ω·u| (the gyro about the vertical) with the odometry's
   |yaw rate| (:func:`imu_learn.calib.reference.fit_lag` on |ω|), refined to the millisecond by the
   residual of step 3 around it; the odometry is then moved onto the IMU's clock.
3. **The gyro bias and scale about the vertical**: robust (Huber) linear least squares over windows
   of ``window_s`` (0.5 s) of the IMU's mean vertical rate against the odometry's mean yaw rate,
   ω_u = s ω_yaw + b; their standard errors from the spread over recordings (one recording: four time
   blocks) over sqrt(groups), as the floor's (:mod:`imu_learn.calib.fit`). The scale is the gyro's
   relative to the odometry's yaw (a wheel-base error of the odometry reads as a gyro scale); it is
   applied only where significant (``scale_sigmas`` standard errors and ``min_scale`` off 1).
4. **The forward axis** (the mounting yaw ψ about ``u``) from the IMU's horizontal specific force
   against the odometry's body acceleration (dv/dt along, v·ω across) over ``acc_window_s`` windows,
   where the horizontal accelerations fix it; it puts the odometry in the IMU's frame for the
   held-back check, and gives the **accelerometer's forward bias** (the mean of the specific force
   along the forward axis minus the odometry's forward acceleration) with its spread across time
   blocks. That bias is written to the fit log only: ``u`` comes from the same accelerometer at rest,
   so a forward bias tilts ``u`` and cancels itself (0.1 m/s^2 is 0.6° of tilt), and on a level floor
   no heading changes that; the profile keeps the prior (the log shows the value against its spread).

The profile: the gyro bias ``b u`` (across the vertical: the prior 0), the gyro matrix
I + (1/s − 1) u uᵀ where s is significant (else the identity), the time offset at its prior (the
zero-order hold's half sample: the odometry's lag and the IMU's own offset are one), everything else
at its prior; ``observed`` says why per parameter, ``reference`` the kind, the vertical axis, the lag
and the forward axis. The recordings are the odometry moved into the IMU's frame (q_W_imu =
q_W_base · R_base_imu, R_base_imu = Rz(ψ) · level(u)) on the IMU's stamps, so that
:func:`imu_learn.calib.run.calibrate`'s checks run as for every reference: a relative rotation over a
window is then a rotation about ``u`` by the odometry's yaw change, whatever ψ, so the held-back
rotation error is the yaw error plus what the odometry does not see (the IMU's rates across the
vertical, the same raw and with the profile, which changes nothing across it). The held-back block is
scored on the yaw alone too (:func:`held_back_yaw`, in the fit log).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.baselines.affine import Floor, TraditionalParams
from imu_learn.baselines.base import FitSettings
from imu_learn.calib import noise as nz
from imu_learn.calib.fit import time_blocks
from imu_learn.calib.frames import default_gap_s
from imu_learn.calib.profile import FloorFit
from imu_learn.calib.reference import fit_lag, is_planar_odometry, level_rotation
from imu_learn.calib.sources import (
    OBSERVABLE,
    TIME_OFFSET_PRIOR_SAMPLES,
    TRAIN,
    VAL,
    CalibInputs,
    Progress,
    Recording,
    Source,
    _check_exist,
    _format,
    _name,
    device_name,
    held_back,
    span,
)
from imu_learn.core.quat import quat_from_matrix, quat_mul
from imu_learn.data.formats import read_recording
from imu_learn.data.formats.groundtruth import read_groundtruth
from imu_learn.data.loading import AlignOptions, align
from imu_learn.data.types import GroundTruth, ImuData, Segment
from imu_learn.errors import ReferenceFrameError

G = 9.81


def is_odometry_reference(path: Optional[Path]) -> bool:
    """Whether the reference file ``path`` (TUM, ASL) is planar odometry (:func:`is_planar_odometry`)."""
    if path is None or not Path(path).is_file():
        return False
    for floats in (False, True):
        try:
            return is_planar_odometry(read_groundtruth(Path(path), floats))
        except Exception:  # noqa: BLE001 - not a file this reader takes: the 6-DoF path reports it
            continue
    return False


@dataclass(frozen=True)
class OdometryOptions:
    """The module doc's settings."""

    max_lag_s: float = 1.0
    min_correlation: float = 0.6
    window_s: float = 0.5  # step 3's windows
    acc_window_s: float = 1.0  # step 4's windows
    refine_s: float = 0.03  # step 2's refinement: +- around the correlation's lag
    steady_deg: float = 10.0  # step 1 without a still stretch: the 90th percentile of the 1 s means' angles
    min_still_s: float = 2.0
    min_yaw_rate: float = 0.05  # [rad/s] RMS of the odometry's yaw rate below which it does not turn
    scale_sigmas: float = 3.0
    min_scale: float = 0.005
    min_horizontal_acc: float = 0.05  # [m/s^2] RMS that fixes the forward axis
    blocks: int = 4


@dataclass
class YawFit:
    """Step 3: ω_u = scale · ω_yaw + bias over the windows, their standard errors, the residual."""

    bias: float
    scale: float
    bias_std: float
    scale_std: float
    residual: float
    windows: int
    groups: Dict[str, Tuple[float, float]] = field(default_factory=dict)


def yaw_of(q_wxyz: np.ndarray) -> np.ndarray:
    """The unwrapped yaw about the world's z of each orientation."""
    w, x, y, z = q_wxyz.T
    return np.unwrap(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def vertical_axis(imu: ImuData, opts: OdometryOptions = OdometryOptions()) -> Tuple[np.ndarray, str]:
    """Step 1: the IMU's up in its own coordinates, and where it came from."""
    t, a = imu.t_ns, imu.acc
    st = nz.still_stretches(t, imu.gyro, a, nz.StillSettings())
    still_s = sum((t[i1 - 1] - t[i0]) * 1e-9 for i0, i1 in st)
    if st and still_s >= opts.min_still_s:
        m = np.concatenate([a[i0:i1] for i0, i1 in st]).mean(0)
        return m / np.linalg.norm(m), f"the mean specific force of {len(st)} still stretches ({still_s:.1f} s)"
    period = float(np.median(np.diff(t))) * 1e-9
    n = max(1, int(round(1.0 / period)))
    k = len(a) // n
    if k >= 3:
        means = a[:k * n].reshape(k, n, 3).mean(1)
        m = means.mean(0)
        ang = np.degrees(np.arccos(np.clip(means @ m / (np.linalg.norm(means, axis=1) * np.linalg.norm(m)), -1, 1)))
        if abs(np.linalg.norm(m) - G) < 0.1 * G and float(np.percentile(ang, 90)) < opts.steady_deg:
            return m / np.linalg.norm(m), f"the mean specific force (steady within {np.percentile(ang, 90):.1f}°)"
    raise ReferenceFrameError(
        "planar odometry: the IMU's vertical axis cannot be found (no still stretch and no steady gravity in the "
        "accelerometer): the odometry's yaw rate cannot be compared with the gyro; record a still stretch")


def level(u: np.ndarray) -> np.ndarray:
    """The smallest rotation taking ``u`` to +z."""
    return level_rotation(np.asarray(u, dtype=np.float64))


def _rot_z(psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _windows(t_ns: np.ndarray, n: int) -> Tuple[np.ndarray, np.ndarray]:
    starts = np.arange(0, len(t_ns) - n, n)
    return starts, starts + n


def rate_pairs(segs: Sequence[Segment], u: np.ndarray, window_s: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the IMU's mean rate about ``u``, the odometry's mean yaw rate, the window's mid time [s]) over
    windows of ``window_s`` of each segment (the odometry's yaw from its orientations on the IMU
    stamps, the IMU's samples held over their interval)."""
    xs, ys, ts = [], [], []
    for s in segs:
        dt = np.diff(s.t_ns) * 1e-9
        if len(dt) == 0:
            continue
        n = max(2, int(round(window_s / float(np.median(dt)))))
        c = np.concatenate([[0.0], np.cumsum((s.gyro[:-1] @ u) * dt)])
        yaw = yaw_of(s.q_wxyz)
        i0, i1 = _windows(s.t_ns, n)
        if len(i0) == 0:
            continue
        span_s = (s.t_ns[i1] - s.t_ns[i0]) * 1e-9
        ys.append((c[i1] - c[i0]) / span_s)
        xs.append((yaw[i1] - yaw[i0]) / span_s)
        ts.append(0.5 * (s.t_ns[i1] + s.t_ns[i0]) * 1e-9)
    if not xs:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return np.concatenate(ys), np.concatenate(xs), np.concatenate(ts)


def robust_line(y: np.ndarray, x: np.ndarray, iterations: int = 8) -> Tuple[float, float, float]:
    """(scale, bias, robust residual RMS) of y = scale·x + bias, Huber reweighting."""
    a = np.stack([x, np.ones_like(x)], 1)
    w = np.ones(len(y))
    sol = np.array([1.0, 0.0])
    for _ in range(iterations):
        sw = np.sqrt(w)
        sol, *_ = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)
        r = np.abs(y - a @ sol)
        cap = 1.345 * 1.4826 * np.median(r) + 1e-12
        w = np.minimum(1.0, cap / np.maximum(r, 1e-12))
    r = y - a @ sol
    return float(sol[0]), float(sol[1]), float(np.sqrt(np.sum(w * r * r) / max(1.0, np.sum(w))))


def fit_yaw(groups: Dict[str, Sequence[Segment]], u: np.ndarray, window_s: float, blocks: int = 4,
            min_turn: float = OdometryOptions.min_yaw_rate) -> YawFit:
    """Step 3 over every group's segments; the standard errors from the groups (one: ``blocks`` time
    blocks) as the floor's spread (a group whose yaw rate spreads less than ``min_turn`` gives its bias
    at the common scale and no scale)."""
    segs = [s for g in groups.values() for s in g]
    y, x, _ = rate_pairs(segs, u, window_s)
    if len(y) < 8:
        raise ReferenceFrameError(f"planar odometry: {len(y)} windows of {window_s:g} s without a gap; the yaw-rate "
                                  "fit needs 8 or more: raise --max-gap-s or give a longer recording")
    scale, bias, res = robust_line(y, x)
    parts = dict(groups) if len(groups) >= 2 else {k: v[0] for k, v in time_blocks(list(segs), blocks).items()}
    per: Dict[str, Tuple[float, float]] = {}
    for name, part in parts.items():
        py, px, _ = rate_pairs(part, u, window_s)
        if len(py) < 8:
            continue
        if np.std(px) >= min_turn:
            s_, b_, _ = robust_line(py, px)
            per[name] = (b_, s_)
        else:  # a group that barely turns tells the bias (at the common scale), not the scale
            per[name] = (float(np.median(py - scale * px)), math.nan)

    def spread(i: int) -> float:
        v = np.array([x[i] for x in per.values() if np.isfinite(x[i])])
        return float(np.std(v, ddof=1) / math.sqrt(len(v))) if len(v) >= 2 else math.nan

    return YawFit(bias, scale, spread(0), spread(1), res, len(y), per)


def refine_lag(imu: ImuData, ref: GroundTruth, u: np.ndarray, lag: float, opts: OdometryOptions,
               max_gap_s: float, name: str) -> float:
    """Step 2's refinement: the lag in ``lag`` +- ``opts.refine_s`` (1 ms steps) where the yaw-rate fit's
    residual is least (a parabola through the best three)."""
    lags = lag + np.arange(-opts.refine_s, opts.refine_s + 1e-9, 0.001)
    res = []
    for lg in lags:
        segs = _segments(imu, shifted(ref, lg), max_gap_s, name)
        y, x, _ = rate_pairs(segs, u, opts.window_s)
        res.append(robust_line(y, x)[2] if len(y) >= 8 else np.inf)
    res = np.asarray(res)
    i = int(np.argmin(res))
    if 0 < i < len(lags) - 1 and np.all(np.isfinite(res[i - 1:i + 2])):
        d = res[i - 1] - 2 * res[i] + res[i + 1]
        if d > 0:
            return float(lags[i] + 0.001 * 0.5 * (res[i - 1] - res[i + 1]) / d)
    return float(lags[i])


def shifted(ref: GroundTruth, lag_s: float, q_base_imu: Optional[np.ndarray] = None) -> GroundTruth:
    """The odometry on the IMU's clock (its stamps less ``lag_s``), its body turned into the IMU's
    (``q_base_imu``: the IMU's orientation in the base frame) where given."""
    q = ref.q_wxyz if q_base_imu is None else quat_mul(ref.q_wxyz, np.broadcast_to(q_base_imu, ref.q_wxyz.shape))
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return GroundTruth(np.asarray(ref.t_ns - int(round(lag_s * 1e9)), dtype=np.int64), ref.p, np.ascontiguousarray(q))


def _segments(imu: ImuData, ref: GroundTruth, max_gap_s: float, name: str) -> List[Segment]:
    return align(imu, ref, AlignOptions(max_gap_s=max_gap_s), name=name).segments


def forward_axis(segs: Sequence[Segment], u: np.ndarray, window_s: float, min_acc: float,
                 blocks: int = 4) -> Dict[str, Any]:
    """Step 4: the mounting yaw ψ (base = Rz(ψ) · level(u) · imu) from the horizontal specific force in
    the level IMU frame against the odometry's acceleration in its base frame, over windows of
    ``window_s``; the accelerometer's forward bias (module doc) with its spread across ``blocks`` time
    blocks. ``psi_deg`` None: the horizontal accelerations are too small to fix it."""
    lv = level(u)
    fl, ab, tm = [], [], []
    for s in segs:
        dt = float(np.median(np.diff(s.t_ns))) * 1e-9
        n = max(2, int(round(window_s / dt)))
        i0, i1 = _windows(s.t_ns, n)
        if len(i0) == 0:
            continue
        f_l = s.acc @ lv.T
        c = np.concatenate([[np.zeros(3)], np.cumsum(f_l[:-1] * np.diff(s.t_ns)[:, None] * 1e-9, 0)])
        span_s = (s.t_ns[i1] - s.t_ns[i0]) * 1e-9
        yaw = yaw_of(s.q_wxyz)
        a_w = (s.v[i1] - s.v[i0]) / span_s[:, None]
        ym = 0.5 * (yaw[i0] + yaw[i1])
        cy, sy = np.cos(ym), np.sin(ym)
        ab.append(np.stack([cy * a_w[:, 0] + sy * a_w[:, 1], -sy * a_w[:, 0] + cy * a_w[:, 1]], 1))
        fl.append(((c[i1] - c[i0]) / span_s[:, None])[:, :2])
        tm.append(0.5 * (s.t_ns[i0] + s.t_ns[i1]) * 1e-9)
    if not fl:
        return {"psi_deg": None, "horizontal_acc_rms_mps2": 0.0}
    f, a, t = np.concatenate(fl), np.concatenate(ab), np.concatenate(tm)
    rms = float(np.sqrt(np.mean(np.sum(a * a, 1))))
    out: Dict[str, Any] = {"psi_deg": None, "horizontal_acc_rms_mps2": rms, "windows": len(f)}
    if rms < min_acc:
        return out

    def psi_of(ff: np.ndarray, aa: np.ndarray) -> float:  # Rz(ψ) f = a, in the plane
        return math.atan2(float(np.sum(ff[:, 0] * aa[:, 1] - ff[:, 1] * aa[:, 0])), float(np.sum(ff * aa)))

    psi = psi_of(f, a)
    fb = f @ _rot_z(psi)[:2, :2].T
    fwd = fb[:, 0] - a[:, 0]
    edges = np.quantile(t, np.linspace(0, 1, blocks + 1))
    per_psi, per_b = [], []
    for j in range(blocks):
        m = (t >= edges[j]) & (t <= edges[j + 1])
        if m.sum() >= 3:
            per_psi.append(math.degrees(psi_of(f[m], a[m])))
            per_b.append(float(np.mean(fwd[m])))
    k = len(per_psi)
    psi_std = float(np.std(per_psi, ddof=1) / math.sqrt(k)) if k >= 2 else math.nan
    b_std = float(np.std(per_b, ddof=1) / math.sqrt(k)) if k >= 2 else math.nan
    r_base_imu = _rot_z(psi) @ lv
    out.update({"psi_deg": math.degrees(psi), "psi_std_deg": psi_std,
                "forward_axis_in_imu": (r_base_imu.T @ [1.0, 0, 0]).tolist(),
                "acc_residual_rms_mps2": float(np.sqrt(np.mean(np.sum((fb - a) ** 2, 1)))),
                "acc_forward_bias_mps2": float(np.mean(fwd)), "acc_forward_bias_std_mps2": b_std,
                "acc_forward_bias_blocks_mps2": per_b})
    return out


def yaw_floor(fit: YawFit, u: np.ndarray, opts: OdometryOptions = OdometryOptions()) -> Tuple[Floor, TraditionalParams, bool]:
    """The floor (module doc) and its standard deviations; whether the scale was applied."""
    scale_on = (np.isfinite(fit.scale_std) and abs(fit.scale - 1) > opts.scale_sigmas * fit.scale_std
                and abs(fit.scale - 1) > opts.min_scale)
    uu = np.outer(u, u)
    m_g = np.eye(3) + (1.0 / fit.scale - 1.0) * uu if scale_on else np.eye(3)
    p = TraditionalParams(m_g, fit.bias * u, np.zeros((3, 3)), np.eye(3), np.zeros(3),
                          time_offset=TIME_OFFSET_PRIOR_SAMPLES)
    std = TraditionalParams.unknown()
    std = TraditionalParams(np.abs(uu) * fit.scale_std / fit.scale ** 2 if scale_on else std.M_g,
                            np.abs(u) * fit.bias_std, std.G, std.M_a, std.b_a, time_offset=np.float64(np.nan))
    return Floor(p), std, bool(scale_on)


def held_back_yaw(segs: Sequence[Segment], floor: Optional[Floor], u: np.ndarray, window_s: float) -> Dict[str, float]:
    """The held-back block scored on what the odometry observes: the RMS [deg] of the yaw change over
    windows of ``window_s`` integrated from the gyro about ``u`` against the odometry's, raw and with
    ``floor`` (its gyro)."""
    raw, cal = [], []
    for s in segs:
        if len(s) < 4:
            continue
        g = s.gyro if floor is None else floor.apply(s.t_ns, s.gyro, s.acc)[0]
        dt = np.diff(s.t_ns) * 1e-9
        n = max(2, int(round(window_s / float(np.median(dt)))))
        i0, i1 = _windows(s.t_ns, n)
        if len(i0) == 0:
            continue
        yaw = yaw_of(s.q_wxyz)
        for gg, out in ((s.gyro, raw), (g, cal)):
            c = np.concatenate([[0.0], np.cumsum((gg[:-1] @ u) * dt)])
            out.append((c[i1] - c[i0]) - (yaw[i1] - yaw[i0]))
    if not raw:
        return {}
    r, c = np.concatenate(raw), np.concatenate(cal)
    return {"window_s": window_s, "windows": int(len(r)), "raw_yaw_deg": math.degrees(float(np.sqrt(np.mean(r * r)))),
            "profile_yaw_deg": math.degrees(float(np.sqrt(np.mean(c * c))))}


WHY = "planar odometry observes the yaw rate and the forward speed only"


class OdometrySource(Source):
    """Planar wheel odometry (module doc): ``inputs`` with their odometry ``groundtruths``, reference
    gaps longer than ``max_gap_s`` split (None: 0.05 s, or 1.5 periods of a sparse reference), the
    last ``val_fraction`` of each recording held back."""

    kind = "odometry"

    def __init__(self, inputs: Sequence[Path], groundtruths: Sequence[Optional[Path]], fmt: str = "auto",
                 columns: Any = None, max_gap_s: Optional[float] = None, val_fraction: float = 0.15,
                 device: Optional[str] = None, opts: OdometryOptions = OdometryOptions()) -> None:
        self.inputs = [Path(p) for p in inputs]
        self.groundtruths = [None if g is None else Path(g) for g in groundtruths]
        self.groundtruths += [None] * (len(self.inputs) - len(self.groundtruths))
        self.fmt, self.columns, self.max_gap_s = fmt, columns, max_gap_s
        self.val_fraction, self.device, self.opts = val_fraction, device, opts
        self.u: Optional[np.ndarray] = None
        self.u_from = ""
        self.lags: List[Dict[str, float]] = []
        self.fwd: Dict[str, Any] = {}
        self.yaw: Optional[YawFit] = None
        self.scale_applied = False

    def read(self, progress: Progress = lambda s: None) -> CalibInputs:
        _check_exist([*self.inputs, *self.groundtruths])
        pairs, names, sources, fmts = [], [], [], []
        for path, gt in zip(self.inputs, self.groundtruths):
            fmts.append(_format(path, self.fmt, self.columns))
            pairs.append(read_recording(path, self.fmt, gt, columns=self.columns))
            names.append(_name(path))
            sources.append({"recording": str(path), "format": fmts[-1], "groundtruth": str(gt) if gt else "the format's own",
                            "reference_kind": "odometry"})
        return self.read_pairs(pairs, names, sources, fmts[0] if fmts else "auto", progress)

    def read_pairs(self, pairs: Sequence[Tuple[ImuData, GroundTruth]], names: Sequence[str],
                   sources: Optional[List[Dict[str, Any]]] = None, fmt: str = "auto",
                   progress: Progress = lambda s: None) -> CalibInputs:
        """Steps 1-4 (module doc) on (IMU, odometry) pairs, the recordings cut into the fitted and the
        held-back block."""

        o = self.opts
        sources = sources if sources is not None else [{"recording": n, "reference_kind": "odometry"} for n in names]
        progress("planar odometry: the IMU's vertical axis, the lag, the yaw rate")
        imu_all = ImuData(np.concatenate([p[0].t_ns for p in pairs]), np.concatenate([p[0].gyro for p in pairs]),
                          np.concatenate([p[0].acc for p in pairs]))
        self.u, self.u_from = vertical_axis(imu_all if len(pairs) == 1 else pairs[0][0], o)
        u = self.u
        self.lags = []
        for (imu, ref), name in zip(pairs, names):
            yaw = yaw_of(ref.q_wxyz)
            rate = np.diff(yaw) / np.maximum(np.diff(ref.t_ns) * 1e-9, 1e-9)
            if float(np.sqrt(np.mean(rate ** 2))) < o.min_yaw_rate or float(np.ptp(yaw)) < math.radians(10):
                raise ReferenceFrameError(
                    f"{name}: the odometry does not turn (yaw rate {np.sqrt(np.mean(rate ** 2)):.3f} rad/s RMS, "
                    f"{math.degrees(float(np.ptp(yaw))):.1f}° of yaw in all): it observes the gyro about the vertical "
                    "only through turns; record the robot turning")
            gap = self.max_gap_s if self.max_gap_s is not None else default_gap_s(ref)
            vert = ImuData(imu.t_ns, np.outer(imu.gyro @ u, [0.0, 0.0, 1.0]), imu.acc)
            lag, corr, edge = fit_lag(vert, ref, o.max_lag_s)
            if not np.isfinite(corr) or corr < o.min_correlation:
                raise ReferenceFrameError(
                    f"{name}: the odometry's yaw rate does not follow the gyro about the IMU's vertical (correlation "
                    f"{corr:.2f} at its best lag, within +-{o.max_lag_s:g} s): a reference of another recording, a time "
                    "unit off, or a lag beyond the search")
            if edge:
                raise ReferenceFrameError(f"{name}: the odometry lags the IMU by {lag:+.2f} s or more (the search's "
                                          f"edge, +-{o.max_lag_s:g} s): put both on one clock")
            fine = refine_lag(imu, ref, u, lag, o, gap, name)
            self.lags.append({"lag_s": fine, "correlation_lag_s": lag, "correlation": corr, "max_gap_s": gap})
        # step 4 needs the fitted block on the IMU's clock first: the forward axis, then the recordings
        base: List[List[Segment]] = []
        for (imu, ref), name, lg in zip(pairs, names, self.lags):
            segs = _segments(imu, shifted(ref, lg["lag_s"]), lg["max_gap_s"], name)
            base.append(held_back(segs, self.val_fraction)[0] if segs else [])
        self.fwd = forward_axis([s for b in base for s in b], u, o.acc_window_s, o.min_horizontal_acc, o.blocks)
        psi = math.radians(self.fwd["psi_deg"]) if self.fwd.get("psi_deg") is not None else 0.0
        q_base_imu = quat_from_matrix(_rot_z(psi) @ level(u))  # the IMU in the base frame: R_base_imu = Rz(ψ) level(u)
        recordings: List[Recording] = []
        observes = self.observes_keys()
        for (imu, ref), name, source, lg in zip(pairs, names, sources, self.lags):
            segs = _segments(imu, shifted(ref, lg["lag_s"], q_base_imu), lg["max_gap_s"], name)
            if not segs:
                raise ReferenceFrameError(f"{name}: no stretch of IMU samples with the odometry: check --max-gap-s "
                                          "and the clocks")
            tr, va = held_back(segs, self.val_fraction)
            recordings += [Recording(source["recording"], role, part, self.kind, observes)
                           for role, part in ((TRAIN, tr), (VAL, va)) if part]
            source.update({"max_gap_s": lg["max_gap_s"], "train": [span(s) for s in tr], "val": [span(s) for s in va]})
        inp = CalibInputs(recordings=recordings, settings=FitSettings(), sources=sources, source=self)
        inp.device = self.device or device_name(fmt, inp.train[0].name if inp.train else names[0])
        progress(f"odometry: vertical axis {_vec(u)} ({self.u_from}); lag {np.median([x['lag_s'] for x in self.lags]) * 1e3:+.1f} ms")
        return inp

    def _groups(self, inp: CalibInputs) -> Dict[str, List[Segment]]:
        out: Dict[str, List[Segment]] = {}
        for s, g in zip(inp.train, inp.groups):
            out.setdefault(g, []).append(s)
        return out

    def fit_floor(self, inp: CalibInputs, progress: Progress = lambda s: None, uncertainty: bool = True) -> FloorFit:
        """Step 3 on the fitted block: the floor of the module doc, its spread and the held-back block's
        yaw-only score (in the fit log)."""
        assert self.u is not None, "OdometrySource: read() first"
        progress("planar odometry: the gyro bias and scale about the vertical axis")
        self.yaw = fit_yaw(self._groups(inp), self.u, self.opts.window_s, self.opts.blocks, self.opts.min_yaw_rate)
        floor, std, self.scale_applied = yaw_floor(self.yaw, self.u, self.opts)
        y = self.yaw
        progress(f"odometry: gyro about the vertical: bias {y.bias:+.5f} ± {y.bias_std:.5f} rad/s, scale "
                 f"{y.scale:.4f} ± {y.scale_std:.4f}" + (" (applied)" if self.scale_applied else " (not significant)"))
        held = held_back_yaw(inp.val, floor, self.u, self.opts.window_s)
        entries = {"odometry": {
            "yaw_rate_fit": {"bias_rad_s": y.bias, "bias_std_rad_s": y.bias_std, "scale": y.scale,
                             "scale_std": y.scale_std, "scale_applied": self.scale_applied,
                             "residual_rad_s": y.residual, "windows": y.windows, "window_s": self.opts.window_s,
                             "groups": {k: {"bias_rad_s": b, "scale": s} for k, (b, s) in y.groups.items()}},
            "held_back_yaw": held, "forward_axis": self.fwd, "lags": self.lags}}
        return FloorFit(floor, {}, std, [], entries=entries)

    def band_limit(self) -> Optional[str]:
        return "planar wheel odometry: its rates and speed are the wheels', not the IMU's motion above their band"

    def reference(self) -> Dict[str, Any]:
        lag = float(np.median([x["lag_s"] for x in self.lags])) if self.lags else math.nan
        return {"kind": "odometry", "vertical_axis_in_imu": None if self.u is None else self.u.tolist(),
                "vertical_from": self.u_from, "lag_s": lag,
                "lag_correlation": float(min(x["correlation"] for x in self.lags)) if self.lags else math.nan,
                "lags": self.lags, "mounting_yaw_deg": self.fwd.get("psi_deg"),
                "mounting_yaw_std_deg": self.fwd.get("psi_std_deg"),
                "forward_axis_in_imu": self.fwd.get("forward_axis_in_imu"),
                "applied": {"lag": bool(self.lags), "rotation": True, "level": False, "scale": False, "lever_arm": False},
                "rotation_deg": self._rotation_deg(), "rotation_from": "planar odometry: the vertical from gravity, the forward axis "
                                                         "from the horizontal specific force"}

    def _rotation_deg(self) -> float:
        """The angle of R_base_imu (the IMU in the odometry's base frame), NaN before read()."""
        if self.u is None:
            return math.nan
        psi = math.radians(self.fwd["psi_deg"]) if self.fwd.get("psi_deg") is not None else 0.0
        r = _rot_z(psi) @ level(self.u)
        return math.degrees(math.acos(float(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0))))

    def observes_keys(self) -> Tuple[str, ...]:
        return ("gyroscope.bias",) + (("gyroscope.matrix",) if self.scale_applied else ())

    def observed(self) -> Dict[str, Dict[str, Any]]:
        u = "?" if self.u is None else _vec(self.u)
        out: Dict[str, Dict[str, Any]] = {k: {"observed": False, "why": f"{WHY}: kept at the prior"} for k in OBSERVABLE}
        out["gyroscope.bias"] = {
            "observed": True, "why": "planar odometry observes the yaw rate: the gyro bias and scale about the vertical "
            "axis", "partly": f"about the vertical axis {u} only; the components across it kept at the prior 0"}
        y = self.yaw
        scale = "" if y is None else f" (scale {y.scale:.4f} ± {y.scale_std:.4f})"
        if self.scale_applied:
            out["gyroscope.matrix"] = {"observed": True, "why": "planar odometry observes the yaw rate: the gyro scale "
                                       f"about the vertical axis{scale}", "partly": "the scale about the vertical axis only, "
                                       "relative to the odometry's yaw (a wheel-base error of the odometry reads as one); "
                                       "across it the identity"}
        else:
            out["gyroscope.matrix"] = {"observed": False, "why": "planar odometry observes the yaw rate: the gyro scale "
                                       f"about the vertical axis is not significant{scale}; identity"}
        lag = self.reference().get("lag_s", math.nan)
        out["time_offset"] = {"observed": False, "why": f"the odometry's stamps were {lag * 1e3:+.0f} ms off the IMU's; "
                              "the IMU's own offset cannot be told apart from the odometry's latency: the prior, the "
                              "zero-order hold's half sample"}
        b = self.fwd.get("acc_forward_bias_mps2")
        fb = "" if b is None else f" (found {b:+.3f} ± {self.fwd.get('acc_forward_bias_std_mps2', math.nan):.3f} m/s^2)"
        out["accelerometer.bias"] = {"observed": False, "why": f"{WHY}: the forward speed gives the bias along the "
                                     f"forward axis{fb}, but the vertical axis comes from the same accelerometer at rest, "
                                     "so that bias tilts it and cancels itself on a level floor, and in turns the IMU's "
                                     "offset from the base's centre adds a body-fixed centripetal term; kept at the prior 0"}
        out["g_sensitivity"]["why"] = f"{WHY}: no rotation across the vertical to tell it; kept at the prior 0"
        for k in ("accelerometer.matrix", "cutoff_gyro", "cutoff_acc"):
            out[k]["why"] = f"{WHY}: no specific force across the plane, no fast rotation; kept at the prior"
        return out


def _vec(v: Any) -> str:
    return "[" + ", ".join(f"{x:+.4f}" for x in np.asarray(v, dtype=np.float64)) + "]"


__all__ = ["OdometryOptions", "OdometrySource", "YawFit", "fit_yaw", "held_back_yaw", "is_odometry_reference",
           "is_planar_odometry", "vertical_axis", "yaw_floor"]
