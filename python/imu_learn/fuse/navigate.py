"""Navigate a user's recording: IMU fused with real aiding, no ground truth at run time.

``imu-learn navigate --input REC --aiding FILE --aiding-kind {position,pose,relative-pose}`` runs
:func:`navigate`: it reads the recording's IMU only (the layouts of :mod:`imu_learn.data.formats`;
ground truth is never opened), the aiding file (:mod:`.aiding.tum`), the extrinsic (:mod:`imu_learn.data.formats.extrinsics`),
optionally refines the IMU with a checkpoint (:mod:`imu_learn.infer.refiner`), builds the first state
from the data (:mod:`.start`) and fuses with :func:`imu_learn.fuse.graph.fuse` under a loose prior.
It writes ``causal.tum`` and ``smoothed.tum`` (``t tx ty tz qx qy qz qw``, seconds, body = IMU
frame, at the graph's keyframes), ``plot.png`` and ``summary.json`` to the output folder; with GNSS
fixes also the tracks on the globe (:mod:`.geo`), with a bag the trajectories as Odometry bags
(:func:`write_outputs`). The aiding's format is found from its content (:mod:`.aiding.detect`); the
IMU noise is ``--imu-noise``, a device profile's (which also applies its floor), the recording's
sensor.yaml or the MEMS class default scaled to the aiding (:func:`imu_noise`, :mod:`.noise_fit`).

Frames. A camera trajectory (ORB-SLAM2 and the like) gives ``T_C0_Ck``: camera k in the first
camera's frame C0. With the camera-to-body extrinsic ``T_BS`` the body pose in that aiding world
A = C0 is ``T_A_Bk = T_C0_Ck T_BS^-1``, and the body motion between two frames
``T_Bi_Bj = T_A_Bi^-1 T_A_Bj`` (the same as ``T_BS T_Ci_Cj T_BS^-1``).

* ``relative-pose`` (recommended for visual odometry / SLAM): a ``BetweenFactorPose3`` between the
  body poses of consecutive aiding rows. Relative motions do not depend on the aiding's world
  frame, so its non-gravity-aligned first-camera frame needs no handling at all; roll and pitch
  come from gravity through the IMU, heading and position are the prior's gauge (fixed by the
  first pose). Rows further apart than ``max_relative_gap_s`` are not chained: a visual system
  that lost track reports no motion across the gap, and the IMU alone carries it. Aiding without
  such breaks is also tied to its own world, one free state of the graph, weighted by its noise
  estimated against the IMU (:mod:`.aiding.spans`, :mod:`.aiding.estimate`); the aiding's time
  offset is estimated first.
* ``pose``: a prior factor on each aided body pose in the navigation frame W. A is rotated into W by
  ``R_WA``, estimated once at the start from the levelled attitude (:func:`.start.level.level_aiding`):
  its tilt error (the accelerometer bias over g, ~0.1-0.5 deg) then stays in every absolute pose
  and pulls against gravity, and a SLAM map's attitude errs slowly (a degree or so, not white); the
  absolute poses' rotation sigma is loose for that reason (``pose_sigma_rot_deg``, 10 deg: at 1 deg
  the poses together held the IMU's tilt to those errors and each coast through a camera gap started
  from them). Estimating ``R_WA`` inside the graph would remove the first error but is not done here.
* ``position``: position fixes in their own world frame, taken as gravity-aligned (z up): a
  TUM/CSV/ASL file of positions (one sigma, ``position_sigma_m``), or an RTKLIB ``.pos`` file
  (:mod:`imu_learn.fuse.aiding.rtklib`: local ENU at its first epoch, each fix with its own sigmas, float
  solutions down-weighted). The extrinsic's translation, when given, is the antenna's lever arm.
  Roll and pitch are levelled at the IMU's start; the heading comes from the track once moving
  faster than 1 m/s (:func:`.start.track.track_start`: the body x-axis along the velocity, as GNSS/INS
  filters for cars do), where fusion starts.

Scoring (``groundtruth``, optional, only for the report; checked before fusion by :func:`check_inputs`,
used only after it): ground truth
interpolated at the estimate's stamps; absolute aiding that shares the ground truth's world
(``position``): RMSE without alignment; relative and camera-frame aiding: after a rigid SE(3)
(Umeyama, no scale) alignment, as ``evo_ape -a``. The visual-only trajectory (the aiding's own body
positions) is scored the same way beside it.
"""
from __future__ import annotations

import logging
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Dict, Optional, Tuple

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from imu_learn.calib import correction
from imu_learn.calib.metric_scale import ScaleFit
from imu_learn.calib.plausible import LIMITS
from imu_learn.calib.profile import Profile
from imu_learn.calib.reference import applied_extrinsic
from imu_learn.core.stamps import sample_rate_hz
from imu_learn.core.still import MEMS_PRIOR, MIN_STILL_START_S, BiasPrior
from imu_learn.data import formats
from imu_learn.data.formats import CsvColumns, rosbag
from imu_learn.data.formats.asl import imu_sensor_yaml
from imu_learn.data.formats.extrinsics import inverse, read_t_bs
from imu_learn.data.formats.gnss_imu import mounting_rotation
from imu_learn.errors import AidingError, ColumnCountError, ConfigError, InvalidInputError
from imu_learn.infer.bias import bias_entry, bias_step
from imu_learn.infer.bias import choices as bias_choices
from imu_learn.util import interrupts
from imu_learn.util.staging import staged_dir

from . import geo
from .aiding import OutageWindow, snap_to_samples
from .aiding import bag as bag_aiding
from .aiding.detect import FORMATS as DETECTED_FORMATS
from .aiding.detect import detect as detect_aiding
from .aiding.estimate import one_line_text, shift_trajectory, with_noise
from .aiding.frame import FrameCheck, check_frame, turned_onto_gyro
from .aiding.kinds import GEODETIC_KIND, AidingKind, kind_of
from .aiding.kinds import KINDS as AIDING_KINDS
from .aiding.outages import in_windows
from .aiding.rtklib import FLOAT_GAIN, RtkSolution, fixes_on_imu, normal_gravity, read_pos
from .aiding.spans import SPANS_S
from .aiding.tum import Trajectory, check_overlap, read_trajectory
from .aiding.types import AidingRows, GnssFixes
from .factors import chain
from .factors.nhc import NhcSettings, nhc_callback
from .factors.velocity import velocity_callback, velocity_lag
from .graph import IncrementalFusion, feed, samples_of
from .inputs import checkpoint_bias, displacement_hook, displacement_model
from .mounting import mounting_check
from .noise import ImuNoise, from_profile
from .noise_fit import CLASS_WHITE, FACTOR_BOUNDS, NoiseFit, fit_noise, fit_scale, fitted_noise, prepare
from .output import plot_navigation, write_json, write_trajectory, write_trajectory_bag
from .score import convergence, read_truth, score_against, score_against_fixes
from .settings import FusionSettings, PriorSigmas
from .start import Start
from .start.delay import DelayEstimate, imu_delay
from .start.gravity import GravityCheck, check_gravity
from .start.level import start_rest
from .start.prior import profile_bias_sigmas
from .start.track import rest_from_track

log = logging.getLogger(__name__)

KINDS = tuple(AIDING_KINDS)  # position, pose, relative-pose (:mod:`.aiding.kinds`)
AIDING_FORMATS = ("auto",) + DETECTED_FORMATS  # auto: by content (:mod:`.aiding.detect`)
GEODETIC_FORMATS = ("rtklib",)  # and a bag's NavSatFix topic
PROGRESS_DELAY_S = 3.0  # the progress bar shows on runs longer than this


