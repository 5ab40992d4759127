"""A device profile from positions only (RTK GNSS, a NavSatFix track written as TUM, any positions-only
trajectory): attitude is a latent state, estimated by the navigator.

A reference of positions alone cannot be compared with the gyroscope directly
(:func:`imu_learn.calib.reference.check_orientation` refuses it for the 6-DoF path). Here:

1. ``imu-learn navigate``'s smoother (:func:`imu_learn.fuse.navigate.navigate`, batch pass over the
   whole recording, the positions as aiding, no outages) estimates the attitude. Its smoothed
   trajectory (keyframes at ``keyframe_hz``, body frame) is moved into the IMU's own frame
   (``R_W_imu = R_W_body M``, body = M imu) and back onto the IMU's clock (minus the logging delay), and
   aligned onto the IMU stamps (:func:`imu_learn.data.loading.align`: slerp, velocity from a local
   quadratic fit of the positions) as a 6-DoF reference.
2. The bias-only floor against it: :func:`imu_learn.calib.fit.fit_once` with ``terms`` holding every
   matrix at the identity and G at zero (``held`` = both sensors: the biases alone solved), no
   low-pass (``cutoffs_hz=(None,)``) and no time offset (``fit_offset=False``): TraditionalTiming's own
   windowed rotation and velocity residuals, robust (Huber), so the gyro bias is the robust mean of
   ω_imu − ω_smoothed over its windows and the acc bias that of the velocity increments. Its standard
   error: the same fit on ``blocks`` time blocks alone, spread / sqrt(blocks) (as calibrate's
   uncertainty for one recording).
3. The smoother again with that floor applied (a profile written beside the pass's outputs), a new fit
   of what bias remains, added; repeated until every bias component changed by less than its standard
   error, at most ``max_iterations`` passes.

The mounting (which IMU axis is forward) matters to the navigator: it starts with the body x-axis along
the track. Given (``imu_rotation_rpy_deg``) it is used as is; otherwise
:func:`..mounting.mounting_from_track` estimates it from the data: the IMU's up from the accelerometer at
the start, its forward from the horizontal specific force against the track's along- and cross-track
accelerations (over 3 m/s where the track has enough fixes, else over 1 m/s with navigate's checks; a
track that shows no forward axis leaves the IMU's own axes, except with ``nhc``). The IMU's logging
delay against the positions (``imu_delay_s``, the navigator's convention: added to every IMU stamp) is
given, or estimated from the data (:func:`estimate_imu_delay`: the same levelled horizontal specific
force against the track's, over a 1-D search of candidate delays); a lag left in leaks into the forward
accelerometer bias. The delay and the antenna's lever arm are the navigator's options and stay out of
the profile (its time offset is 0 and not observed); profile.json's ``reference`` records them, the
delay with its standard error and whether it was given or estimated.

What the profile says it observed (:func:`observed`): the gyro and accelerometer biases; the matrices,
g-sensitivity, cutoffs and time offset are held at their priors. :class:`PositionsSource` is calibrate's
reference source for positions (:mod:`imu_learn.calib.sources`): its recordings are the final pass's
reference, its floor this bias-only one; :func:`calibrate_positions` writes the profile through
:func:`imu_learn.calib.run.calibrate` (its checks, noise and files, as for every reference kind).
"""
from __future__ import annotations

import math
import tempfile
import time
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.baselines.affine import Floor, TraditionalParams
from imu_learn.baselines.base import FitSettings
from imu_learn.calib import fit as ff
from imu_learn.calib import run as cr
from imu_learn.calib.frames import default_gap_s
from imu_learn.calib.profile import FloorFit, Profile
from imu_learn.calib.sources import NAVIGATOR_OPTIONS, OBSERVABLE, TRAIN, VAL, CalibInputs, Recording, Source, span
from imu_learn.calib.sources import held_back as _held_back
from imu_learn.core.quat import xyzw_to_wxyz
from imu_learn.core.stamps import sample_rate_hz
from imu_learn.data import formats
from imu_learn.data.formats.extrinsics import read_t_bs
from imu_learn.data.formats.gnss_imu import mounting_rotation
from imu_learn.data.formats.source import CsvColumns
from imu_learn.data.loading import AlignOptions, align
from imu_learn.data.types import GroundTruth, ImuData, Segment
from imu_learn.errors import ConfigError, InvalidInputError
from imu_learn.fuse.aiding.detect import detect
from imu_learn.fuse.aiding.rtklib import normal_gravity, read_pos
from imu_learn.fuse.aiding.tum import Trajectory, check_overlap, read_trajectory
from imu_learn.fuse.mounting import _level_rotation, mounting_from_track
from imu_learn.fuse.navigate import ImuRecording, NavigateOptions, Sources, navigate, parse_vector, read_imu
from imu_learn.fuse.noise import ImuNoise
from imu_learn.infer.rates import recording_device