@dataclass(frozen=True)
class NavigateOptions:
    """How :func:`navigate` reads and weighs the aiding (defaults: a stereo visual SLAM at 20 Hz)."""

    aiding_kind: str = "relative-pose"
    aiding_format: str = "tum"  # or auto: by the file's content (:func:`resolve_aiding`)
    keyframe_hz: float = 10.0
    gravity: float = 9.81
    # relative-pose factors between consecutive rows. ORB-SLAM2 stereo on EuRoC, frame to frame (50 ms)
    # against ground truth: median 3-5 mm and 0.04-0.08 deg (RMS 5-9 mm, 0.06-0.16 deg; docs/navigate.md).
    # Its errors are correlated (drift, not white), so sigmas at the median fuse best (measured on
    # MH_04 and V1_01 trial0: 0.003 m / 0.05 deg beat 0.005 / 0.1 and 0.01 / 0.1).
    rel_sigma_rot_deg: float = 0.05
    rel_sigma_trans_m: float = 0.003
    max_relative_gap_s: float = 0.5
    # relative poses tie each row to rows these spans [s] before it (0: the row before; :mod:`.aiding.spans`)
    relative_spans_s: Tuple[float, ...] = SPANS_S
    # unbroken relative-pose aiding: each row also tied to the aiding's own world, one free state (:mod:`.aiding.spans`)
    relative_world: bool = True
    # poses whose body frame the rates put clearly off the IMU's (after any extrinsic) turned onto it
    # (:func:`.aiding.frame.turned_onto_gyro`); False: fused in the frame given
    turn_aiding_frame: bool = True
    # absolute poses (in the aiding's world, rotated into W)
    # 10 deg: the rotations are in a world levelled once and carry the map's slow attitude error; at 1 deg
    # ~2000 poses pinned the IMU's tilt to them (EuRoC, ORB-SLAM2: gap ends 2x, docs/experiments/navigate-vo.md)
    pose_sigma_rot_deg: float = 10.0
    pose_sigma_m: float = 0.02
    position_sigma_m: float = 0.05
    # pose aiding: multiply its positions by this (a monocular VO's scale; None: as read, checked metric)
    aiding_scale: Optional[float] = None
    # the first state's prior (loose: it comes from the data, not ground truth)
    prior_rot_deg: float = 3.0
    prior_pos_m: float = 0.1
    prior_vel_mps: float = 0.5
    level_s: float = 2.0
    gaps: Tuple[OutageWindow, ...] = ()  # seconds from the first IMU sample: aiding dropped
    aiding_hz: Optional[float] = None  # thin the aiding to at most this rate (None: every row)
    lag_s: Optional[float] = None  # the causal fixed-lag window (None: the graph's default)
    # the IMU as mounted: roll, pitch, yaw [deg] of the body frame relative to the IMU frame
    # (:func:`imu_learn.data.formats.gnss_imu.mounting_rotation`; body = M imu), and a logging delay
    # [s] added to every IMU stamp (rtklibexplorer's imu_t_off: -0.125 s on its drive)
    imu_rotation_rpy_deg: Optional[Tuple[float, float, float]] = None
    imu_delay_s: float = 0.0
    # "fixes" (--imu-delay-s auto): the delay measured from the data against GNSS fixes
    # (:func:`.start.delay.imu_delay`, outside ``gaps``) in place of imu_delay_s; "profile": imu_delay_s is
    # a profile's (calibrate's reference.navigator), "option": the option's; "unset" (none given): with GNSS
    # fixes measured as "fixes" is and applied where it clearly fits better than none (:func:`unset_delay`), else 0
    imu_delay_from: str = "unset"
    # position aiding: the antenna from the IMU, body frame [m] (instead of an extrinsic's translation)
    lever_arm: Optional[Tuple[float, float, float]] = None
    # the non-holonomic constraint of a wheeled vehicle (:mod:`.factors.nhc`): no sideways / vertical body velocity
    nhc: bool = False
    nhc_sigma_lat_mps: float = 0.1
    nhc_sigma_vert_mps: float = 0.1
    # GNSS fixes: each epoch's velocity (an RTKLIB .pos's vn, ve, vu) as a factor too, this sigma [m/s] for a
    # fixed epoch (x2 for a float one, as its position), at the instant its lag behind the positions puts it
    # (:func:`.factors.velocity.velocity_lag`, measured from the file outside the gaps); 0: positions only
    gnss_velocity_sigma_mps: float = 0.05
    # white noise / random walk of the IMU (gyro_nd, acc_nd, gyro_rw, acc_rw) instead of the built-in
    imu_noise: Optional[Tuple[float, float, float, float]] = None
    # multiply a covariance head's per-sample gyro and acc variances (the `learned` input) by these:
    # the head's variances calibrated over the keyframe interval (:mod:`.variance`; docs/navigate.md)
    variance_scale: Optional[Tuple[float, float]] = None
    # the recording's own gyro bias, estimated on the IMU as fused and subtracted before the fusion:
    # none or a name of the registry (:mod:`imu_learn.infer.bias`: auto, still, gravity, still+gravity)
    bias: str = "none"

    def check(self) -> None:
        if self.aiding_kind not in KINDS:
            raise ConfigError(f"--aiding-kind: one of {', '.join(KINDS)}, got {self.aiding_kind!r}")
        if self.bias not in bias_choices(navigate=True):
            raise ConfigError(f"--bias: one of {', '.join(bias_choices(navigate=True))}, got {self.bias!r}")
        if self.aiding_format not in AIDING_FORMATS:
            raise ConfigError(f"--aiding-format: one of {', '.join(AIDING_FORMATS)}, got {self.aiding_format!r}")
        for name in ("keyframe_hz", "rel_sigma_rot_deg", "rel_sigma_trans_m", "max_relative_gap_s",
                     "pose_sigma_rot_deg", "pose_sigma_m", "position_sigma_m", "prior_rot_deg", "prior_pos_m",
                     "prior_vel_mps", "level_s", "nhc_sigma_lat_mps", "nhc_sigma_vert_mps"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: must be a positive number, got {v!r}")
        if self.aiding_scale is not None and not (np.isfinite(self.aiding_scale) and self.aiding_scale > 0):
            raise ConfigError(f"--aiding-scale: must be a positive number, got {self.aiding_scale!r}")
        if self.aiding_scale is not None and not kind_of(self.aiding_kind).poses:
            raise ConfigError("--aiding-scale scales poses: only with --aiding-kind pose or relative-pose")
        if self.aiding_hz is not None and not self.aiding_hz > 0:
            raise ConfigError(f"--aiding-hz: must be > 0, got {self.aiding_hz!r}")
        for start, dur in self.gaps:
            if not (np.isfinite(start) and np.isfinite(dur) and dur > 0):
                raise ConfigError(f"--gaps: each START:DURATION with DURATION > 0, got {start}:{dur}")
        for name, n in (("imu_rotation_rpy_deg", 3), ("lever_arm", 3), ("imu_noise", 4)):
            v = getattr(self, name)
            if v is not None and (len(v) != n or not np.all(np.isfinite(np.asarray(v, dtype=np.float64)))):
                raise ConfigError(f"--{name.replace('_', '-')}: {n} finite numbers, got {v!r}")
        if self.variance_scale is not None and (
                len(self.variance_scale) != 2
                or not all(np.isfinite(x) and x > 0 for x in np.asarray(self.variance_scale, dtype=np.float64))):
            raise ConfigError(f"--variance-scale: two positive numbers G,A, got {self.variance_scale!r}")
        if self.imu_noise is not None and not all(x > 0 for x in self.imu_noise):
            raise ConfigError(f"--imu-noise: each density must be > 0, got {self.imu_noise!r}")
        if not np.isfinite(self.imu_delay_s):
            raise ConfigError(f"--imu-delay-s: must be finite, got {self.imu_delay_s!r}")
        if self.imu_delay_from not in ("unset", "option", "fixes", "profile"):
            raise ConfigError(f"imu_delay_from: 'unset', 'option', 'fixes' or 'profile', got {self.imu_delay_from!r}")
        if self.lever_arm is not None and not kind_of(self.aiding_kind).lever:
            raise ConfigError("--lever-arm is the antenna's: only with --aiding-kind position")
        if self.aiding_format == "rtklib" and not kind_of(self.aiding_kind).geodetic:
            raise ConfigError(f"--aiding-format rtklib holds positions: use it with --aiding-kind {GEODETIC_KIND}")


def parse_vector(text: str, n: int, option: str) -> Tuple[float, ...]:
    """``"180,-6.79,185.35"`` -> (180.0, -6.79, 185.35): exactly ``n`` comma-separated numbers."""
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        v = ()
    if len(v) != n or not all(np.isfinite(v)):
        raise ConfigError(f"{option}: expected {n} comma-separated finite numbers, got {text!r}")
    return v


def parse_gaps(text: str) -> Tuple[OutageWindow, ...]:
    """``"30:10,60:10"`` -> ((30.0, 10.0), (60.0, 10.0)): START:DURATION seconds from the first IMU sample."""
    out = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        a, sep, b = part.partition(":")
        try:
            if not sep:
                raise ValueError
            w = OutageWindow(float(a), float(b))
        except ValueError:
            raise ConfigError(f"--gaps: {part!r} is not START:DURATION (seconds)") from None
        if not (math.isfinite(w[0]) and math.isfinite(w[1])) or w[0] < 0 or w[1] <= 0:
            raise ConfigError(f"--gaps: {part!r}: START must be at least 0 and DURATION above 0 (seconds from the first "
                              "IMU sample)")
        out.append(w)
    ordered = sorted(out)
    for (a0, d0), (a1, _) in zip(ordered, ordered[1:]):
        if a1 < a0 + d0:
            log.warning(f"--gaps: {a0:g}:{d0:g} and {a1:g}:... overlap: one gap from {a0:g} s")
    return tuple(out)


# --------------------------------------------------------------------------------------------
# Poses and their frames
# --------------------------------------------------------------------------------------------


def body_poses(traj: Trajectory, T_BS: Optional[np.ndarray]) -> Tuple[np.ndarray, np.ndarray]:
    """(R_A_B (N, 3, 3), p_A_B (N, 3)): the aiding's sensor poses moved to the body (IMU) frame,
    ``T_A_B = T_A_S T_BS^-1`` (module docstring); the poses unchanged without an extrinsic."""
    R = Rotation.from_quat(traj.q_xyzw).as_matrix()
    p = traj.p
    if T_BS is None:
        return R, p.copy()
    T_SB = inverse(T_BS)
    return R @ T_SB[:3, :3], p + R @ T_SB[:3, 3]


# pose aiding faster than this: one line suggesting --aiding-hz (:func:`dense_aiding_note`)
DENSE_AIDING_HZ = 50.0


def thin(t_ns: np.ndarray, rate_hz: Optional[float]) -> np.ndarray:
    """Mask keeping the first row of each 1/rate_hz bin (all rows when rate_hz is None)."""
    if rate_hz is None:
        return np.ones(len(t_ns), dtype=bool)
    bins = (t_ns - t_ns[0]) // int(round(1e9 / rate_hz))
    keep = np.zeros(len(t_ns), dtype=bool)
    keep[np.unique(bins, return_index=True)[1]] = True
    return keep


def dense_aiding_note(t_ns: np.ndarray, path: str, opts: NavigateOptions) -> Optional[float]:
    """One line where pose aiding comes faster than :data:`DENSE_AIDING_HZ` and ``--aiding-hz`` was not
    given: every row is a keyframe, and the causal solver's window then holds hundreds of them at a time
    (TUM-VI room 3's 120 Hz motion capture: 175 s for its 141 s; at 20 Hz 10 s; docs/navigate.md). Returns
    the rate [Hz] it found (None: under it, thinned already, or fewer than two rows)."""
    if opts.aiding_hz is not None or len(t_ns) < 2 or not kind_of(opts.aiding_kind).poses:
        return None
    rate = sample_rate_hz(t_ns)  # the package's one rate rule (median period): a capture's dropouts do not lower it
    if rate <= DENSE_AIDING_HZ:
        return None
    log.info("%s: pose aiding at %.0f Hz, every row a keyframe: fusion may take longer than the recording; "
             "--aiding-hz 20 thins it (docs/navigate.md, \"Dense aiding\")", Path(path).name, rate)
    return rate


def select_rows(traj: Trajectory, imu_t_ns: np.ndarray, T_BS: Optional[np.ndarray], opts: NavigateOptions) -> AidingRows:
    """The aiding rows tied to IMU samples (:func:`imu_learn.fuse.aiding.snap_to_samples`), thinned
    and without the rows inside ``opts.gaps``."""
    check_overlap(traj, imu_t_ns)
    nearest, inside, close = snap_to_samples(imu_t_ns, traj.t_ns)
    keep = inside & close
    dropped = {"outside_imu": int((~inside).sum()), "no_imu_sample": int((inside & ~close).sum())}
    # one row per IMU sample (the first)
    seen = np.zeros(len(keep), dtype=bool)
    _, first = np.unique(np.where(keep, nearest, -1), return_index=True)
    seen[first] = True
    shared = keep & ~seen
    dropped["shared_sample"] = int(shared.sum())
    keep &= seen
    rel_s = (traj.t_ns - int(imu_t_ns[0])) * 1e-9
    in_gap = keep & in_windows(rel_s, opts.gaps)
    dropped["in_gaps"] = int(in_gap.sum())
    keep &= ~in_gap
    idx = np.flatnonzero(keep)
    th = thin(traj.t_ns[idx], opts.aiding_hz)
    dropped["thinned"] = int((~th).sum())
    idx = idx[th]
    dense_aiding_note(traj.t_ns[idx], traj.path, opts)
    if len(idx) < 2:
        raise AidingError(f"{traj.path}: {len(idx)} aiding row(s) left inside the IMU's span (dropped: "
                          f"{', '.join(f'{v} {k}' for k, v in dropped.items() if v)}); at least 2 needed",
                          traj.path, opts.aiding_kind)
    if traj.q_xyzw is not None and kind_of(opts.aiding_kind).poses:
        R, p = body_poses(traj, T_BS)
        R = R[idx]
        p = p[idx]
    else:
        R, p = None, traj.p[idx].copy()
    sample = nearest[idx].astype(np.int64)
    return AidingRows(sample, traj.t_ns[idx], np.asarray(imu_t_ns, dtype=np.int64)[sample], p, R, dropped)


# --------------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ImuRecording:
    """A recording's IMU as :func:`read_imu` read it: stamps, samples (read-only: a run that holds it
    again may not change it), the recording's own noise (its sensor.yaml) or None, the source file and
    its layout."""

    t_ns: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray
    noise: Optional[ImuNoise]
    file: str
    fmt: str


def read_imu(path: Path, fmt: str = "auto", columns: Optional[CsvColumns] = None) -> ImuRecording:
    """The IMU of a recording, or of a user's CSV (``columns``): the IMU only (no ground truth is read)."""
    src = formats.read_imu_source(Path(path), fmt, columns=columns)
    if src.t_ns is None:
        raise InvalidInputError(f"{path}: the recording has no IMU stamps of its own; navigation needs them")
    yaml = imu_sensor_yaml(src.root) if src.fmt == "asl" else None
    noise = ImuNoise.from_sensor_yaml(yaml) if yaml is not None else None
    arrays = [np.asarray(src.t_ns, dtype=np.int64), np.asarray(src.gyro), np.asarray(src.acc)]
    for a in arrays:
        a.setflags(write=False)
    return ImuRecording(*arrays, noise, str(src.imu_file), src.fmt)


def read_aiding(src: Sources, opts: NavigateOptions) -> Trajectory:
    """The aiding file (or bag topic) as a :class:`Trajectory` (poses, or positions for ``position``;
    geodetic fixes: see :func:`gnss_rows`), its positions times ``--aiding-scale`` where given."""
    need = kind_of(opts.aiding_kind).poses
    if opts.aiding_format == "bag":
        traj = bag_aiding.read_trajectory(Path(src.aiding), str(src.aiding_topic), need_orientation=need)
    else:
        traj = read_trajectory(src.aiding, opts.aiding_format, need_orientation=need)
    return traj if opts.aiding_scale is None else replace(traj, p=traj.p * float(opts.aiding_scale))


def read_geodetic(src: Sources, opts: NavigateOptions) -> RtkSolution:
    """Geodetic fixes in local ENU at their first epoch: an RTKLIB ``.pos`` file or a bag's NavSatFix topic
    (read once, by :func:`read_inputs`: the delay, the noise fit and the rows all take that solution)."""
    if opts.aiding_format == "bag":
        return bag_aiding.read_navsat(Path(src.aiding), str(src.aiding_topic), opts.position_sigma_m)
    return read_pos(Path(src.aiding))


def gnss_rows(src: Sources, sol: RtkSolution, imu_t_ns: np.ndarray, lever: np.ndarray, opts: NavigateOptions):
    """(GnssFixes on the IMU's samples with their own per-fix sigmas, AidingRows) of the geodetic fixes
    ``sol`` (:func:`read_geodetic`; RTKLIB: fixed and float solutions, float down-weighted), without the
    fixes inside ``opts.gaps``."""
    path = src.aiding
    fixes = fixes_on_imu(sol, imu_t_ns, lever, label=None if opts.aiding_format != "bag" else aiding_label(src, opts))
    rel_s = (imu_t_ns[fixes.idx] - int(imu_t_ns[0])) * 1e-9
    in_gap = in_windows(rel_s, opts.gaps)
    fixes = fixes.select(~in_gap, dropped_outage=int(in_gap.sum()))
    th = thin(np.asarray(imu_t_ns, dtype=np.int64)[fixes.idx], opts.aiding_hz)  # --aiding-hz thins fixes too
    fixes = fixes.select(th)
    if len(fixes) < 2:
        why = (f" ({int(in_gap.sum())} withheld by --gaps {','.join(f'{a:g}:{d:g}' for a, d in opts.gaps)}: leave some "
               "fixes outside the gaps)" if in_gap.any() else "")
        raise AidingError(f"{path}: {len(fixes)} usable fix(es) inside the IMU's span{why}", str(path), GEODETIC_KIND)
    dropped = {"outside_imu": fixes.dropped_outside, "no_imu_sample": fixes.dropped_unmatched,
               "in_gaps": int(in_gap.sum()), "thinned": int((~th).sum()),
               "quality_not_used": int(len(sol) - len(fixes) - int(in_gap.sum()) - int((~th).sum())
                                       - fixes.dropped_outside - fixes.dropped_unmatched)}
    t = np.asarray(imu_t_ns, dtype=np.int64)[fixes.idx]
    return fixes, AidingRows(fixes.idx.astype(np.int64), t, t, fixes.p.copy(), None, dropped)


@dataclass(frozen=True)
class Sources:
    """The files :func:`navigate` reads: the recording ``input`` (its IMU only, layout ``fmt``), the
    ``aiding`` file, and optionally the aiding sensor's ``extrinsics``, a ``checkpoint`` refining the
    IMU (or a ``calibration`` fit of ``imu-learn evaluate``), a ``displacement`` model, and a
    ``groundtruth`` file to score the result with afterwards; ``profile``, a device profile giving
    the IMU noise and, without a checkpoint or calibration, its floor."""

    input: Path
    aiding: Path
    fmt: str = "auto"
    aiding_topic: Optional[str] = None  # the aiding's topic when ``aiding`` is a ROS bag
    columns: Optional[CsvColumns] = None  # ``input`` is a user's CSV of this layout
    profile: Optional[Path] = None  # a device profile (imu-learn calibrate): noise and floor
    extrinsics: Optional[Path] = None
    checkpoint: Optional[Path] = None
    groundtruth: Optional[Path] = None
    displacement: Optional[Path] = None
    calibration: Optional[Path] = None
    force: bool = False  # apply a profile or model made for another rate (a warning), as refine --force
    imu_name: Optional[str] = None  # the recording's device, checked against the profile's or model's
    recording: Optional[ImuRecording] = None  # ``input``'s IMU already read (:func:`read_imu`); None: read here


@dataclass
class Imu:
    """The recording's IMU as the navigator fuses it: stamps (delay applied), samples rotated into the
    body frame by ``mounting`` (None: as read), the noise model, and the file they came from."""

    t_ns: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray
    noise: Optional[ImuNoise]  # None while it waits for the checked aiding rows (:func:`moving_imu`)
    file: str
    mounting: Optional[np.ndarray] = None
    floor: Optional[str] = None  # the profile whose floor was applied (sensor frame, before the mounting)
    var: Optional[np.ndarray] = None  # a covariance head's per-sample variances (body frame), None: none
    label: str = "raw"  # what the samples are (the summary's imu_input)
    correction: Dict[str, object] = field(default_factory=dict)  # the correction plan's summary
    delay: Dict[str, object] = field(default_factory=dict)  # the delay added to the stamps and where it came from
    mounting_check: Dict[str, object] = field(default_factory=dict)  # :func:`check_mounting`'s verdict


def imu_noise(src: Sources, opts: NavigateOptions, own: Optional[ImuNoise], profile: Optional[Profile],
              imu: Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]] = None,
              sol: Optional[RtkSolution] = None) -> Optional[ImuNoise]:
    """The noise the graph assumes: ``--imu-noise``, else the profile's (its white noise raised to the moving
    IMU's, :func:`in_motion`: with GNSS fixes ``sol`` here, and to the rest's, :func:`at_rest_floor`; with pose
    aiding once the rows are read, :func:`moving_imu`), else the recording's
    sensor.yaml, else with ``imu`` (its stamps, gyro, acc as fused: corrected, in the body frame, the
    stamps delayed) the MEMS class default scaled to
    the aiding's innovations (:mod:`.noise_fit`): here for the geodetic fixes ``sol``; None for poses and
    positions of a trajectory file, whose fit waits for their rows read and checked (:func:`moving_imu`: a
    file in another frame or unit is refused before any fit); else the built-in device's (one warning line
    each)."""
    if opts.imu_noise is not None:
        return ImuNoise(*opts.imu_noise, source="--imu-noise")
    # GNSS: the fixes as the run fuses them, read once for the innovations' fit and the track's rest
    rows = gnss_rows(src, sol, imu[0], np.zeros(3), opts)[1] if sol is not None and imu is not None else None
    # a profile that measured no noise (no reference and no still stretch) gives none: the recording's own below
    kalibr = profile.kalibr() if profile is not None else {}
    blank = profile is not None and all(v is None for v in kalibr.values())
    if profile is not None and not blank:
        noise = from_profile(kalibr, str(src.profile), [k for k in kalibr if profile.unobserved_noise(k)])
        # GNSS: the profile's white noise (at rest) raised to the moving IMU's as pose aiding's is (:func:`moving_imu`),
        # then axis by axis to this recording's rest as without a profile (:func:`at_rest_floor`: the car's idling
        # engine, which a profile made on another recording never saw); pose aiding's rows are read (and their frame
        # checked) later
        if rows is None:
            return noise
        moving = in_motion(noise, innovation_fit(opts, imu, sol, rows))
        return at_rest_floor(moving, imu, rest_from_track(imu[0], rows.sample, rows.p), opts.gravity)
    if own is not None:
        return own
    if imu is not None and rows is None:  # pose or position aiding: fitted once its rows are read and checked
        return None
    if imu is not None:
        rest = rest_from_track(imu[0], rows.sample, rows.p)
        return fitted_at_rest(src, opts, innovation_fit(opts, imu, sol, rows), imu, rest)
    noise = ImuNoise()
    log.warning(f"no --profile or --imu-noise: the IMU noise is the built-in EuRoC ADIS16448's (gyro "
                f"{noise.gyro_noise_density:g} rad/s/sqrt(Hz), acc {noise.acc_noise_density:g} m/s^2/sqrt(Hz)); "
                "imu-learn calibrate writes your device's noise (docs/your-device.md)")
    return noise