Progress = Callable[[str], None]

WHY = "from positions via the navigator's smoothed attitude"
FLOOR_KEYS = OBSERVABLE
BIASES = ("b_g", "b_a")  # what it fits


@dataclass(frozen=True)
class PositionsOptions:
    """How the navigator runs over the recording (its options of the same names) and how the floor is
    iterated."""

    fmt: str = "auto"  # the recording's layout
    columns: Optional[CsvColumns] = None  # a user's CSV: its column map and units (``--columns`` ...)
    imu_rotation_rpy_deg: Optional[Tuple[float, float, float]] = None  # None: :func:`mounting_from_track`
    imu_delay_s: Optional[float] = None  # added to every IMU stamp; None: :func:`estimate_imu_delay`
    lever_arm: Optional[Tuple[float, float, float]] = None
    imu_noise: Optional[Tuple[float, float, float, float]] = None  # None: the navigator's built-in figures
    keyframe_hz: float = 10.0
    nhc: bool = False
    max_iterations: int = 4
    blocks: int = 4
    max_windows: Optional[int] = None  # the floor fit's window budget (None: TraditionalTiming's default)
    val_fraction: float = 0.15  # the held-back block of the final reference (plausibility)


@dataclass
class PositionsFloor:
    """The result: the floor, per parameter its standard error (NaN: held at its prior), the
    ``observed`` dict, the ``reference`` dict for profile.json, each pass's log, and the final
    reference as segments (``train``/``val``) with the gravity the fit used."""

    floor: Floor
    std: TraditionalParams
    observed: Dict[str, Dict[str, Any]]
    reference: Dict[str, Any]
    passes: List[Dict[str, Any]]
    train: List[Segment] = field(default_factory=list)
    val: List[Segment] = field(default_factory=list)
    gravity: float = 9.81


# ------------------------------------------------------------------------------------------------
# what a positions reference is


def reference_format(path: Path) -> str:
    """The aiding format of ``path`` (:func:`imu_learn.fuse.aiding.detect.detect`)."""

    return detect(Path(path))


def is_positions_reference(path: Path) -> bool:
    """Whether ``path`` holds positions only: an RTKLIB ``.pos`` file (by its content), or a TUM/CSV
    trajectory with 4 columns or whose orientation never changes (check_orientation's rule)."""

    path = Path(path)
    if not path.is_file():
        return False
    try:
        fmt = reference_format(path)
    except (OSError, ValueError):
        return False
    if fmt == "rtklib":
        return True
    if fmt not in ("tum", "csv"):
        return False
    try:
        traj = read_trajectory(path, fmt, need_orientation=False)
    except Exception:  # noqa: BLE001 - not a trajectory this reader takes: the 6-DoF path reports it
        return False
    if traj.q_xyzw is None:
        return True
    q = traj.q_xyzw
    dots = np.abs(q @ q[0])
    return bool(np.max(2 * np.arccos(np.clip(dots, -1, 1))) < math.radians(0.5))


def read_fix_track(path: Path) -> Tuple[Trajectory, float, str]:
    """(the fixes as a positions-only trajectory, with their lines in the file; gravity [m/s^2]; format)
    of a positions file: RTKLIB fixed and float epochs in ENU at the first epoch with the normal gravity
    there, or a TUM/CSV's positions with the navigator's default gravity (9.81)."""

    fmt = reference_format(path)
    if fmt == "rtklib":
        sol = read_pos(Path(path))
        keep = np.isin(sol.q, (1, 2))
        return (Trajectory(sol.t_ns[keep], sol.enu[keep], None, str(path), sol.lines[keep]),
                normal_gravity(sol.origin_llh[0], sol.origin_llh[2]), fmt)
    return read_trajectory(path, fmt, need_orientation=False), 9.81, fmt


def read_fixes(path: Path) -> Tuple[np.ndarray, np.ndarray, float, str]:
    """(t_ns, positions (M, 3) in a local z-up frame, gravity [m/s^2], format): :func:`read_fix_track`."""
    traj, gravity, fmt = read_fix_track(path)
    return traj.t_ns, traj.p, gravity, fmt


# ------------------------------------------------------------------------------------------------
# the IMU's logging delay, from the data