def at_rest_floor(noise: ImuNoise, imu: Tuple[np.ndarray, np.ndarray, np.ndarray],
                  rest: Optional[Tuple[int, int, str]], gravity: float) -> ImuNoise:
    """``noise`` (fitted from the innovations) with each sensor's white noise raised, axis by axis, to what the
    IMU shows at rest where that is higher: the per-sample spread of each body axis over the rest at the start
    (:func:`.start.level.start_rest`: the IMU's still start, else ``rest``, the one the GNSS track shows) times
    sqrt(dt). The innovations' one factor on the class default splits the noise between the sensors by the
    class's ratio; a car parked with its engine running shows its own, on one axis most (the drive: gyro 1.1e-3,
    4.0e-3, 1.6e-4 rad/s/sqrt(Hz) at rest against the fit's 1.2e-3; docs/experiments/fusion_gnss.md, "Where the
    gaps fall"). The densities (the summary's figure) are the axes' RMS where above the fit; the graph takes
    the axes (:attr:`ImuNoise.gyro_axes`)."""
    t_ns, gyro, acc = imu
    span = start_rest(t_ns, gyro, acc, gravity, rest, MIN_STILL_START_S)
    if span is None:
        return noise
    first, end, kind, seconds = span
    where = f"the IMU's still start ({seconds:.2f} s)" if kind == "still" else \
        f"the rest the GNSS track shows ({seconds:.2f} s)"
    dt = float(np.median(np.diff(t_ns[first:end]))) * 1e-9
    g, a = (np.sqrt(np.var(x[first:end], axis=0) * dt) for x in (gyro, acc))
    fit = (noise.gyro_noise_density, noise.acc_noise_density)
    if np.all(g <= fit[0]) and np.all(a <= fit[1]):
        return noise
    g_axes, a_axes = (tuple(float(v) for v in np.maximum(x, f)) for x, f in ((g, fit[0]), (a, fit[1])))
    raised = replace(noise, gyro_noise_density=max(float(np.sqrt(np.mean(g ** 2))), fit[0]),
                     acc_noise_density=max(float(np.sqrt(np.mean(a ** 2))), fit[1]), gyro_axes=g_axes, acc_axes=a_axes)
    axes = "; ".join(f"{name} ({', '.join(f'{v:.3g}' for v in x)}) {unit}" for name, x, unit in
                     (("gyro", g_axes, "rad/s/sqrt(Hz)"), ("acc", a_axes, "m/s^2/sqrt(Hz)")))
    return replace(raised, source=f"{noise.source}; white noise raised to what the IMU shows at rest over {where}, "
                                  f"axis by axis: {axes} (RMS gyro {raised.gyro_noise_density:.3g}, acc "
                                  f"{raised.acc_noise_density:.3g}; the fit's {fit[0]:.3g}, {fit[1]:.3g})")


def fitted_at_rest(src: Sources, opts: NavigateOptions, fit: NoiseFit,
                   imu: Tuple[np.ndarray, np.ndarray, np.ndarray], rest: Optional[Tuple[int, int, str]]) -> ImuNoise:
    """No noise given (no --imu-noise, sensor.yaml, or a profile that measured some): the class default scaled
    by the aiding's innovations ``fit``, its white noise raised to the IMU's at rest (:func:`at_rest_floor`);
    one warning line saying so."""
    noise = at_rest_floor(fitted_noise(fit), imu, rest, opts.gravity)
    why = (f"the profile {src.profile} measured no noise (no reference, no still stretch)" if src.profile is not None
           else "no --profile, --imu-noise or sensor.yaml")
    log.warning(f"{why}: the IMU noise is {noise.source}; "
                "imu-learn calibrate writes your device's noise (docs/your-device.md)")
    return noise


def innovation_fit(opts: NavigateOptions, imu: Tuple[np.ndarray, np.ndarray, np.ndarray], sol: RtkSolution,
                   rows: AidingRows) -> NoiseFit:
    """The IMU's white noise fitted from the GNSS fixes' innovations (:mod:`.noise_fit`) on ``imu`` (stamps,
    gyro, acc as fused); ``rows``: the fixes ``sol`` as the run fuses them (:func:`gnss_rows`)."""
    t_ns, gyro, acc = imu
    return fit_noise(t_ns, gyro, acc, rows.t_ns, rows.p, rows.R, normal_gravity(sol.origin_llh[0], sol.origin_llh[2]),
                     opts.max_relative_gap_s)


def moving_imu(src: Sources, opts: NavigateOptions, imu: Imu, rows: AidingRows) -> Imu:
    """Pose aiding, once its rows are read and their frame checked: the aiding's innovations against the
    IMU (:mod:`.noise_fit`, on those rows) refuse positions that are not metric (:func:`.noise_fit.fit_scale`
    off 1: a monocular VO, mm or cm; the fix names ``--aiding-scale``) or do not follow the accelerometer
    (a noise fit beyond :data:`.noise_fit.FACTOR_BOUNDS`' upper end: no IMU is that noisy), and raise a
    profile's white noise to the moving IMU's (:func:`in_motion`). With no noise given (``imu.noise`` None:
    :func:`imu_noise` leaves it to the checked rows) the class default scaled by these innovations
    (:func:`fitted_at_rest`), for position rows too."""
    poses = kind_of(opts.aiding_kind).poses
    if not poses and imu.noise is not None:
        return imu
    prep = prepare(imu.t_ns, imu.gyro, imu.acc, rows.t_ns, opts.max_relative_gap_s)
    if poses:
        rows.scale = fit_scale(rows.p, rows.R, prep)
        check_scale(src, opts, rows.scale)
    fit = fit_noise(imu.t_ns, imu.gyro, imu.acc, rows.t_ns, rows.p, rows.R, opts.gravity, opts.max_relative_gap_s,
                    prep=prep)
    if poses and fit.factor is not None and fit.factor > FACTOR_BOUNDS[1]:
        raise ConfigError(f"--aiding {src.aiding}: its positions do not follow the accelerometer (their changes of "
                          f"velocity need x{fit.factor:.3g} the MEMS class noise, at most x{FACTOR_BOUNDS[1]:g} fits "
                          "any IMU): positions in mm or cm, or a monocular VO without metric scale? give them in metres")
    if imu.noise is None:  # no noise given: the class default scaled by these innovations
        return replace(imu, noise=fitted_at_rest(src, opts, fit, (imu.t_ns, imu.gyro, imu.acc), None))
    if src.profile is None or opts.imu_noise is not None:  # the noise is not the profile's
        return imu
    return replace(imu, noise=in_motion(imu.noise, fit))


def check_scale(src: Sources, opts: NavigateOptions, fit: ScaleFit) -> None:
    """Refused (exit 2, before the fusion) where the poses' positions are observed off metric; the fix is
    the factor that makes them metric (``--aiding-scale``, times the one given); a warning where the data
    could not tell the scale (positions in other units would then pass unnamed)."""
    if not fit.observed:
        log.warning(f"--aiding {src.aiding}: its metric scale is not checked ({fit.reason}); make sure its positions "
                    "are in metres (summary.json: aiding_estimates.scale)")
    if not fit.off:
        return
    k, given = float(fit.scale), opts.aiding_scale or 1.0
    fix = given / k
    after = "" if opts.aiding_scale is None else f" after --aiding-scale {given:g}"
    raise ConfigError(f"--aiding {src.aiding}: its positions are x{k:.3g} (+-{float(fit.std):.2g}) the distances "
                      f"the accelerometer measures{after}: a monocular VO without metric scale, or positions in mm or "
                      f"cm? give them in metres, or pass --aiding-scale {fix:.4g}")


def in_motion(noise: ImuNoise, fit: NoiseFit) -> ImuNoise:
    """A profile's noise with its white noise raised to what the aiding's innovations (poses, GNSS fixes) say
    the moving IMU has (:func:`innovation_fit`: one factor on the MEMS class default's gyro and accelerometer white
    noise, as without a profile; a profile measures them at rest, where motors and roads are quiet, or against a
    motion capture that resolves the IMU's band (a reference that cannot, the profile's class default,
    :func:`imu_learn.calib.noise.candidates`): on EuRoC's flights the fit is 6-11x the ADIS16448 profile's), each
    sensor's where the fit is usable and
    higher; the random walks stay the profile's. The source says which (docs/experiments/navigate-vo.md,
    "The IMU's noise in motion")."""
    if not fit.used:
        return replace(noise, source=f"{noise.source}; no in-motion fit from the aiding's innovations ({fit.reason})")
    gyro, acc = (float(fit.factor) * w for w in CLASS_WHITE)
    if gyro <= noise.gyro_noise_density and acc <= noise.acc_noise_density:
        return replace(noise, source=f"{noise.source}; the aiding's innovations fit x{float(fit.factor):.3g} the class "
                                     "white noise, not above it: kept")
    raised = replace(noise, gyro_noise_density=max(gyro, noise.gyro_noise_density),
                     acc_noise_density=max(acc, noise.acc_noise_density))
    return replace(raised, source=f"{noise.source}; white noise (gyro {noise.gyro_noise_density:.3g}, acc "
                                  f"{noise.acc_noise_density:.3g}: the profile's) raised to gyro {raised.gyro_noise_density:.3g} "
                                  f"rad/s/sqrt(Hz), acc {raised.acc_noise_density:.3g} m/s^2/sqrt(Hz), fitted from the "
                                  f"aiding's innovations in motion (x{float(fit.factor):.3g} the class default, chi2/dof "
                                  f"{fit.chi2_ratio}, {fit.residuals} residuals)")


def load_profile(src: Sources) -> Optional[Profile]:
    """The device profile (its rate and device are checked with what is applied: :func:`read_body_imu`)."""
    return None if src.profile is None else Profile.load(src.profile)


def read_body_imu(src: Sources, opts: NavigateOptions, sol: Optional[RtkSolution] = None) -> Imu:
    """The recording's IMU through the correction plan (:mod:`imu_learn.calib.correction`, as refine
    applies it: the rate and device check, refused more than 5 % off unless ``src.force``, then the
    profile's floor when there is no checkpoint or calibration, else the model (after the profile it
    carries, once) or the fit, then the guard) in the IMU's own frame, then in the body frame
    (``--imu-rotation-rpy-deg``), its stamps moved by ``--imu-delay-s`` (``auto``: measured against the
    geodetic fixes ``sol``), with its noise (:func:`imu_noise`)."""
    read = src.recording if src.recording is not None else read_imu(src.input, src.fmt, src.columns)
    t_ns, gyro, acc, own, imu_file, fmt = read.t_ns, read.gyro, read.acc, read.noise, read.file, read.fmt
    profile = load_profile(src)
    if src.calibration is not None and src.checkpoint is not None:
        raise ConfigError("--calibration and --checkpoint both refine the IMU: pass one")
    refined = src.checkpoint is not None or src.calibration is not None
    floor = profile is not None and profile.has_floor and not refined
    if profile is not None and profile.has_floor and refined:
        log.info(f"{src.profile}: its noise only (the IMU is refined by --checkpoint / --calibration, not its floor)")
    plan = correction.build(correction.Request(
        profile=src.profile if floor else None, checkpoint=src.checkpoint, calibration=src.calibration,
        noise_profile=None if floor else src.profile, force=src.force, variance="if-head", command="imu-learn navigate"))
    label = input_label(src, opts, plan, floor)
    rec = correction.Recording(str(src.input), t_ns, gyro, acc, fmt, src.fmt, src.imu_name,
                               src.columns.gyro_unit if src.columns is not None else None)
    fixed = correction.correct(plan, rec, src.force)
    gyro, acc, var = fixed.gyro, fixed.acc, fixed.var
    acc_imu = acc
    mounting = None
    if opts.imu_rotation_rpy_deg is not None:
        mounting = mounting_rotation(opts.imu_rotation_rpy_deg)
        gyro, acc = np.ascontiguousarray(gyro @ mounting.T), np.ascontiguousarray(acc @ mounting.T)
        if var is not None:  # the diagonal of M diag(v) M^T: exact for an axis permutation or flip
            var = np.ascontiguousarray(np.hstack([var[:, :3] @ (mounting**2).T, var[:, 3:] @ (mounting**2).T]))
    delay = measured_delay(sol, opts, t_ns, acc) if opts.imu_delay_from == "fixes" else \
        unset_delay(sol, opts, t_ns, acc) if opts.imu_delay_from == "unset" and sol is not None and not opts.imu_delay_s \
        else profile_delay(sol, opts, t_ns, acc, src.profile) if opts.imu_delay_from == "profile" and sol is not None \
        else {"delay_s": opts.imu_delay_s, "from": ("the profile's reference.navigator" if opts.imu_delay_from == "profile"
                                                    else "--imu-delay-s" if opts.imu_delay_from == "option"
                                                    else "none (no --imu-delay-s)")}
    if delay["delay_s"]:
        t_ns = t_ns + int(round(float(delay["delay_s"]) * 1e9))
    check = check_mounting(t_ns, acc_imu, sol, mounting, opts, src.force)
    noise = imu_noise(src, opts, own, profile, (t_ns, gyro, acc), sol)  # after the checks: on the IMU as fused
    return Imu(t_ns, gyro, acc, noise, imu_file, mounting, str(src.profile) if floor else None, var, label,
               fixed.summary, delay, check)


def outside_gaps(sol: RtkSolution, t0_ns: int, gaps: Tuple[OutageWindow, ...]) -> np.ndarray:
    """The solution's epochs outside ``--gaps`` (windows in seconds from the IMU's first sample ``t0_ns``): the
    fixes the run fuses, the ones the delay, the velocities' lag and the mounting are measured on."""
    return ~in_windows((np.asarray(sol.t_ns, dtype=np.int64) - int(t0_ns)) * 1e-9, gaps)


def check_mounting(t_ns: np.ndarray, acc_imu: np.ndarray, sol: Optional[RtkSolution], mounting: Optional[np.ndarray],
                   opts: NavigateOptions, force: bool = False) -> Dict[str, object]:
    """With ``--nhc`` and GNSS fixes: the body's forward axis (``--imu-rotation-rpy-deg``, else the IMU's x)
    against the track's (:func:`.mounting.mounting_check`), refused beyond its tolerance (``force``: one warning);
    else not checked."""
    if not opts.nhc or sol is None:
        return {"checked": False, "why": "checked with --nhc and GNSS fixes only (the forward axis of a wheeled vehicle)"}
    keep = outside_gaps(sol, int(t_ns[0]), opts.gaps)  # the fixes the run fuses, none withheld
    check = mounting_check(t_ns, acc_imu, sol.t_ns[keep], sol.enu[keep], mounting,
                           normal_gravity(sol.origin_llh[0], sol.origin_llh[2]))
    if check.get("checked") and not check["ok"]:
        given = "--imu-rotation-rpy-deg" if mounting is not None else "no --imu-rotation-rpy-deg (the IMU's own x)"
        line = (f"the body's forward axis ({given}) is {check['angle_deg']:.0f} deg from the one the track shows "
                f"(roll, pitch, yaw {', '.join(f'{x:g}' for x in check['estimated_rpy_deg'])} estimated, a z-up "
                "body; roll + 180 for a z-down one): with --nhc a wrong mounting wrecks the track")
        if not force:  # the drive turned 90 deg: causal RMS 11.6 m against 0.54 m, exit 0 with this as a warning
            raise ConfigError(f"{line}; give --imu-rotation-rpy-deg as estimated, or --force to fuse as given")
        log.warning(f"{line}; fused as given (--force)")
    return check


def delay_estimate(sol: RtkSolution, opts: NavigateOptions, t_ns: np.ndarray, acc: np.ndarray) -> DelayEstimate:
    """The IMU's delay measured against the GNSS fixes ``sol`` outside ``--gaps`` (:func:`.start.delay.imu_delay`)."""
    return imu_delay(t_ns, acc, sol, normal_gravity(sol.origin_llh[0], sol.origin_llh[2]),
                     use=outside_gaps(sol, int(t_ns[0]), opts.gaps))


def measured_delay(sol: Optional[RtkSolution], opts: NavigateOptions, t_ns: np.ndarray,
                   acc: np.ndarray, est: Optional[DelayEstimate] = None) -> Dict[str, object]:
    """``--imu-delay-s auto``: the delay to add to the IMU's stamps, measured against the GNSS fixes
    ``sol`` (None: the aiding is not GNSS fixes, refused) outside ``--gaps`` (:func:`.start.delay.imu_delay`:
    the specific force's norm, no attitude needed)."""
    if sol is None:
        raise ConfigError("--imu-delay-s auto measures the delay against GNSS fixes (an RTKLIB .pos or a NavSatFix "
                          "topic); with this aiding give the delay in seconds")
    est = delay_estimate(sol, opts, t_ns, acc) if est is None else est
    if opts.imu_delay_from == "fixes":  # without the option :func:`unset_delay` says what it did with it
        log.info("IMU time offset from the fixes: %+.3f s (specific-force norm RMS %.3f m/s^2, %.3f at 0 s; %d epochs)",
                 est.delay_s, est.rms_mps2, est.rms_at_zero_mps2, est.epochs)
    return {"delay_s": round(est.delay_s, 4), "from": "fixes", "rms_mps2": round(est.rms_mps2, 4),
            "rms_at_zero_mps2": round(est.rms_at_zero_mps2, 4), "epochs": est.epochs}


# no --imu-delay-s with GNSS fixes: the measured delay is applied where its fit is at most this fraction of the
# fit at zero delay (the car drive: 0.285 against 0.404 m/s^2 at -0.20 s, applied; the walk: 0.407 against 0.413
# at -0.03 s, not: it moved its two outages' ends both ways, 5.30 -> 4.80 and 1.62 -> 1.80 m)
CLEAR_DELAY_FIT = 0.9