def estimate_imu_delay(t_ns: np.ndarray, acc: np.ndarray, fix_t_ns: np.ndarray, fix_p: np.ndarray,
                       gravity: float = 9.81, search_s: float = 0.5, step_s: float = 0.005, blocks: int = 4,
                       min_speed: float = 1.0, level_s: float = 2.0, span_s: float = 0.5) -> Dict[str, Any]:
    """The IMU's logging delay against the positions, in the navigator's convention (``--imu-delay-s``:
    added to every IMU stamp; a log written 0.125 s late gives -0.125), without a reference attitude.

    The IMU's specific force is levelled with its mean over the first ``level_s`` (as
    :func:`forward_mounting`) and smoothed with the kernel the track's second difference over +-T applies
    (a triangle of half-width T: ``span_s``, at least two fix periods; it averages the fixes' noise); the
    track gives its along-track acceleration plus gravity along the grade and its cross-track one at every
    fix faster than ``min_speed``. For each candidate
    delay d in [-search_s, search_s] (steps of ``step_s``) the IMU's horizontal force at the stamps
    ``fix - d`` is fitted to the track's by one complex factor (the forward axis's heading and a scale,
    least squares); the delay is the one with the least RMS residual, refined by a parabola through
    its neighbours. Standard error: the same search on ``blocks`` time blocks alone, spread /
    sqrt(blocks). Returns {"imu_delay_s", "std_s", "blocks_s", "residual_mps2", "residual_at_zero_mps2",
    "fixes_used", "search_s", "at_edge"} (at_edge: the minimum at the end of the search, not trusted)."""
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    tf = (np.asarray(fix_t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    acc = np.asarray(acc, dtype=np.float64)
    up = np.mean(acc[t <= t[0] + level_s], axis=0)
    f = (acc @ _level_rotation(up / np.linalg.norm(up)).T)[:, :2]
    T = max(span_s, 2 * float(np.median(np.diff(tf))))
    pt = [np.stack([np.interp(tf + u, tf, fix_p[:, j]) for j in range(3)], axis=1) for u in (-T, T)]
    v = (pt[1] - pt[0]) / (2 * T)
    a = (pt[1] - 2 * np.asarray(fix_p, dtype=np.float64) + pt[0]) / T ** 2
    speed = np.linalg.norm(v[:, :2], axis=1)
    sp = np.maximum(speed, 1e-9)
    track = ((a[:, 0] * v[:, 0] + a[:, 1] * v[:, 1] + gravity * v[:, 2]) / sp  # along, with the grade
             + 1j * (v[:, 0] * a[:, 1] - v[:, 1] * a[:, 0]) / sp)  # cross (to the left)
    dt = float(np.median(np.diff(t)))
    h = max(1, int(round(T / dt)))
    kern = np.concatenate([np.arange(1, h + 1), np.arange(h + 1, 0, -1)]).astype(np.float64)
    kern /= kern.sum()
    z = np.convolve(f[:, 0], kern, "same") + 1j * np.convolve(f[:, 1], kern, "same")
    ok = speed > min_speed
    ok &= (tf - T >= tf[0]) & (tf + T <= tf[-1])
    ok &= (tf - search_s > t[0] + 2 * h * dt) & (tf + search_s < t[-1] - 2 * h * dt)
    if ok.sum() < 40:
        raise InvalidInputError(f"positions: {int(ok.sum())} fixes faster than {min_speed:g} m/s; the IMU's logging "
                                "delay cannot be estimated from the track (give --imu-delay-s)")
    ds = np.arange(-search_s, search_s + step_s / 2, step_s)
    tk = tf[ok]
    Z = np.stack([np.interp(tk - d, t, z.real) + 1j * np.interp(tk - d, t, z.imag) for d in ds])
    S = track[ok]

    def search(sel: np.ndarray) -> Tuple[float, np.ndarray, int]:
        s_ = S[sel]
        c = (Z[:, sel] @ s_.conj()) / np.vdot(s_, s_).real
        r = np.sqrt(np.mean(np.abs(Z[:, sel] - c[:, None] * s_[None, :]) ** 2, axis=1))
        i = int(np.argmin(r))
        d = float(ds[i])
        if 0 < i < len(ds) - 1:
            den = r[i - 1] - 2 * r[i] + r[i + 1]
            if den > 0:
                d += 0.5 * step_s * float(r[i - 1] - r[i + 1]) / float(den)
        return d, r, i

    d, r, i = search(np.ones(len(S), dtype=bool))
    edges = np.linspace(tk[0], tk[-1] + 1e-9, blocks + 1)
    per = []
    for b in range(blocks):
        sel = (tk >= edges[b]) & (tk < edges[b + 1])
        if sel.sum() >= 20:
            per.append(search(sel)[0])
    std = float(np.std(per, ddof=1) / math.sqrt(len(per))) if len(per) >= 2 else math.nan
    return {"imu_delay_s": d, "std_s": std, "blocks_s": per, "residual_mps2": float(r[i]),
            "residual_at_zero_mps2": float(r[int(np.argmin(np.abs(ds)))]), "fixes_used": int(ok.sum()),
            "search_s": search_s, "at_edge": i in (0, len(ds) - 1)}


DELAY_SIGMAS = 2.0  # an estimated IMU delay within this many standard deviations of 0 is held at 0


def imu_delay(opts: PositionsOptions, imu: ImuData, fix_t: np.ndarray, fix_p: np.ndarray,
              gravity: float) -> Tuple[float, Dict[str, Any]]:
    """(the delay the navigator gets, profile.json's ``reference.imu_delay`` entry): ``opts.imu_delay_s``
    as given, else :func:`estimate_imu_delay`."""
    if opts.imu_delay_s is not None:
        return float(opts.imu_delay_s), {"s": float(opts.imu_delay_s), "std_s": None, "from": "given"}
    est = estimate_imu_delay(imu.t_ns, imu.acc, fix_t, fix_p, gravity)
    if est["at_edge"]:
        raise InvalidInputError(f"positions: the IMU's logging delay is beyond +-{est['search_s']:g} s or not "
                                "observed by the track (give --imu-delay-s)")
    d, sd = float(est["imu_delay_s"]), est["std_s"]
    if sd is not None and math.isfinite(float(sd)) and abs(d) < DELAY_SIGMAS * float(sd):
        # not told apart from none: held at 0, the estimate kept beside (the walk: 66 +- 48 ms)
        return 0.0, {**est, "s": 0.0, "std_s": sd, "estimate_s": d,
                     "from": f"held at 0: the track's estimate {d * 1e3:+.0f} +- {float(sd) * 1e3:.0f} ms is within "
                             f"{DELAY_SIGMAS:g} standard deviations of it"}
    return d, {**est, "s": d, "std_s": sd, "from": "estimated from the track (estimate_imu_delay)"}


# ------------------------------------------------------------------------------------------------
# one pass: the smoother, its trajectory as a reference, the bias-only floor against it


def bias_floor(b_g: Sequence[float], b_a: Sequence[float]) -> Floor:
    """A ``traditional+timing`` floor with biases only (identity matrices, no G, no filter, no offset)."""
    return Floor(TraditionalParams.biases(b_g, b_a))


def _bias_profile(floor: Floor, device: str, rate: float) -> Profile:
    return Profile.of_floor(device, rate, 1.0 / rate, floor, TraditionalParams.unknown(), math.nan, math.nan)


def smoother_pass(rec: ImuRecording, imu_path: Path, ref_path: Path, opts: PositionsOptions, rpy: Sequence[float],
                  floor: Optional[Floor], out: Path, device: str, rate: float) -> Dict[str, Any]:
    """The navigator over the whole recording ``imu_path`` (its IMU ``rec``, read once for every pass;
    positions as aiding, no gaps), with ``floor`` applied through a profile when given; returns its
    summary (the trajectories in ``out``)."""

    out.mkdir(parents=True, exist_ok=True)
    prof = None
    if floor is not None:
        prof = out / "floor_profile.json"
        _bias_profile(floor, device, rate).save(prof)
    n = ImuNoise()
    noise = opts.imu_noise or (n.gyro_noise_density, n.acc_noise_density, n.gyro_random_walk, n.acc_random_walk)
    nav = NavigateOptions(aiding_kind="position", aiding_format="auto", keyframe_hz=opts.keyframe_hz,
                          imu_rotation_rpy_deg=tuple(float(x) for x in rpy), imu_delay_s=opts.imu_delay_s, imu_delay_from="option",
                          lever_arm=None if opts.lever_arm is None else tuple(opts.lever_arm), nhc=opts.nhc,
                          imu_noise=tuple(float(x) for x in noise))
    return navigate(Sources(input=Path(imu_path), aiding=Path(ref_path), fmt=opts.fmt, columns=opts.columns,
                            profile=prof, recording=rec), out, nav)


def smoothed_groundtruth(smoothed_tum: Path, mounting: np.ndarray, delay_s: float) -> GroundTruth:
    """The navigator's smoothed trajectory (body frame, the delayed IMU clock) as the IMU's own pose on
    the IMU's recorded clock: ``R_W_imu = R_W_body M``, stamps minus the delay; no velocity (aligning
    derives it)."""

    tr = read_trajectory(smoothed_tum, "tum")
    R = Rotation.from_quat(tr.q_xyzw).as_matrix() @ mounting
    q = xyzw_to_wxyz(Rotation.from_matrix(R).as_quat())
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)
    return GroundTruth(t_ns=tr.t_ns - int(round(delay_s * 1e9)), p=tr.p.copy(), q_wxyz=q)


def reference_segments(imu: ImuData, gt: GroundTruth, name: str) -> List[Segment]:
    """The IMU with the reference on its stamps (gaps of more than 1.5 keyframe periods split)."""

    return list(align(imu, gt, AlignOptions(max_gap_s=default_gap_s(gt)), name=name).segments)


def fit_biases(train: List[Segment], val: List[Segment], settings: FitSettings, blocks: int = 4,
               max_windows: Optional[int] = None) -> Tuple[Floor, TraditionalParams, Dict[str, Any]]:
    """(bias-only floor, its standard errors (of b_g and b_a from ``blocks`` time blocks; the rest, held
    at the prior, NaN), the fit log):
    :func:`imu_learn.calib.fit.fit_once` with the matrices held (module docstring)."""
    terms = {"cutoffs_hz": (None,), "held": ("gyro", "acc"), "fit_offset": False}
    method, log = ff.fit_once(train, val, settings, max_windows, terms)
    p = TraditionalParams.from_dict(method.to_dict())
    floor = bias_floor(p.b_g, p.b_a)
    per: List[TraditionalParams] = []
    for tr, _ in ff.time_blocks(train, blocks).values():
        if not any(len(s) > settings.window + 1 for s in tr):
            continue
        m, _ = ff.fit_once(tr, [], settings, max_windows, terms)
        per.append(TraditionalParams.from_dict(m.to_dict()))
    k = len(per)
    values = {n: np.stack([q.estimate(n) for q in per]) for n in BIASES} if k else {}
    std = TraditionalParams.unknown()  # what is held at its prior has none
    if k >= 2:
        std = replace(std, **{n: np.std(v, axis=0, ddof=1) / math.sqrt(k) for n, v in values.items()})
    info = {"log": log, "blocks": {n: v.tolist() for n, v in values.items()}}
    return floor, std, info


def observed() -> Dict[str, Dict[str, Any]]:
    """profile.json's ``observed`` for a positions reference."""
    out = {k: {"observed": False, "why": ""} for k in FLOOR_KEYS}
    out["gyroscope.bias"] = {"observed": True, "why": WHY}
    out["accelerometer.bias"] = {"observed": True, "why": WHY}
    held = ("a positions-only reference: the attitude is the navigator's estimate, which already assumes an "
            "identity {what}; kept at the prior ({prior})")
    out["gyroscope.matrix"]["why"] = held.format(what="gyroscope scale and misalignment", prior="identity")
    out["accelerometer.matrix"]["why"] = held.format(what="accelerometer scale and misalignment", prior="identity")
    out["g_sensitivity"]["why"] = held.format(what="g-sensitivity", prior="zero")
    for k in ("cutoff_gyro", "cutoff_acc"):
        out[k]["why"] = ("a positions-only reference, smoothed through keyframes, cannot tell a low-pass the IMU needs; "
                         "kept at the prior (no filter)")
    out["time_offset"]["why"] = ("positions only: the IMU's offset cannot be told apart from the logging delay the "
                                 "navigator was given or estimated (reference.navigator.imu_delay); kept at 0")
    return out


@dataclass(frozen=True)
class _Setup:
    """What every pass of :func:`positions_floor` shares: the recording's IMU (read once), the fixes'
    format and gravity, the navigator's options with the delay settled, the mounting and where the
    delay and mounting came from."""

    imu_path: Path
    ref_path: Path
    rec: ImuRecording
    opts: PositionsOptions
    rpy: List[float]
    gravity: float
    ref_fmt: str
    delay_info: Dict[str, Any]
    mount_info: Dict[str, Any]

    @property
    def imu(self) -> ImuData:
        return imu_data(self.rec)

    @property
    def rate(self) -> float:
        return float(sample_rate_hz(self.rec.t_ns))

    @property
    def name(self) -> str:
        return self.imu_path.stem if self.imu_path.is_file() else self.imu_path.name

    @property
    def mounting(self) -> np.ndarray:
        return mounting_rotation(self.rpy)


def imu_data(rec: ImuRecording) -> ImuData:
    """The recording's IMU as the floor fits take it (no copy where it is float64 already)."""
    return ImuData(t_ns=rec.t_ns, gyro=np.asarray(rec.gyro, dtype=np.float64), acc=np.asarray(rec.acc, dtype=np.float64))


def _setup(imu_path: Path, ref_path: Path, opts: PositionsOptions, progress: Progress) -> _Setup:
    """The recording and its fixes read and checked against each other, the IMU's logging delay and its
    mounting given or estimated from the track."""
    rec = read_imu(imu_path, opts.fmt, opts.columns)  # once: every smoother pass takes it
    imu = imu_data(rec)
    track, gravity, ref_fmt = read_fix_track(ref_path)
    check_overlap(track, imu.t_ns, "positions")  # another recording's fixes: named before any estimate
    fix_t, fix_p = track.t_ns, track.p
    if opts.imu_delay_s is None:
        progress("positions: the IMU's logging delay from the track")
    delay, delay_info = imu_delay(opts, imu, fix_t, fix_p, gravity)
    if delay_info["from"] != "given":
        progress(f"positions: IMU delay {delay:+.3f} s (+-{delay_info['std_s']:.3f}), estimated")
    opts = replace(opts, imu_delay_s=delay)
    if opts.imu_rotation_rpy_deg is not None:
        rpy, mount_info = [float(x) for x in opts.imu_rotation_rpy_deg], {"from": "given"}
    else:
        progress("positions: the IMU's forward axis from the track")
        est = mounting_from_track(imu.t_ns + int(round(delay * 1e9)), imu.acc, fix_t, fix_p, gravity, need_forward=opts.nhc)
        rpy, mount_info = est["rpy_deg"], est
        if "why" in est:
            progress(f"positions: {est['from']} ({est['why']})")
    return _Setup(imu_path, ref_path, rec, opts, rpy, gravity, ref_fmt, delay_info, mount_info)


def _pass_reference(run: _Setup, summ: Dict[str, Any], settings: FitSettings) -> Tuple[List[Segment], List[Segment]]:
    """(fitted, held-back) segments of the IMU with a pass's smoothed trajectory as its reference;
    refused where the trajectory leaves less than the floor's window to fit on."""
    gt = smoothed_groundtruth(Path(summ["outputs"]["smoothed"]), run.mounting, float(run.opts.imu_delay_s))
    segs = reference_segments(run.imu, gt, run.name)
    if not segs:
        raise InvalidInputError(f"{run.ref_path}: the navigator's smoothed trajectory gives no stretch of reference")
    train, val = held_back(segs, run.opts.val_fraction)
    longest = max(len(s) for s in train) if train else 0
    if longest <= settings.window + 1:
        start_s = float(summ.get("init", {}).get("start_after_first_sample_s") or 0.0)
        raise InvalidInputError(
            f"{run.ref_path}: the navigator's smoothed trajectory leaves {longest / run.rate:.1f} s of the IMU to fit on "
            f"(it starts {start_s:.1f} s in, where the track first gives the heading: a fix faster than 1 m/s; "
            f"the last {run.opts.val_fraction:g} held back), shorter than the floor's window "
            f"({settings.window} samples): a longer recording, or one that moves sooner")
    return train, val


def _reference_entry(run: _Setup, passes: List[Dict[str, Any]]) -> Dict[str, Any]:
    """profile.json's ``reference`` for the positions: the method, the navigator's settings, the passes."""
    last = passes[-1]
    converged = len(passes) > 1 and all(abs(c) < s for c, s in zip(last["change_b_g"] + last["change_b_a"],
                                                                     last["std_b_g"] + last["std_b_a"]))
    opts = run.opts
    return {
        "kind": "positions", "file": str(run.ref_path), "format": run.ref_fmt,
        "method": "attitude a latent state: the navigator's smoothed trajectory (positions as aiding, no outages) "
                  "as the reference, the bias-only floor fitted against it, the smoother run again with it; "
                  "repeated until the biases change by less than their standard error",
        "navigator": {"imu_rotation_rpy_deg": run.rpy, "mounting": run.mount_info, "imu_delay_s": opts.imu_delay_s,
                      "imu_delay": run.delay_info, "lever_arm_m": None if opts.lever_arm is None else list(opts.lever_arm),
                      "imu_noise": None if opts.imu_noise is None else list(opts.imu_noise),
                      "keyframe_hz": opts.keyframe_hz, "nhc": opts.nhc, "gravity_mps2": run.gravity},
        "passes": len(passes), "converged": bool(converged),
        "floor_fit": "calib.fit.fit_once, terms cutoffs_hz=(None,), held=(gyro, acc) (M_g, G, M_a held), "
                     "fit_offset=False",
    }


def positions_floor(imu_path: Path, ref_path: Path, opts: PositionsOptions = PositionsOptions(),
                    work: Optional[Path] = None, progress: Progress = lambda s: None,
                    device: str = "unknown") -> PositionsFloor:
    """The bias-only floor of the recording ``imu_path`` from the positions in ``ref_path``, with its
    standard errors, observed flags and passes (module docstring). ``work``: where each pass's
    navigator outputs go (default: a temporary folder, removed)."""

    run = _setup(Path(imu_path), Path(ref_path), opts, progress)
    M, settings = run.mounting, FitSettings(gravity=run.gravity)
    where = tempfile.TemporaryDirectory(prefix="imu-learn-positions-") if work is None else nullcontext(str(work))
    with where as folder:
        work = Path(folder)
        floor: Optional[Floor] = None
        total_g, total_a = np.zeros(3), np.zeros(3)
        passes: List[Dict[str, Any]] = []
        for k in range(max(1, opts.max_iterations)):
            t0 = time.perf_counter()
            progress(f"positions: pass {k + 1}: the navigator's smoother over {run.name}"
                     + (" with the floor so far" if floor is not None else ""))
            summ = smoother_pass(run.rec, run.imu_path, run.ref_path, run.opts, run.rpy, floor, work / f"pass{k + 1}",
                                 device, run.rate)
            train, val = _pass_reference(run, summ, settings)
            progress(f"positions: pass {k + 1}: the biases against the smoothed attitude")
            step, std, info = fit_biases([_applied(s, floor) for s in train], [_applied(s, floor) for s in val],
                                         settings, opts.blocks, opts.max_windows)
            d_g, d_a = step.params.b_g, step.params.b_a
            total_g, total_a = total_g + d_g, total_a + d_a
            floor = bias_floor(total_g, total_a)
            fb = np.asarray(summ["final_bias"], dtype=np.float64)
            passes.append({"pass": k + 1, "b_g": total_g.tolist(), "b_a": total_a.tolist(), "change_b_g": d_g.tolist(),
                           "change_b_a": d_a.tolist(), "std_b_g": std.b_g.tolist(), "std_b_a": std.b_a.tolist(),
                           "smoother_final_bias_imu": {"b_g": (M.T @ fb[:3]).tolist(), "b_a": (M.T @ fb[3:]).tolist()},
                           "keyframes": summ["keyframes"], "fixes": summ.get("position_fixes"),
                           "fit": {"blocks": info["blocks"]},
                           "seconds": round(time.perf_counter() - t0, 1)})
            progress(f"positions: pass {k + 1}: gyro bias {_vec(total_g)} rad/s (change {_vec(d_g)}, std "
                     f"{_vec(std.b_g)}), acc bias {_vec(total_a)} m/s^2 (change {_vec(d_a)}, std {_vec(std.b_a)})")
            if k > 0 and np.all(np.abs(d_g) < std.b_g) and np.all(np.abs(d_a) < std.b_a):
                break
    assert floor is not None
    return PositionsFloor(floor, std, observed(), _reference_entry(run, passes), passes, train, val, run.gravity)


def held_back(segments: List[Segment], frac: float) -> Tuple[List[Segment], List[Segment]]:
    """The fitted and the held-back block (the last ``frac`` of the recording), as calibrate cuts them."""
    return _held_back(segments, frac)


def _applied(s: Segment, floor: Optional[Floor]) -> Segment:
    """``s`` with the floor so far applied to its IMU (the next pass fits what bias remains)."""
    if floor is None:
        return s
    g, a = floor.apply(s.t_ns, s.gyro, s.acc)
    return replace(s, gyro=g, acc=a)


def _vec(v: Any) -> str:
    return "[" + ", ".join(f"{x:+.5f}" for x in np.asarray(v, dtype=np.float64)) + "]"


# ------------------------------------------------------------------------------------------------
# the reference source and the profile


class PositionsSource(Source):
    """calibrate's reference source for positions only (module doc): reading runs the smoother loop
    (:func:`positions_floor`, each pass's navigator outputs in ``work``; None: a temporary folder), whose
    final reference gives the recordings (one recording, its held-back block ``opts.val_fraction``) and
    whose bias-only floor is this source's :meth:`fit_floor`. ``device``: None, the format's device or
    the recording's name; ``entry``: profile.json's ``sources`` entry (default: the recording, its
    format and the positions file)."""

    kind = "positions"

    def __init__(self, imu_path: Path, ref_path: Path, opts: PositionsOptions = PositionsOptions(),
                 work: Optional[Path] = None, device: Optional[str] = None,
                 entry: Optional[Dict[str, Any]] = None) -> None:
        self.imu_path, self.ref_path, self.opts = Path(imu_path), Path(ref_path), opts
        self.work, self.device, self.entry = work, device, entry
        self.result: Optional[PositionsFloor] = None

    def read(self, progress: Progress = lambda s: None) -> CalibInputs:
        t0 = time.time()
        progress(f"{self.ref_path}: positions only: the attitude from the navigator's smoother (fuse.calibrate_positions)")
        name = self.imu_path.stem if self.imu_path.is_file() else self.imu_path.name
        device = self.device
        if device is None:

            device = recording_device(self.opts.fmt) or name
        res = self.result = positions_floor(self.imu_path, self.ref_path, self.opts, self.work, progress, device)
        fmt = formats.USER_CSV if formats.user_csv(self.opts.fmt, self.opts.columns) is not None else self.opts.fmt
        src = dict(self.entry or {"recording": str(self.imu_path), "format": fmt, "groundtruth": str(self.ref_path)})
        src.update({"train": [span(s) for s in res.train], "val": [span(s) for s in res.val]})
        observes = self.observes()
        recordings = [Recording(str(self.imu_path), role, part, self.kind, observes)
                      for role, part in ((TRAIN, res.train), (VAL, res.val)) if part]
        return CalibInputs(recordings=recordings, settings=FitSettings(gravity=res.gravity), device=device,
                           sources=[src], source=self, seconds=time.time() - t0)

    def _result(self) -> PositionsFloor:
        if self.result is None:
            raise RuntimeError("PositionsSource: read() first (the smoother loop fits the floor)")
        return self.result

    def fit_floor(self, inp: CalibInputs, progress: Progress = lambda s: None, uncertainty: bool = True) -> FloorFit:
        """The bias-only floor the smoother loop fitted, its standard errors and passes."""

        res = self._result()
        return FloorFit(res.floor, {}, res.std, [], entries={"positions": res.passes})

    def reference(self) -> Dict[str, Any]:
        return self._result().reference

    def band_limit(self) -> Optional[str]:
        return (f"a positions reference: its motion is the navigator's smoothed keyframes "
                f"({self.opts.keyframe_hz:g} Hz), the IMU's motion above their band is in the residuals")

    def observed(self) -> Dict[str, Dict[str, Any]]:
        return observed()


def calibrate_positions(imu_path: Path, ref_path: Path, out_dir: Path, opts: PositionsOptions = PositionsOptions(),
                        options: Any = None, device: Optional[str] = None, progress: Progress = lambda s: None,
                        source: Optional[Dict[str, Any]] = None) -> Any:
    """``imu-learn calibrate`` with a positions reference: :class:`PositionsSource`'s recordings and
    floor through :func:`imu_learn.calib.run.calibrate` (gravity, the residual and Allan noise, the
    plausibility checks, profile.json, imu.yaml, calibration.png), with its observed flags and
    ``reference`` kind "positions". The navigator's passes are kept in ``out_dir/positions/``.
    Returns a CalibResult."""

    out_dir = Path(out_dir)
    src = PositionsSource(imu_path, ref_path, opts, out_dir / "positions", device, source)
    return cr.calibrate(src.read(progress), out_dir, options if options is not None else cr.CalibOptions(), progress)


def source_from_cli(args: Any, columns: Optional[CsvColumns] = None) -> PositionsSource:
    """``imu-learn calibrate --input REC --groundtruth POSITIONS``'s source, with the command's options
    (one recording, a user's CSV where ``columns`` is given; the navigator's options
    :func:`navigator_options`); the navigator's passes in ``--out``/positions."""

    if len(args.input) != 1 or len(args.groundtruth or []) != 1:
        raise ConfigError("calibrate with a positions reference (GNSS): one --input and its --groundtruth")
    if args.learned:
        raise ConfigError("--learned needs a 6-DoF reference; a positions reference gives the bias-only floor")
    opts = PositionsOptions(fmt=args.format, columns=columns, val_fraction=args.val_fraction, **navigator_options(args))
    return PositionsSource(args.input[0], args.groundtruth[0], opts, Path(args.out) / "positions", args.device)




def navigator_options(args: Any) -> Dict[str, Any]:
    """The :class:`PositionsOptions` fields calibrate's navigator options give, with ``imu-learn
    navigate``'s names and conventions: ``--imu-rotation-rpy-deg R,P,Y`` (the body frame relative to
    the IMU frame), ``--imu-delay-s S`` (added to every IMU stamp; absent: estimated) and ``--lever-arm
    X,Y,Z`` (the antenna from the IMU in the body frame; or ``--extrinsics``' translation, not both)."""

    out: Dict[str, Any] = {}
    rpy, delay, lever = (getattr(args, k, None) for k in NAVIGATOR_OPTIONS)
    if rpy is not None:
        out["imu_rotation_rpy_deg"] = parse_vector(rpy, 3, "--imu-rotation-rpy-deg")
    if delay is not None:
        if not math.isfinite(delay):
            raise ConfigError(f"--imu-delay-s: must be finite, got {delay!r}")
        out["imu_delay_s"] = float(delay)
    if lever is not None:
        if getattr(args, "extrinsics", None):
            raise ConfigError("--lever-arm and --extrinsics both give the antenna's lever arm; give one")
        out["lever_arm"] = parse_vector(lever, 3, "--lever-arm")
    elif getattr(args, "extrinsics", None):

        out["lever_arm"] = tuple(float(x) for x in read_t_bs(args.extrinsics)[:3, 3])
    return out


def refuse_navigator_options(args: Any, kind: str) -> None:
    """A :class:`ConfigError` when navigator options (:data:`NAVIGATOR_OPTIONS`) come with a reference
    kind other than positions, which does not use them."""

    given = [f"--{k.replace('_', '-')}" for k in NAVIGATOR_OPTIONS if getattr(args, k, None) is not None]
    if given and kind != PositionsSource.kind:
        raise ConfigError(f"{', '.join(given)}: the navigator's options for a positions-only --groundtruth (GNSS); "
                          f"not used with the {kind} reference kind")