def unset_delay(sol: RtkSolution, opts: NavigateOptions, t_ns: np.ndarray, acc: np.ndarray,
                est: Optional[DelayEstimate] = None) -> Dict[str, object]:
    """No ``--imu-delay-s`` with GNSS fixes: the delay :func:`measured_delay` finds, applied where the data
    clearly support it (its fit at most :data:`CLEAR_DELAY_FIT` of the fit at zero; one warning line says so,
    a logger's delay left out costs the drive 116 m at its first outage's end), else none (the summary says
    why); none where it cannot be measured."""
    try:
        est = measured_delay(sol, opts, t_ns, acc, est)
    except InvalidInputError as e:
        return {"delay_s": 0.0, "from": f"none (no --imu-delay-s; not measured: {e})"}
    if est["rms_mps2"] <= CLEAR_DELAY_FIT * est["rms_at_zero_mps2"] and est["delay_s"]:
        log.warning(f"the IMU's stamps are {float(est['delay_s']):+.3f} s off the GNSS fixes' (measured: the specific "
                    f"force's norm fits the fixes' accelerations to {est['rms_mps2']:.3g} m/s^2 there, "
                    f"{est['rms_at_zero_mps2']:.3g} at 0): applied; --imu-delay-s 0 keeps the stamps as they are")
        return {**est, "from": "fixes (no --imu-delay-s: measured, clearly better than none)"}
    log.info(f"IMU time offset from the fixes: {float(est['delay_s']):+.3f} s measured, not applied: its fit "
             f"({est['rms_mps2']:.3g} m/s^2) is not clearly better than at 0 ({est['rms_at_zero_mps2']:.3g}); "
             "--imu-delay-s auto applies it")
    return {**est, "delay_s": 0.0, "measured_s": est["delay_s"],
            "from": f"none (no --imu-delay-s; the measured {float(est['delay_s']):+.3f} s fits not clearly better than "
                    f"0: {est['rms_mps2']:.3g} against {est['rms_at_zero_mps2']:.3g} m/s^2, more than "
                    f"{CLEAR_DELAY_FIT:g}x)"}


def profile_delay(sol: RtkSolution, opts: NavigateOptions, t_ns: np.ndarray, acc: np.ndarray,
                  profile: Optional[Path]) -> Dict[str, object]:
    """A profile's delay (calibrate's ``reference.navigator``: its own recording's) checked against this
    recording's GNSS fixes: kept where they fit it about as well as the delay they show; else left out with
    one warning line, and the delay decided as with none given (:func:`unset_delay`). A log's delay moves
    between recordings: the walk's profile, held at 0 s, on the car drive, whose fixes show -0.20 s clearly,
    took its outages' mean end from 8.5 to 14.6 m. Kept as it is where the fixes cannot measure one."""
    kept = {"delay_s": opts.imu_delay_s, "from": "the profile's reference.navigator"}
    try:
        est = delay_estimate(sol, opts, t_ns, acc)
    except InvalidInputError as e:
        return {**kept, "checked": f"not measured from the fixes: {e}"}
    at_profile = est.rms_at(float(opts.imu_delay_s))
    measured = {"measured_s": round(est.delay_s, 4), "rms_mps2": round(est.rms_mps2, 4)}
    if not math.isfinite(at_profile):
        return {**kept, **measured, "checked": f"not checked: outside the delays searched {est.grid_s[:2]} s"}
    if est.rms_mps2 > CLEAR_DELAY_FIT * at_profile:
        return {**kept, **measured, "rms_at_profile_mps2": round(at_profile, 4),
                "checked": "the fixes fit it about as well as the delay they show"}
    log.warning(f"{profile}'s IMU delay {float(opts.imu_delay_s):+.3f} s (reference.navigator: the recording it was "
                f"calibrated on) fits these GNSS fixes clearly worse ({at_profile:.3g} m/s^2) than the {est.delay_s:+.3f} s "
                f"they show ({est.rms_mps2:.3g}): left out, the delay decided as with none given; --imu-delay-s "
                f"{float(opts.imu_delay_s):g} keeps the profile's")
    decided = unset_delay(sol, opts, t_ns, acc, est)
    return {**decided, "profile_s": opts.imu_delay_s, "rms_at_profile_mps2": round(at_profile, 4),
            "from": f"{decided['from']}; the profile's {float(opts.imu_delay_s):+.3f} s fits the fixes clearly worse"}


MIN_AIDING_SPAN_S = 1.0  # the least aiding inside the IMU's span (the start's gravity from it needs 0.4 s)


def aiding_rows(src: Sources, opts: NavigateOptions, t_ns: np.ndarray, T_BS: Optional[np.ndarray],
                lever: np.ndarray, imu: Optional[Imu] = None,
                sol: Optional[RtkSolution] = None) -> Tuple[AidingRows, int, Optional[object], NavigateOptions]:
    """(the rows used, the rows read, (the GNSS fixes, their solution) of geodetic aiding or None, the
    options with the gravity of geodetic fixes). ``sol``: the geodetic fixes (:func:`read_geodetic`),
    None for other aiding. Poses with ``imu``: their time offset estimated and applied, and their noise
    estimated (:mod:`.aiding.estimate`)."""
    if sol is not None:
        gnss, rows = gnss_rows(src, sol, t_ns, lever, opts)
        # geodetic fixes: the normal gravity at their origin (9.797 m/s^2 on the drive, not 9.81)
        opts = replace(opts, gravity=round(normal_gravity(sol.origin_llh[0], sol.origin_llh[2]), 6))
        return rows, len(rows.sample) + sum(rows.dropped.values()), (gnss, sol), opts
    traj = read_aiding(src, opts)
    inside = (traj.t_ns >= t_ns[0]) & (traj.t_ns <= t_ns[-1])
    span_s = float(np.ptp(traj.t_ns[inside])) * 1e-9 if inside.sum() >= 2 else 0.0
    if inside.any() and span_s < MIN_AIDING_SPAN_S:  # the start needs gravity and motion from its first seconds
        raise ConfigError(f"--aiding {src.aiding}: {int(inside.sum())} row(s) over {span_s:.2f} s inside the IMU's span; "
                          f"at least {MIN_AIDING_SPAN_S:g} s of aiding is needed to start from")
    if imu is not None and not kind_of(opts.aiding_kind).poses:
        rows = select_rows(traj, t_ns, T_BS, opts)
        rows.gravity = checked_up(src, opts, rows, imu)
        return rows, len(traj), None, opts
    if imu is None or traj.q_xyzw is None or not kind_of(opts.aiding_kind).poses:
        return select_rows(traj, t_ns, T_BS, opts), len(traj), None, opts
    traj, offset = shift_trajectory(traj, imu.t_ns, imu.gyro)
    rows = select_rows(traj, t_ns, T_BS, opts)
    rows.offset = offset
    rows.frame = checked_frame(src, rows, imu, opts.max_relative_gap_s, from_profile=T_BS is not None,
                               turn=opts.turn_aiding_frame)
    if opts.turn_aiding_frame:
        rows = turned_onto_gyro(rows, rows.frame)  # where the check resolved the rotation (its line said so)
    return with_noise(rows, imu.t_ns, imu.gyro, imu.acc, opts.max_relative_gap_s), len(traj), None, opts


def checked_up(src: Sources, opts: NavigateOptions, rows: AidingRows, imu: Imu) -> GravityCheck:
    """Positions of a trajectory file against the accelerometer (:mod:`.start.gravity`), before any fusion:
    refused (exit 2) where their world is not z up; a warning line where it cannot be told."""
    check = check_gravity(imu.t_ns, imu.acc, rows.t_ns, rows.p, opts.gravity)
    if check.verdict == "refused" and check.scale != 1.0:
        raise ConfigError(f"--aiding {src.aiding}: {check.why}")
    if check.verdict == "refused":
        fix = ("poses of a VO or SLAM (a camera's first frame as their world)? give them as poses (navigate: "
               "--aiding-kind pose or relative-pose with --extrinsics; calibrate: the file with its quaternions), "
               "else turn the positions into a z-up world (ENU)")
        raise ConfigError(f"--aiding {src.aiding}: its positions' world is not z up: {check.why}: {fix}")
    if check.verdict == "not checked":
        log.warning("aiding positions' world not checked against gravity: %s; it must be z up", check.why)
    return check


def checked_frame(src: Sources, rows: AidingRows, imu: Imu, max_gap_s: float, from_profile: bool = False,
                  turn: bool = False) -> FrameCheck:
    """The aiding poses' body frame against the IMU's (:mod:`.aiding.frame`), before any fusion:
    refused (exit 2) when it is not the IMU's, naming ``--extrinsics`` (``from_profile``: after the rotation
    of the profile's reference, :func:`aiding_extrinsic`); with ``turn``, one line saying that a rotation
    the rates resolve will be turned away (the caller turns the rows, :func:`.aiding.frame.turned_onto_gyro`);
    else one warning line when it is a little off or cannot be told."""
    check = check_frame(imu.t_ns, imu.gyro, rows, max_gap_s)
    if turn and check.resolved:
        given = (f"after --extrinsics {Path(src.extrinsics).name}" if src.extrinsics is not None
                 else "after --profile's reference rotation" if from_profile else "as given")
        log.warning(f"aiding frame: its poses are {check.rotation_deg:.2f} deg (+- {check.spread_deg:.2f}) off the "
                    f"IMU's {given} (a rectified camera's?): turned onto the gyro's frame (--keep-aiding-frame "
                    "fuses them as given)")
        return check
    if check.verdict == "refused" and not check.matches:  # the file itself, whatever the extrinsic
        raise ConfigError(f"--aiding {src.aiding}: {check.why}; check the file against the IMU (imu-learn groundtruth)")
    if check.verdict == "refused":
        if src.extrinsics is None and from_profile:
            fix = ("after the rotation of --profile's reference: that reference's sensor is not this aiding's; pass "
                   "--extrinsics with this sensor's pose in the IMU frame (a Kalibr/EuRoC sensor.yaml T_BS)")
        elif src.extrinsics is None:
            fix = ("they are another sensor's poses (a camera's?): pass --extrinsics with that sensor's pose in the "
                   "IMU frame (a Kalibr/EuRoC sensor.yaml T_BS)")
        else:
            fix = (f"after --extrinsics {src.extrinsics}: that extrinsic is not this aiding's (T_BS is the sensor's "
                   "pose in the IMU frame; check its direction and the sensor)")
        raise ConfigError(f"--aiding {src.aiding}: {check.why}: {fix}")
    if check.verdict == "warned":
        log.warning("aiding frame: %s; the poses are fused as the IMU's (pass --extrinsics if you know the "
                    "sensor's mounting)", check.why)
    elif check.verdict == "not checked":
        log.warning("aiding frame not checked: %s", check.why)
    return check


def input_label(src: Sources, opts: NavigateOptions, plan: correction.Plan, floor: bool) -> str:
    """What the IMU as fused is, for the summary's ``imu_input``; refuses ``--variance-scale`` without a
    covariance head's variances to scale (before any model runs)."""
    if opts.variance_scale is not None:
        if src.calibration is not None:
            raise ConfigError("--variance-scale scales a covariance head's variances: not with --calibration")
        if src.checkpoint is None:
            raise ConfigError("--variance-scale scales a covariance head's variances: it needs --checkpoint")
        if not plan.covariance:
            raise ConfigError(f"--variance-scale: {Path(src.checkpoint).name} has no covariance head (model.covariance)")
    if src.calibration is not None:
        return plan.words[0]
    if src.checkpoint is not None:
        label = f"refined by {Path(src.checkpoint).name}"
        return label + (", weighted by its learned covariance" if plan.covariance else "")
    return f"the floor of profile {Path(src.profile).parent.name or src.profile}" if floor else "raw"


def imu_input(src: Sources, opts: NavigateOptions, imu: Imu) -> Tuple[np.ndarray, np.ndarray, Optional[np.ndarray], str]:
    """(gyro, acc, per-sample variances or None, label): the IMU as fused (corrected by
    :func:`read_body_imu`), a covariance head's variances scaled by ``--variance-scale``."""
    var, label = imu.var, imu.label
    if var is not None and opts.variance_scale is not None:
        kg, ka = (float(x) for x in opts.variance_scale)
        var = var * np.repeat([kg, ka], 3)
        label += f" scaled by {kg:g} (gyro), {ka:g} (acc)"
    return imu.gyro, imu.acc, var, label


AIDING_SOURCES = {"tum": "TUM trajectory", "csv": "CSV trajectory", "asl": "ASL trajectory",
                  "rtklib": "RTKLIB solution"}


def aiding_label(src: Sources, opts: NavigateOptions) -> str:
    """What the aiding is, for the summary's ``aiding_label`` and the plot's title: a bag's topic by its
    message type (``run.bag topic /gps/fix (NavSatFix, bag)``: GNSS fixes, not an RTKLIB solution), else the
    file with its format (``cam0.tum (TUM trajectory)``). The kind and sigmas follow it
    (:meth:`.aiding.kinds.AidingKind.build`); RTKLIB solutions name their qualities (:func:`fixes_on_imu`)."""
    name = Path(src.aiding).name
    if opts.aiding_format == "bag":
        kind = bag_aiding.topic_type(Path(src.aiding), str(src.aiding_topic)).rsplit("/", 1)[-1]
        return f"{name} topic {src.aiding_topic} ({kind}, bag)"
    return f"{name} ({AIDING_SOURCES.get(opts.aiding_format, opts.aiding_format)})"


def is_geodetic(src: Sources, opts: NavigateOptions) -> bool:
    """Whether the aiding is geodetic fixes (an RTKLIB file or a bag's NavSatFix topic)."""
    return opts.aiding_format in GEODETIC_FORMATS or (
        opts.aiding_format == "bag" and bag_aiding.is_geodetic(Path(src.aiding), str(src.aiding_topic)))


def resolve_aiding(src: Sources, opts: NavigateOptions, kind: Optional[str]) -> NavigateOptions:
    """``opts`` with the aiding's format found from its content when ``auto`` (:mod:`.aiding.detect`)
    and its kind: ``kind`` when given, else ``position`` for geodetic fixes (they are nothing else);
    a :class:`ConfigError` for any other aiding without a kind, or a bag without a topic."""
    if opts.aiding_format == "auto":
        opts = replace(opts, aiding_format=detect_aiding(Path(src.aiding)))
    if opts.aiding_format == "bag" and not src.aiding_topic:
        raise ConfigError(f"--aiding {src.aiding} is a ROS bag: name its topic with --aiding-topic "
                          "(PoseStamped, Odometry, TransformStamped, PointStamped or NavSatFix)")
    if opts.aiding_format != "bag" and src.aiding_topic:
        raise ConfigError(f"--aiding-topic: {src.aiding} is not a ROS bag (format {opts.aiding_format})")
    if kind is not None and not getattr(kind_of(kind), "geodetic", False) and opts.aiding_format == "bag" \
            and is_geodetic(src, opts):
        raise ConfigError(f"{src.aiding} topic {src.aiding_topic} holds GNSS fixes: use it with --aiding-kind "
                          f"{GEODETIC_KIND}")
    if kind is None:
        if not is_geodetic(src, opts):
            raise ConfigError(f"--aiding-kind {{{','.join(KINDS)}}}: say what {Path(src.aiding).name} holds "
                              f"(its format, {opts.aiding_format}, does not)")
        kind = GEODETIC_KIND
    return replace(opts, aiding_kind=kind)


def truth_is_fixes(src: Sources) -> bool:
    """``--groundtruth`` is an RTKLIB ``.pos`` (scored by :func:`.score.score_against_fixes`)."""
    return src.groundtruth is not None and detect_aiding(Path(src.groundtruth)) == "rtklib"


def check_inputs(src: Sources) -> Optional[Tuple[int, int]]:
    """Read the side files before any fusion, so that a bad one is refused first (not after a long
    fusion, with tracks and no summary): ``--groundtruth`` (poses: ``t tx ty tz qx qy qz qw`` or
    ASL, or an RTKLIB ``.pos`` whose RTK-fixed rows score a GNSS-aided run's antenna; another
    positions-only file is refused), ``--extrinsics`` and ``--profile``. Returns the ground
    truth's (first, last) stamp [ns], or None without one."""
    span = None
    if truth_is_fixes(src):
        fixes = read_pos(Path(src.groundtruth))
        if int(np.sum(np.asarray(fixes.q) == 1)) < 3:
            raise ConfigError(f"--groundtruth {src.groundtruth}: fewer than 3 RTK-fixed rows (Q = 1) to score with")
        span = (int(fixes.t_ns[0]), int(fixes.t_ns[-1]))
    elif src.groundtruth is not None:
        try:
            gt = read_truth(Path(src.groundtruth))
        except ColumnCountError as e:
            raise ConfigError(f"--groundtruth: {' '.join(str(e).split())}: navigate scores poses (t tx ty tz qx qy qz "
                              "qw, or an ASL state/pose CSV) or a GNSS-aided run's antenna against an RTKLIB .pos; "
                              "another positions-only file cannot be scored") from None
        if len(gt.t_ns) < 2:
            raise ConfigError(f"--groundtruth {src.groundtruth}: {len(gt.t_ns)} pose(s); scoring needs at least 2")
        span = (int(gt.t_ns[0]), int(gt.t_ns[-1]))
    if src.extrinsics is not None:
        read_t_bs(src.extrinsics)
    if src.profile is not None:
        Profile.load(src.profile)
    return span


@dataclass
class Inputs:
    """What :func:`read_inputs` read and checked: the options as resolved (with geodetic fixes' gravity),
    the aiding's kind, the IMU (:func:`read_body_imu`), the lever arm, the aiding rows used and how
    many were read, and (the GNSS fixes, their solution) of geodetic aiding or None."""

    opts: NavigateOptions
    kind: AidingKind
    imu: Imu
    lever: np.ndarray
    rows: AidingRows
    rows_read: int
    gnss: Optional[tuple]


@dataclass
class Started:
    """What :func:`start_run` hands the fusion: the first state, the graph's aiding and the summary's
    counts of it, the IMU as fused (gyro, acc, variances or None) and its label, the summary's
    ``bias`` entry and where the first bias came from, the GNSS fixes' velocity hook (None: none) and
    the summary's ``gnss_velocities`` entry."""

    st: Start
    aiding: object
    counts: Dict[str, object]
    fused: tuple
    label: str
    bias: Dict[str, object]
    bias_source: str
    velocities: Optional[Callable] = None
    velocity_entry: Dict[str, object] = field(default_factory=dict)


def check_gaps(gaps: Tuple[OutageWindow, ...], duration_s: float) -> None:
    """Refuses a ``--gaps`` window that lies wholly outside the recording (0 to ``duration_s`` from its first
    IMU sample): it would drop nothing, and the run would look like one with an outage."""
    for start, dur in gaps:
        if start >= duration_s or start + dur <= 0.0:
            raise ConfigError(f"--gaps {start:g}:{dur:g} lies outside the recording (0 to {duration_s:.1f} s from its "
                              "first IMU sample): give START in seconds from the first sample")
        if start + dur > duration_s:
            log.warning(f"--gaps {start:g}:{dur:g} runs past the recording's end ({duration_s:.1f} s): the aiding is "
                        "dropped to the end, and no fix returns to score that gap's end")


LEVER_ARM_WARN_M = 3.0  # a lever arm longer than this gets a warning before the fusion (a car's antenna: 0.5-2 m)


def read_inputs(src: Sources, opts: NavigateOptions) -> Inputs:
    """The run's inputs, each checked before any fusion: the aiding's format and kind
    (:func:`resolve_aiding`), the options, the side files (:func:`check_inputs`), the IMU (the ground
    truth's stamps overlapping it), the lever arm and the aiding rows (:func:`aiding_rows`). Geodetic
    fixes are read once (:func:`read_geodetic`), for the delay, the noise fit and the rows alike."""
    opts = resolve_aiding(src, opts, opts.aiding_kind)
    opts.check()
    gt_span = check_inputs(src)
    kind = kind_of(opts.aiding_kind)
    T_BS = aiding_extrinsic(src, kind)
    if opts.lever_arm is not None and src.extrinsics is not None:
        raise ConfigError("--lever-arm and --extrinsics both give the antenna's lever arm: pass one")
    sol = read_geodetic(src, opts) if is_geodetic(src, opts) else None
    if truth_is_fixes(src) and sol is None:
        raise ConfigError(f"--groundtruth {src.groundtruth}: an RTKLIB .pos scores a run aided by GNSS fixes (in their "
                          "ENU world); give this run's reference as poses (t tx ty tz qx qy qz qw, or ASL)")
    imu = read_body_imu(src, opts, sol)
    t_ns = imu.t_ns
    if gt_span is not None and (gt_span[1] < t_ns[0] or gt_span[0] > t_ns[-1]):
        raise ConfigError(f"--groundtruth {src.groundtruth}: its stamps [{gt_span[0]}, {gt_span[1]}] ns do not overlap "
                          f"the IMU's [{int(t_ns[0])}, {int(t_ns[-1])}] ns (same clock?)")
    check_gaps(opts.gaps, float((t_ns[-1] - t_ns[0]) * 1e-9))
    rate = sample_rate_hz(t_ns) if len(t_ns) > 1 else None
    if rate and opts.keyframe_hz > rate:
        log.warning(f"--keyframe-hz {opts.keyframe_hz:g} is above the IMU's rate ({rate:.0f} Hz): every IMU sample is a "
                    f"keyframe: about {rate / 10:.0f}x the keyframes of the default 10 Hz, and its time")
    lever = T_BS[:3, 3] if (T_BS is not None and kind.lever) else np.zeros(3)
    if opts.lever_arm is not None:
        lever = np.asarray(opts.lever_arm, dtype=np.float64)
    if float(np.linalg.norm(lever)) > LEVER_ARM_WARN_M:
        log.warning("the lever arm is %.3g m long (%s): in metres? (a lever arm in cm or mm typed as m moves every "
                    "fix by that much; the smoother's biases would show it only after the fusion)",
                    float(np.linalg.norm(lever)), ", ".join(f"{x:g}" for x in lever))
    rows, rows_read, gnss, opts = aiding_rows(src, opts, t_ns, T_BS, lever, imu, sol)
    warn_unaided_end(src, rows, t_ns, opts.gaps)
    return Inputs(opts, kind, moving_imu(src, opts, imu, rows), lever, rows, rows_read, gnss)


def aiding_extrinsic(src: Sources, kind: AidingKind) -> Optional[np.ndarray]:
    """The aiding sensor's pose in the IMU frame (T_BS, 4x4): ``--extrinsics``; else, for poses, the rotation
    ``imu-learn calibrate`` estimated and applied between its reference and the IMU (``--profile``'s
    reference, :func:`~imu_learn.calib.reference.applied_extrinsic`), one warning line saying so (a VIO's
    camera poses calibrated against, then navigated with: refused before, naming --extrinsics, though the
    profile held the rotation); the frame check judges it as it judges --extrinsics."""
    if src.extrinsics is not None:
        return read_t_bs(src.extrinsics)
    if src.profile is None or not kind.poses:
        return None
    found = applied_extrinsic(Profile.load(src.profile).reference or {})
    if found is None:
        return None
    T, rotation_deg, where = found
    log.warning(f"--aiding {Path(src.aiding).name}: its poses moved into the IMU frame by --profile's reference, as "
                f"imu-learn calibrate estimated it: rotation {rotation_deg:.2f} deg, {where}; --extrinsics gives another")
    return T


UNAIDED_END_S = 5.0  # an aiding that stops this long before the IMU gets a warning (the tracks' end is unaided)


def warn_unaided_end(src: Sources, rows: AidingRows, t_ns: np.ndarray, gaps: Tuple[OutageWindow, ...]) -> None:
    """One warning where the aiding's last row comes more than :data:`UNAIDED_END_S` before the IMU's last
    sample outside a ``--gaps`` window that runs to the end (a file cut short, a receiver that stopped):
    the tracks' end is then the IMU's alone, which nothing else in the output says."""
    if not len(rows.t_ns):
        return
    last_s, end_s = (float((x - t_ns[0]) * 1e-9) for x in (rows.t_ns[-1], t_ns[-1]))
    if end_s - last_s <= UNAIDED_END_S or any(g0 <= last_s + UNAIDED_END_S and g0 + dur >= end_s for g0, dur in gaps):
        return
    log.warning(f"--aiding {src.aiding}: its last row is at {last_s:.1f} s of the IMU's {end_s:.1f} s: the tracks' last "
                f"{end_s - last_s:.1f} s are the IMU's alone (dead reckoning): a file cut short, or a receiver that "
                "stopped?")


def start_run(src: Sources, inp: Inputs) -> Started:
    """The start: the IMU as fused (the checkpoint's bias, ``--variance-scale``, ``--bias``), the first
    state (:meth:`.aiding.kinds.AidingKind.start`) under its loose prior, and the graph's aiding from it."""
    opts, kind, rows, lever, t_ns = inp.opts, inp.kind, inp.rows, inp.lever, inp.imu.t_ns
    bias0, bias_source = checkpoint_bias(src.checkpoint)
    gyro, acc, var, label = imu_input(src, opts, inp.imu)
    gyro, bias = own_bias(opts, t_ns, gyro, acc, str(src.input), bias_prior(inp.imu))
    if bias.get("applied") and np.any(bias0[:3]):  # the estimate replaces the device bias's gyro part
        bias0 = np.r_[unobserved(bias) @ bias0[:3], bias0[3:]]
        bias_source += f"; gyro part: only where the recording's own bias ({opts.bias}) was not observed"
    st = kind.start((t_ns, gyro, acc), rows, lever, bias0, opts)
    aiding, counts = kind.build(rows, st.start, st.R_WA, lever, opts, aiding_label(src, opts), str(src.aiding),
                                None if inp.gnss is None else inp.gnss[0])
    if len(aiding) == 0:
        raise AidingError(f"{src.aiding}: no aiding measurement left to fuse", str(src.aiding), opts.aiding_kind)
    # position aiding starts moving
    at_rest = st.info["still_s"] >= MIN_STILL_START_S and not kind.moving_start
    # the bias prior: a floor-applied profile's per-recording bias spread (.start.prior), else the defaults
    bias_sigmas, st.info["bias_prior"] = (None, {"source": "defaults: no profile floor applied"}) if inp.imu.floor is None \
        else profile_bias_sigmas(Profile.load(inp.imu.floor), isotropic=inp.imu.mounting is not None)
    bias_kw = {} if bias_sigmas is None else {"bias_gyro": bias_sigmas[0], "bias_acc": bias_sigmas[1]}
    st = replace(st, prior=PriorSigmas(rot_rad=float(np.deg2rad(opts.prior_rot_deg)), pos_m=opts.prior_pos_m,
                                       vel_mps=0.05 if at_rest else opts.prior_vel_mps, **bias_kw))
    if src.displacement is not None:
        label += f" + displacements of {Path(src.displacement).name}"
    hook, velocity_entry = gnss_velocities(aiding, None if inp.gnss is None else inp.gnss[1], opts, int(t_ns[0]))
    return Started(st, aiding, counts, (gyro, acc, var), label, bias, bias_source, hook, velocity_entry)


def final_bias_check(bias: np.ndarray) -> Dict[str, object]:
    """summary.json's ``final_bias_check``: the smoother's last gyro and acc biases (6,) against a MEMS IMU's
    limits (:data:`imu_learn.calib.plausible.LIMITS`, calibrate's); beyond them one warning line names the
    usual causes (the fused tracks are still written). A wrong mounting or a lever arm in centimetres ends
    in biases no MEMS IMU has (a lever arm of 5 m on the walk: acc bias 3.4 m/s^2)."""
    b = np.asarray(bias, dtype=np.float64)
    limits = (LIMITS["gyro_bias_rad_s"], LIMITS["acc_bias_mps2"])
    over = [f"{name} bias {v:+.3g} {unit} on {'xyz'[i]} (limit {lim:g})"
            for (name, unit, part, lim) in (("gyro", "rad/s", b[:3], limits[0]), ("acc", "m/s^2", b[3:], limits[1]))
            for i, v in enumerate(part) if abs(v) > lim]
    entry: Dict[str, object] = {"plausible": not over, "limits": {"gyro_rad_s": limits[0], "acc_mps2": limits[1]}}
    if over:
        entry["why"] = ("the fused IMU's biases are beyond a MEMS IMU's (" + "; ".join(over) + "): a wrong mounting "
                        "(--imu-rotation-rpy-deg), a lever arm not in metres (--lever-arm), the IMU's units or a "
                        "profile of another device; the tracks are written, check them")
        log.warning(entry["why"])
    return entry


def run_summary(src: Sources, out: Path, inp: Inputs, run: Started, res) -> Dict[str, object]:
    """summary.json's content (without ``seconds``, known once written), with ``--groundtruth`` the scores."""
    opts, imu, rows, st, t_ns, s0 = inp.opts, inp.imu, inp.rows, run.st, inp.imu.t_ns, run.st.start
    kf_t = t_ns[s0:][res.kf_idx]
    summary: Dict[str, object] = {
        "input": str(src.input), "imu_file": imu.file, "imu_input": run.label,
        "noise": imu.noise.source if run.fused[2] is None else "learned per-sample variances"
        + ("" if opts.variance_scale is None else " x variance_scale"),
        "imu_noise": imu.noise.to_dict(), "profile": _text(src.profile), "profile_floor": imu.floor is not None,
        "aiding_topic": src.aiding_topic,
        "aiding": str(src.aiding), "aiding_kind": opts.aiding_kind, "aiding_format": opts.aiding_format,
        "aiding_label": run.aiding.label, "extrinsics": _text(src.extrinsics), "checkpoint": _text(src.checkpoint),
        "displacement": _text(src.displacement), "calibration": _text(src.calibration),
        "variance_scale": None if opts.variance_scale is None else [float(x) for x in opts.variance_scale],
        "aiding_rows_read": int(inp.rows_read), "aiding_rows_used": int(len(rows.sample)),
        "aiding_dropped": rows.dropped, **run.counts, "keyframes": int(len(res.kf_idx)),
        "imu_samples_before_start": s0, "duration_s": round(float((t_ns[-1] - t_ns[s0]) * 1e-9), 3),
        "init": {**st.info, "bias0": [round(float(b), 6) for b in st.bias], "bias_source": run.bias_source,
                 "prior": asdict(st.prior)},
        "convergence": convergence(kf_t * 1e-9, res.causal_p, res.causal_R, res.smoothed_p, res.smoothed_R),
        "counts": res.counts, "seconds_fusion": round(res.seconds, 2),
        "options": {k: (list(map(list, v)) if k == "gaps" else v) for k, v in asdict(opts).items()},
        "imu_mounting": None if imu.mounting is None else np.round(imu.mounting, 6).tolist(),
        "imu_mounting_check": imu.mounting_check,
        "lever_arm_m": [round(float(x), 4) for x in inp.lever],
        "final_bias": [round(float(b), 6) for b in res.smoothed_bias[-1]],
        "final_bias_check": final_bias_check(res.smoothed_bias[-1]),
        "aiding_up_check": None if rows.gravity is None else rows.gravity.to_dict(),
        "bias": run.bias, "correction": imu.correction, "imu_delay": imu.delay, "gnss_velocities": run.velocity_entry,
        "outputs": {"causal": str(out / "causal.tum"), "smoothed": str(out / "smoothed.tum")},
        "causal_frame": res.causal_frame,
        **frames(src, opts, None if inp.gnss is None else inp.gnss[1]),
    }
    if src.groundtruth is not None and truth_is_fixes(src):
        summary["groundtruth"] = str(src.groundtruth)
        summary["scores"] = score_against_fixes(read_pos(Path(src.groundtruth)), kf_t, res, inp.lever,
                                                inp.gnss[1].origin_llh, int(t_ns[0]), opts.gaps)
    elif src.groundtruth is not None:
        summary["groundtruth"] = str(src.groundtruth)
        summary["scores"] = score_against(src.groundtruth, kf_t, res, rows, st.R_WA, int(t_ns[0]), inp.kind.aligned,
                                          opts.gaps)
    return summary


def write_run(src: Sources, out: Path, inp: Inputs, run: Started, res, summary: Dict[str, object],
              written: Optional[Callable[[], None]], t_start: float) -> Dict[str, object]:
    """Every file into a staging folder, swapped in whole at the end (:func:`imu_learn.util.staging.staged_dir`):
    ``out`` holds this run's files or the old ones; returns the summary, its ``seconds`` and outputs filled in."""
    t_ns, gnss = inp.imu.t_ns, inp.gnss
    kf_t = t_ns[run.st.start:][res.kf_idx]
    with staged_dir(out, OUTPUT_NAMES, written) as stage:
        write_trajectory(stage / "causal.tum", kf_t, res.causal_p, res.causal_R)
        write_trajectory(stage / "smoothed.tum", kf_t, res.smoothed_p, res.smoothed_R)
        extra = write_outputs(src, stage, kf_t, res, None if gnss is None else gnss[1])
        summary["outputs"].update({k: str(out / Path(v).relative_to(stage)) for k, v in extra.items()})
        if plot_navigation(stage / "plot.png", f"{Path(src.input).name}: {run.aiding.label}", kf_t, res, inp.rows,
                           run.st.R_WA, summary.get("scores"), inp.opts.gaps, int(t_ns[0])):
            summary["outputs"]["plot"] = str(out / "plot.png")
        summary["seconds"] = round(time.perf_counter() - t_start, 2)
        write_json(stage / "summary.json", summary)
    return summary


def navigate(src: Sources, out: Path, opts: NavigateOptions = NavigateOptions(),
             progress: bool = False, written: Optional[Callable[[], None]] = None) -> Dict[str, object]:
    """Fuse the recording's IMU with its aiding file and write ``out``/{causal.tum, smoothed.tum,
    plot.png, summary.json} (and the geodetic tracks of GNSS aiding, the bags of bag aiding: see
    :func:`write_outputs`); returns the summary (module docstring). ``progress``: a bar on stderr for
    runs longer than a few seconds. ``opts.aiding_kind`` None: from the aiding
    (:func:`resolve_aiding`). The outputs go in all at once (:func:`imu_learn.util.staging.staged_dir`):
    an error or a Ctrl-C before that leaves ``out`` as it was; ``written()`` is called once ``out``
    holds them all (a Ctrl-C during the swap is raised after it). The steps: :func:`read_inputs`,
    :func:`start_run`, :func:`fuse_run`, :func:`run_summary`, :func:`write_run`."""
    t_start = time.perf_counter()
    inp = read_inputs(src, opts)
    run = start_run(src, inp)
    res = fuse_run(src, inp.opts, inp.imu, run.fused, run.st, run.aiding, run.label, progress, run.velocities)
    out = Path(out)
    summary = run_summary(src, out, inp, run, res)
    return write_run(src, out, inp, run, res, summary, written, t_start)


def bias_prior(imu: Imu) -> BiasPrior:
    """The device prior of ``--bias``: the bias spread between recordings of the profile whose floor was
    applied (:meth:`Profile.gyro_bias_prior_std`; its largest axis on every axis when the IMU is rotated
    into the body frame), else a MEMS gyro's."""
    if imu.floor is None:
        return MEMS_PRIOR
    profile = Profile.load(imu.floor)
    std, how = profile.gyro_bias_prior_std()
    return BiasPrior.from_bias_std(std, f"the bias spread of profile {imu.floor} ({how})",
                                   isotropic=imu.mounting is not None, measured=profile.bias_prior)


def own_bias(opts: NavigateOptions, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
             where: str, prior: BiasPrior = MEMS_PRIOR) -> Tuple[np.ndarray, Dict[str, object]]:
    """(the gyro with the recording's own bias removed, the summary's ``bias`` entry): ``opts.bias``
    estimated on the IMU as fused (after the profile's floor or the model, in the body frame) and
    bounded by ``prior``, the estimator refine's ``--bias`` runs (:func:`imu_learn.infer.bias.bias_step`)."""
    if opts.bias == "none":
        return gyro, {"method": "none"}
    sink: Dict[str, object] = {}
    g, _, _ = bias_step(opts.bias, opts.gravity, sink, prior=prior)(t_ns, gyro, acc)
    entry, warning = bias_entry(opts.bias, sink, where)
    if warning:
        log.warning(warning)
    return g, entry


def unobserved(entry: Dict[str, object]) -> np.ndarray:
    """(3, 3) projection onto the body-frame directions a ``--bias`` estimate did not observe (gravity
    consistency's weak directions; zero for the still stretches, which observe every axis): the
    entry's ``unobserved_directions_body`` (:func:`imu_learn.infer.bias.bias_entry`, whatever the
    estimator nests), else gravity consistency's own keys at its top level."""
    if entry.get("unobserved_directions_body") is not None:
        return sum((np.outer(d, d) for d in entry["unobserved_directions_body"]), np.zeros((3, 3)))
    dirs, seen = entry.get("directions_body"), entry.get("direction_observed")
    P = np.zeros((3, 3))
    for d, ok in zip(dirs or [], seen or []):
        if not ok:
            P += np.outer(d, d)
    return P


def _text(path: Optional[Path]) -> Optional[str]:
    return None if path is None else str(path)


def frames(src: Sources, opts: NavigateOptions, sol: Optional[RtkSolution]) -> Dict[str, object]:
    """What the trajectories' frame and stamps are, for summary.json: the ENU origin of geodetic
    fixes, and the time system of the stamps."""
    if sol is None:
        return {"frame": "the aiding's world, gravity-aligned (z up)",
                "time_system": "the recording's IMU clock (seconds as read), the aiding on the same clock"}
    lat, lon, h = sol.origin_llh
    origin = {"latitude_deg": lat, "longitude_deg": lon, "height_m": h,
              "what": "WGS-84, ellipsoidal height; the first fix of the aiding"}
    if opts.aiding_format == "rtklib":
        ts = ("GPST: GPS time, seconds since 1970-01-01 00:00:00 without leap seconds (RTKLIB's stamps; the IMU "
              "on the same scale)")
    else:
        ts = f"the header stamps of {src.aiding_topic} (the bag's clock: usually UTC or the recorder's system time)"
    return {"frame": "local east-north-up (x east, y north, z up) at enu_origin", "enu_origin": origin,
            "time_system": ts}


# Every name navigate writes in its output folder: a previous run's are replaced or removed, other files kept.
OUTPUT_NAMES = ("causal.tum", "smoothed.tum", "plot.png", "summary.json", "causal_llh.csv", "smoothed_llh.csv",
                "track.kml", "track.geojson", "causal.bag", "smoothed.bag", "causal_bag", "smoothed_bag")


def write_outputs(src: Sources, out: Path, kf_t: np.ndarray, res, sol: Optional[RtkSolution]) -> Dict[str, str]:
    """The files beside the TUM ones: with geodetic aiding the causal and smoothed tracks as
    latitude/longitude/height CSVs (``causal_llh.csv``, ``smoothed_llh.csv``), ``track.kml`` and
    ``track.geojson``; with a ROS bag as input or aiding both trajectories as nav_msgs/Odometry on
    ``/imu_learn/odometry`` in bags of that bag's kind (``causal.bag``/``smoothed.bag`` for ROS 1,
    the folders ``causal_bag``/``smoothed_bag`` for ROS 2). Returns {name: path}."""
    written: Dict[str, str] = {}
    tracks = {"causal": (res.causal_p, res.causal_R), "smoothed": (res.smoothed_p, res.smoothed_R)}
    if sol is not None:
        llh = {k: geo.enu_to_llh(p, sol.origin_llh) for k, (p, _R) in tracks.items()}
        for k, v in llh.items():
            geo.write_llh_csv(out / f"{k}_llh.csv", kf_t, v)
            written[f"{k}_llh"] = str(out / f"{k}_llh.csv")
        geo.write_kml(out / "track.kml", Path(src.input).name, llh)
        geo.write_geojson(out / "track.geojson", {k: (kf_t, v) for k, v in llh.items()})
        written.update(kml=str(out / "track.kml"), geojson=str(out / "track.geojson"))
    like = next((Path(p) for p in (src.input, src.aiding) if rosbag.detect(Path(p))), None)
    if like is not None:
        ros1 = rosbag.is_ros1(rosbag.bag_path(like))
        for k, (p, R) in tracks.items():
            written[f"{k}_bag"] = str(write_trajectory_bag(out / (k if ros1 else f"{k}_bag"), kf_t, p, R, like=like))
    return written


def fuse_run(src: Sources, opts: NavigateOptions, imu: Imu, fused: tuple, st: Start, aiding, label: str,
             progress: bool = False, velocities: Optional[Callable] = None):
    """The factor graph from the start sample on: the IMU as fused (``fused``: gyro, acc, variances or
    None), the aiding, the GNSS fixes' ``velocities`` (:func:`gnss_velocities`), ``--nhc`` and
    ``--displacement``'s factors (regressed from the raw IMU); the samples streamed as
    :func:`imu_learn.fuse.graph.fuse` streams them, with a progress bar."""
    gyro, acc, var = fused
    sel = slice(st.start, None)
    settings = FusionSettings(imu.noise, opts.gravity, opts.keyframe_hz, st.prior,
                              **({} if opts.lag_s is None else {"lag_s": opts.lag_s}))
    hooks = [] if velocities is None else [velocities]
    if opts.nhc:
        hooks.append(nhc_callback(NhcSettings(opts.nhc_sigma_lat_mps, opts.nhc_sigma_vert_mps),
                                  np.ascontiguousarray(gyro[sel])))
    if src.displacement is not None:
        hooks.append(displacement_hook(displacement_model(Path(src.displacement)), imu.t_ns[sel], imu.gyro[sel],
                                       imu.acc[sel]))
    log.info(f"fusing {len(imu.t_ns) - st.start} IMU samples ({label}) with {len(aiding)} {opts.aiding_kind} "
             f"measurements of {src.aiding}")
    t_ns = imu.t_ns[sel]

    def on_state(*_) -> None:  # between two samples, in plain Python: where a held Ctrl-C is raised
        bar.update(1)
        interrupts.check()

    try:
        # Ctrl-C held while GTSAM runs (it calls the Python factors back from C++): raised by on_state, or
        # at the block's end for one during the batch pass
        with interrupts.held_interrupts():
            t0 = time.perf_counter()
            inc = IncrementalFusion(t_ns, st.pose, [aiding], settings, st.bias, predict_between=False,
                                    extra_factors=chain(*hooks))
            with tqdm(total=len(t_ns), desc="navigate", unit="sample", unit_scale=True, delay=PROGRESS_DELAY_S,
                      mininterval=1.0, disable=not progress, file=sys.stderr, leave=False) as bar:
                feed(inc, samples_of(np.ascontiguousarray(gyro[sel]), np.ascontiguousarray(acc[sel]),
                                     None if var is None else np.ascontiguousarray(var[sel])), on_state=on_state)
                res = inc.smooth(progress=batch_pass_progress(bar))
        res.seconds = time.perf_counter() - t0
        return res
    except RuntimeError as e:  # GTSAM's IndeterminateLinearSystemException and kin
        raise AidingError(f"{src.aiding}: the factor graph could not be solved: {' '.join(str(e).split())[:300]}",
                          str(src.aiding), opts.aiding_kind) from None


def batch_pass_progress(bar: Any) -> Callable[..., Any]:
    """The fusion's bar turned to the batch pass: its label now, then its iterations counted (no total
    known), each shown as it ends. Shown from here on, so its delay is dropped: tqdm takes a bar reset
    within its delay for one never shown and leaves its text behind when it closes (a Ctrl-C's line then
    ran into it)."""
    bar.set_description_str("navigate: smoothing", refresh=False)  # set_description would add a second ": "
    bar.total, bar.unit, bar.unit_scale = None, " iteration", False
    bar.reset()
    bar.delay = 0
    return lambda *_: (bar.update(1), bar.refresh())


def gnss_velocities(fixes, sol: Optional[RtkSolution], opts: NavigateOptions, t0_ns: int
                    ) -> Tuple[Optional[Callable], Dict[str, object]]:
    """The graph's hook adding each fused GNSS fix's epoch velocity (:func:`.factors.velocity.velocity_callback`,
    ``opts.gnss_velocity_sigma_mps``, float epochs x2) at the instant its lag puts it, the lag measured from
    the file's fixed epochs outside ``--gaps`` (:func:`.factors.velocity.velocity_lag`; 0 where it cannot be,
    said in the entry), and summary.json's ``gnss_velocities`` entry; (None, why) without GNSS fixes with
    velocities or with the sigma 0. The rtklibexplorer/GNSS_IMU solutions' velocities lag their positions by
    0.12 s (docs/experiments/fusion_gnss.md)."""
    if sol is None or not isinstance(fixes, GnssFixes) or fixes.epoch is None:
        return None, {"used": False, "why": "no GNSS fixes"}
    if sol.vel_enu is None:
        return None, {"used": False, "why": f"{Path(sol.path).name} has no velocity columns"}
    if opts.gnss_velocity_sigma_mps <= 0:
        return None, {"used": False, "why": "--gnss-velocity-sigma 0: positions only"}
    try:
        lag = velocity_lag(sol, use=outside_gaps(sol, t0_ns, opts.gaps))
        lag_s, lag_entry = max(lag.lag_s, 0.0), {"lag_s": round(lag.lag_s, 4), "epochs": lag.epochs,
                                                 "rms_before_mps": round(lag.rms_before_mps, 4),
                                                 "rms_after_mps": round(lag.rms_after_mps, 4)}
    except InvalidInputError as e:
        lag_s, lag_entry = 0.0, {"lag_s": 0.0, "why": f"not measured: {e}"}
    hook = velocity_callback(fixes, sol, opts.gnss_velocity_sigma_mps, FLOAT_GAIN, lag_s)
    return hook, {"used": True, "sigma_mps": opts.gnss_velocity_sigma_mps, "float_gain": FLOAT_GAIN, "lag": lag_entry}


def one_line(summary: Dict[str, object]) -> str:
    """The line the CLI prints for a run."""
    s = summary
    conv = s["convergence"]["converged_s"]
    text = (f"{Path(str(s['input'])).name}: {s['keyframes']} keyframes over {s['duration_s']:.1f} s, "
            f"{s['aiding_rows_used']} {s['aiding_kind']} rows"
            + (f" ({s['fixes_before_start']} before the start, for its attitude; {s['imu_input']} IMU); "
               if s.get("fixes_before_start") else f" ({s['imu_input']} IMU); ")
            + f"causal within {s['convergence']['pos_tol_m']:g} m / {s['convergence']['rot_tol_deg']:g} deg of smoothed "
            + (f"from {conv:.1f} s" if conv is not None else "not by the end"))
    sc = s.get("scores")
    if sc:
        kind = "aligned" if sc["aligned"] else "unaligned"
        text += (f"; {kind} position RMSE causal {sc['causal']['pos_rmse_m']:.3f} m, smoothed "
                 f"{sc['smoothed']['pos_rmse_m']:.3f} m")
        if sc.get("aiding_only") and sc.get("causal_at_aiding_stamps"):  # like with like: the aiding's stamps
            text += (f"; at the aiding's stamps causal {sc['causal_at_aiding_stamps']['pos_rmse_m']:.3f} m, smoothed "
                     f"{sc['smoothed_at_aiding_stamps']['pos_rmse_m']:.3f} m, aiding alone "
                     f"{sc['aiding_only']['pos_rmse_m']:.3f} m")
            worse = (sc.get("against_aiding") or {}).get("worse") or []
            if worse:
                ratio = sc["against_aiding"]["ratio"]
                text += (" (" + " and ".join(f"{k} x{ratio[k]:.3f}" for k in worse)
                         + " the aiding alone: fusion made its positions worse there)")
        elif sc.get("aiding_only"):
            text += f", aiding alone {sc['aiding_only']['pos_rmse_m']:.3f} m"
        gaps = [g for g in sc["causal"].get("gaps") or [] if g.get("end_m") is not None]
        if gaps:
            text += f"; causal at the gaps' ends {', '.join(format(g['end_m'], '.2f') for g in gaps)} m"
            if all("horizontal" in g for g in gaps):
                text += f" (horizontally {', '.join(format(g['horizontal']['end_m'], '.2f') for g in gaps)} m)"
    if one_line_text(s.get("aiding_estimates")):
        text += f"; {one_line_text(s.get('aiding_estimates'))}"
    return text + f" -> {Path(str(s['outputs']['smoothed'])).parent} ({s['seconds']:.0f} s)"


