"""Where ``imu-learn calibrate``'s recordings come from: one source per reference kind, each reading
its inputs into calibration recordings (:class:`Recording`, gathered in :class:`CalibInputs`),
saying what profile.json records of them (``sources``, ``reference``, ``observed``) and fitting the
floor they observe.

* :class:`PosesSource`: a 6-DoF reference in any frame (``--input``, with ``--groundtruth`` or the
  format's own ground truth): checked against the IMU and moved into its frame
  (:func:`imu_learn.calib.reference.resolve_frame`, :func:`~imu_learn.calib.reference.to_imu_frame`),
  aligned onto the IMU stamps, the last ``val_fraction`` of each recording held back; a reference whose
  velocity cannot resolve accelerations (a 20 Hz VO) gives the accelerometer from its positions
  (:mod:`imu_learn.calib.acc_positions`); against a reference two or more IMU periods apart the floor
  sees the IMU through the reference's slerp (:func:`interpolation_kernel`).
* :class:`ConfigSource`: a fit or evaluate config's train/val split, with evaluate's settings.
* :class:`StillSource`: recordings without a reference (``--imu-only``): the noise of their still
  stretches only.
* :class:`imu_learn.fuse.calibrate_positions.PositionsSource`: positions only (GNSS); the navigator's smoother
  makes the reference and fits the bias-only floor (it lives beside that loop).
* :class:`imu_learn.calib.odometry.OdometrySource`: planar wheel odometry (kind ``odometry``): the yaw
  rate only, the gyro bias and scale about the IMU's vertical axis (it lives beside its fit).

A new reference kind is a new :class:`Source`: :meth:`Source.read` yields its recordings; where the
affine fit against them (:func:`imu_learn.calib.fit.fit_floor`, with :meth:`Source.floor_terms`) is
not the floor it observes, it overrides :meth:`Source.fit_floor`, and says what its reference was
(:meth:`Source.reference`) and what it observed (:meth:`Source.observed`).
:func:`imu_learn.calib.run.calibrate` does the rest (gravity, the noise, the plausibility, the files)
the same for every kind.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.baselines.base import FitSettings
from imu_learn.calib import fit as ff
from imu_learn.calib.acc_positions import BIAS_TERMS, AccFit, AccOptions, fit_acc_from_positions, recording_spread
from imu_learn.calib.frames import default_gap_s
from imu_learn.calib.profile import FloorFit
from imu_learn.calib.reference import (
    ROTATION_FROM_RATES,
    FrameFit,
    FrameOptions,
    frame_lines,
    read_extrinsics,
    resolve_frame,
    to_imu_frame,
)
from imu_learn.core.still import StillSettings, moving_mean, moving_std
from imu_learn.data.formats import USER_CSV, detect_format, read_imu_source, read_recording, user_csv
from imu_learn.data.loading import AlignOptions, align
from imu_learn.data.splits import cut, recording_name
from imu_learn.data.types import Segment, median_period_ns
from imu_learn.errors import ConfigError
from imu_learn.infer.rates import recording_device

Progress = Callable[[str], None]

TRAIN, VAL, NOISE = "train", "val", "noise"  # a recording's role
TIME_OFFSET_PRIOR_SAMPLES = 0.5  # an unobserved time offset: the zero-order hold's half sample
ACC_MAX_SCALE_STD = 0.02  # the positions' fit of the accelerometer is kept where its scales are this certain
MATCH_MIN_PERIODS = 2.0  # a reference this many IMU periods apart or more: the floor sees the IMU through its slerp
# profile.json's ``observed``: the floor's parameters a reference may or may not observe
# calibrate's options of navigate's names for a positions reference (its module reads them; the CLI refuses
# them with another kind before importing it)
NAVIGATOR_OPTIONS = ("imu_rotation_rpy_deg", "imu_delay_s", "lever_arm")
OBSERVABLE = ("time_offset", "gyroscope.matrix", "gyroscope.bias", "g_sensitivity", "accelerometer.matrix",
              "accelerometer.bias", "cutoff_gyro", "cutoff_acc")

log = logging.getLogger(__name__)


@dataclass
class StillPiece:
    """IMU samples of a recording without a reference (gap-free)."""

    name: str
    t_ns: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray


# a reference's frame rotation estimated from the rotation rates takes the gyroscope's misalignment rotation
# with it (Blackbird against its motion capture made into a camera's poses: the estimate 0.75 deg off the
# true rotation, the motion-capture profile's gyro rotation 0.67 deg the other way); profile.json says so
GYRO_ROTATION_WITH_FRAME = (
    "its scales and non-orthogonality only: the rotation between the reference's frame and the IMU's was "
    "estimated from the same rotation rates ({deg:.1f} deg, +-{std:.2f}), which takes the gyroscope's misalignment "
    "rotation with it; the profile keeps the gyroscope's own axes as the IMU's frame (--extrinsics with a "
    "calibrated rotation ties it to that rotation's frame instead)")


@dataclass
class Recording:
    """One block of a recording as calibrate uses it: ``name`` (the recording, as profile.json's
    ``sources`` name it; the group the floor's spread is taken over), ``role`` (``train``: fitted;
    ``val``: held back, selects the floor's filter and offset and judges it; ``noise``: the IMU alone,
    its still stretches), its ``segments`` (the reference on the IMU stamps; :class:`StillPiece` for
    ``noise``), the reference ``kind`` (``poses``, ``positions``, ``odometry``, ``none``) and what that reference
    observes (``observes``: the keys of :data:`OBSERVABLE` it resolves; the noise always)."""

    name: str
    role: str
    segments: List[Any]
    kind: str = "poses"
    observes: Tuple[str, ...] = OBSERVABLE


def blocks(segments: Sequence[Any], names: Sequence[str], role: str, kind: str = "poses",
           observes: Tuple[str, ...] = OBSERVABLE) -> List[Recording]:
    """``segments`` (each of the recording ``names[i]``) as recordings of ``role``, consecutive
    segments of one recording together."""
    out: List[Recording] = []
    for s, n in zip(segments, names):
        if out and out[-1].name == n:
            out[-1].segments.append(s)
        else:
            out.append(Recording(n, role, [s], kind, observes))
    return out


class CalibInputs:
    """What calibrate fits: the recordings a :class:`Source` yielded, the floor's settings, the device,
    profile.json's ``sources`` entries and the source itself (its floor, reference and observed).
    ``seconds``: work the source already did while reading (a floor it fitted then).

    The older form, parallel lists (``train``/``val`` segments with the recording of each in
    ``groups``/``val_groups``, IMU-only pieces), gives the same recordings; ``train``, ``val``,
    ``groups``, ``val_groups`` and ``imu_only`` are derived from the recordings."""

    def __init__(self, train: Sequence[Segment] = (), val: Sequence[Segment] = (), groups: Sequence[str] = (),
                 val_groups: Sequence[str] = (), imu_only: Sequence[StillPiece] = (),
                 settings: FitSettings = FitSettings(), device: str = "unknown",
                 sources: Optional[List[Dict[str, Any]]] = None, *, recordings: Optional[Sequence[Recording]] = None,
                 source: Optional[Source] = None, seconds: float = 0.0) -> None:
        if recordings is None:
            recordings = (blocks(train, groups, TRAIN) + blocks(val, val_groups, VAL)
                          + [Recording(p.name, NOISE, [p], "none", ()) for p in imu_only])
        self.recordings: List[Recording] = list(recordings)
        self.settings = settings
        self.device = device
        self.sources: List[Dict[str, Any]] = list(sources or [])
        self.source: Source = source if source is not None else Source()
        self.seconds = seconds

    def _of(self, role: str) -> List[Recording]:
        return [r for r in self.recordings if r.role == role]

    @property
    def train(self) -> List[Segment]:
        return [s for r in self._of(TRAIN) for s in r.segments]

    @property
    def val(self) -> List[Segment]:
        return [s for r in self._of(VAL) for s in r.segments]

    @property
    def groups(self) -> List[str]:
        return [r.name for r in self._of(TRAIN) for _ in r.segments]

    @property
    def val_groups(self) -> List[str]:
        return [r.name for r in self._of(VAL) for _ in r.segments]

    @property
    def imu_only(self) -> List[StillPiece]:
        return [p for r in self._of(NOISE) for p in r.segments]

    @property
    def has_reference(self) -> bool:
        return bool(self.train)


class Source:
    """A reference kind (module doc). This base reads nothing (its recordings are given) and fits the
    affine floor against them, every parameter observed, the reference as given."""

    kind = "poses"

    def read(self, progress: Progress = lambda s: None) -> CalibInputs:
        raise NotImplementedError(f"{type(self).__name__}.read")

    def floor_terms(self) -> Dict[str, Any]:
        """:func:`imu_learn.calib.fit.fit_once`'s ``terms``: what the floor may fit (all: none given)."""
        return {}

    def fit_floor(self, inp: CalibInputs, progress: Progress = lambda s: None, uncertainty: bool = True) -> FloorFit:
        """The floor against ``inp``'s recordings and its spread between them (``uncertainty=False``: no
        refits, the standard deviations NaN)."""
        return ff.fit_floor(inp.train, inp.val, inp.settings, inp.groups, inp.val_groups, progress, uncertainty,
                            self.floor_terms())

    def reference(self) -> Dict[str, Any]:
        """profile.json's ``reference`` entry (empty: the reference as given)."""
        return {}

    def band_limit(self) -> Optional[str]:
        """Why the residuals against this reference cannot measure the IMU's white noise (None: they can).
        A reference smoothed below the IMU's rate leaves the motion above its band in the residuals, sample
        by sample: their white noise is a bound, not the IMU's (:func:`imu_learn.calib.noise.candidates`)."""
        return None

    def observed(self) -> Dict[str, Dict[str, Any]]:
        """profile.json's ``observed``: per floor parameter, whether the reference observed it, and why not."""
        return {k: {"observed": True} for k in OBSERVABLE}

    def observes(self) -> Tuple[str, ...]:
        return tuple(k for k, o in self.observed().items() if o.get("observed"))


def interpolation_kernel(ref_period_s: float, imu_period_s: float) -> np.ndarray:
    """What interpolating a reference sampled every ``ref_period_s`` does to the motion, on the IMU's
    samples: a triangle of half-width one reference period, unit sum (odd length; ``[1]`` where the
    reference is as dense as the IMU).

    Slerp between poses h apart reproduces a component of frequency f, averaged over where the IMU's
    stamps fall between the poses, with gain sinc²(f h): the triangle's transform. The rest is aliased
    content, uncorrelated with the motion. A rotation fitted against such a reference compares the
    IMU's rates with rates the reference has low-passed, and the gyro's scale comes out low by the
    motion's weighted 1 − sinc²(f h) (EuRoC at 20 Hz: 0.1-0.4 %, most on the axes that roll and pitch);
    the same triangle on the IMU's side compares like with like."""
    r = float(ref_period_s) / float(imu_period_s)
    if not r >= MATCH_MIN_PERIODS:
        return np.ones(1)
    k = np.arange(-math.ceil(r) + 1, math.ceil(r))
    w = np.clip(1.0 - np.abs(k) / r, 0.0, None)
    return w / w.sum()


def smoothed(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``x`` (N, C) convolved with the odd, symmetric ``kernel`` along time (no delay), the ends
    padded with their edge values."""
    h = len(kernel) // 2
    if h == 0:
        return x
    xp = np.pad(np.asarray(x, dtype=np.float64), ((h, h), (0, 0)), mode="edge")
    return np.stack([np.convolve(xp[:, c], kernel, mode="valid") for c in range(xp.shape[1])], axis=1)


def matched(inp: CalibInputs, kernel: np.ndarray) -> CalibInputs:
    """``inp`` with each segment's gyro and accelerometer smoothed by ``kernel`` (the floor fitted on it
    applies to the raw IMU: every term of the floor but its low-pass and offset is linear in them)."""
    recs = [replace(r, segments=[replace(s, gyro=smoothed(s.gyro, kernel), acc=smoothed(s.acc, kernel))
                                 for s in r.segments]) if r.role in (TRAIN, VAL) else r for r in inp.recordings]
    return CalibInputs(recordings=recs, settings=inp.settings, device=inp.device, sources=inp.sources,
                       source=inp.source, seconds=inp.seconds)


def under_root(path: Any, root: Optional[Path]) -> Any:
    """A recording's path relative to the data root when it lies under it (a profile names recordings
    as a user's data root does, not as this machine's folders)."""
    if isinstance(path, str) and root is not None and Path(path).is_absolute():
        try:
            return str(Path(path).resolve().relative_to(Path(root).resolve()))
        except ValueError:
            return path
    return path


def device_name(fmt: str, name: str) -> str:
    """The device a recording's format belongs to (a one-device dataset), else the recording's name."""

    return recording_device(fmt) or recording_name(name)


def span(s: Any) -> Dict[str, Any]:
    """profile.json's entry of a segment used."""
    return {"segment": s.name, "t0_ns": int(s.t_ns[0]), "t1_ns": int(s.t_ns[-1]), "samples": len(s)}


MOVING_SHARE = 0.5  # a block moves where at least this share of its samples does (:func:`moves`)


def moves(segments: Sequence[Segment], center: Optional[np.ndarray] = None) -> bool:
    """Whether a block moves enough to select a floor's filter and offset and to judge it: at least
    :data:`MOVING_SHARE` of its samples move, a sample moving where over the 1 s around it the gyro's or the
    accelerometer's standard deviation on some axis, or the gyro's mean less ``center`` (the recording's
    median gyro: a raw gyro's bias, EuRoC's 0.08 rad/s on z, is not a turn; None: zero), is at least the
    still detector's caps (:class:`imu_learn.core.still.StillSettings`: 0.05 rad/s, 0.5 m/s²)."""
    caps = StillSettings()
    c = np.zeros(3) if center is None else np.asarray(center, dtype=np.float64)
    n_moving, n_all = 0, 0
    for x in segments:
        if len(x) < 3:
            continue
        w = max(2, int(round(caps.window_s / (median_period_ns(x.t_ns) * 1e-9))))
        # the still detector's own spreads; a segment shorter than the window has none (inf there): not moving
        sd = [np.where(np.isfinite(v), v, 0.0) for v in (moving_std(x.gyro, w).max(1), moving_std(x.acc, w).max(1))]
        mean = np.abs(moving_mean(x.gyro, w) - c).max(1)
        n_moving += int(((sd[0] >= caps.gyro_cap) | (sd[1] >= caps.acc_cap) | (mean >= caps.gyro_cap)).sum())
        n_all += len(x)
    return n_all > 0 and n_moving >= MOVING_SHARE * n_all


def held_back(segments: List[Segment], frac: float) -> Tuple[List[Segment], List[Segment]]:
    """The fitted and the held-back block: the last ``frac`` of the recording (0: nothing held back), or,
    where that block does not move (:func:`moves`: a recording that ends at rest, BROAD's trial 18, whose
    still last 15 % chose a 5 Hz filter and judged the profile on bias drift alone), the latest block of
    ``frac`` that does, stepping back by half a block (the fitted part then the time before and after it);
    none moving: the last, with a warning."""
    if frac <= 0:
        return list(segments), []
    name = recording_name(segments[0].name)
    center = np.median(np.concatenate([x.gyro for x in segments]), axis=0)
    step = frac / 2
    for k in range(int(math.floor((1.0 - frac) / step + 1e-9)) + 1):
        a = 1.0 - frac - k * step
        held = cut(segments, a, a + frac, name)
        if moves(held, center):
            if k:
                log.info("%s: its last %g %% does not move; held back %.3g-%.3g of it instead", name, 100 * frac, a,
                         a + frac)
            return cut(segments, 0.0, a, name) + (cut(segments, a + frac, 1.0, name) if k else []), held
    log.warning("%s: no block of %g %% of it moves: the last is held back, but it can neither select the filter "
                "and offset nor judge the profile; give --val-fraction 0 to select on the training windows",
                name, 100 * frac)
    return cut(segments, 0.0, 1.0 - frac, name), cut(segments, 1.0 - frac, 1.0, name)


def _name(path: Path) -> str:
    return path.stem if path.is_file() else path.name


def _check_exist(paths: Sequence[Optional[Path]]) -> None:
    for path in paths:
        if path is not None and not path.exists():
            raise FileNotFoundError(2, "No such file or directory", str(path))


def _format(path: Path, fmt: str, columns: Any) -> str:

    return USER_CSV if user_csv(fmt, columns) is not None else fmt if fmt != "auto" else detect_format(path)


class PosesSource(Source):
    """6-DoF poses in any frame (module doc): ``inputs`` with their ``groundtruths`` (None: the format's
    own), the reference's known ``extrinsics`` (a Kalibr/EuRoC yaml; None: estimated), reference gaps
    longer than ``max_gap_s`` split (None: 0.05 s, or 1.5 periods of a sparse reference), the last
    ``val_fraction`` of each recording held back; ``acc_options``: how a reference whose velocity cannot
    resolve accelerations (a 20 Hz VO) fits the accelerometer from its positions
    (:meth:`acc_from_positions`; None: the acc bias only, M_a = I)."""

    kind = "poses"

    def __init__(self, inputs: Sequence[Path], groundtruths: Sequence[Optional[Path]] = (), fmt: str = "auto",
                 columns: Any = None, extrinsics: Optional[Path] = None, max_gap_s: Optional[float] = None,
                 val_fraction: float = 0.15, device: Optional[str] = None,
                 topics: Optional[Dict[str, Optional[str]]] = None,
                 acc_options: Optional[AccOptions] = AccOptions(fit_tilt=True), match_interpolation: bool = True) -> None:
        self.inputs = [Path(p) for p in inputs]
        self.topics = {k: v for k, v in (topics or {}).items() if v}  # a bag's imu_topic / groundtruth_topic
        gts = [None if g is None else Path(g) for g in groundtruths]
        if len(gts) > len(self.inputs):
            raise ConfigError(f"--groundtruth: {len(gts)} given for {len(self.inputs)} --input")
        self.groundtruths: List[Optional[Path]] = gts + [None] * (len(self.inputs) - len(gts))
        self.fmt, self.columns, self.extrinsics = fmt, columns, extrinsics
        self.max_gap_s, self.val_fraction, self.device = max_gap_s, val_fraction, device
        self.frame: Optional[FrameFit] = None  # how the reference was moved into the IMU's frame
        # the accelerometer from the positions where the velocity cannot resolve it (None: bias only)
        self.acc_options: Optional[AccOptions] = acc_options
        self.acc_fit: Optional[AccFit] = None
        self.acc_refused = ""
        # the floor fitted on the IMU smoothed as the reference's interpolation smooths the motion
        # (:func:`interpolation_kernel`; only a reference MATCH_MIN_PERIODS IMU periods apart or more)
        self.match_interpolation = match_interpolation

    def read(self, progress: Progress = lambda s: None) -> CalibInputs:
        """The recordings read, their reference checked against the IMU and moved into its frame, then
        cut into the fitted and the held-back block."""

        _check_exist([*self.inputs, *self.groundtruths, self.extrinsics])
        extrinsics = read_extrinsics(self.extrinsics) if self.extrinsics else None
        pairs, names, sources, fmts = [], [], [], []
        for path, gt in zip(self.inputs, self.groundtruths):
            fmts.append(_format(path, self.fmt, self.columns))
            pairs.append(read_recording(path, self.fmt, gt, columns=self.columns, **self.topics))
            names.append(_name(path))
            sources.append({"recording": str(path), "format": fmts[-1], "groundtruth": str(gt) if gt else "the format's own"})
        progress("checking the reference against the IMU (frame, lag, gravity, scale)")
        self.frame = resolve_frame(pairs, FrameOptions(), extrinsics, self.max_gap_s, names)
        for line in frame_lines(self.frame):
            progress(line)
        observes = self.observes()
        recordings: List[Recording] = []
        for i, ((imu, ref), name, source) in enumerate(zip(pairs, names, sources)):
            ref = to_imu_frame(ref, self.frame, i)
            gap = self.max_gap_s if self.max_gap_s is not None else default_gap_s(ref)
            segs = align(imu, ref, AlignOptions(max_gap_s=gap), name=name).segments
            tr, va = held_back(segs, self.val_fraction)
            recordings += [Recording(source["recording"], role, part, self.kind, observes)
                           for role, part in ((TRAIN, tr), (VAL, va)) if part]
            source.update({"max_gap_s": gap, "train": [span(s) for s in tr], "val": [span(s) for s in va]})
        inp = CalibInputs(recordings=recordings, settings=FitSettings(), sources=sources, source=self)
        inp.device = self.device or device_name(fmts[0] if fmts else "auto", inp.train[0].name if inp.train else names[0])
        return inp

    def band_limit(self) -> Optional[str]:
        if self.frame is None or self.frame.resolves_acceleration:
            return None
        return "a reference that cannot resolve accelerations (a 20-30 Hz VO): its residuals hold the motion above its band"

    def floor_terms(self) -> Dict[str, Any]:
        """Everything, or (a reference that cannot resolve accelerations,
        :func:`imu_learn.calib.reference.resolves_acceleration`) no low-pass and the acc bias only, M_a
        held at the identity; the acc bias only too on a reference whose scale was estimated
        (:meth:`acc_matrix_unobserved`)."""
        if self.frame is None or (self.frame.resolves_acceleration and not self.acc_matrix_unobserved()):
            return {}
        if self.frame.resolves_acceleration:
            return {"held": ("acc",)}
        return {"cutoffs_hz": (None,), "held": ("acc",)}

    def acc_matrix_unobserved(self) -> str:
        """Why the accelerometer's matrix cannot be fitted against this reference ("": it can): its metric
        scale was estimated from this same accelerometer and applied (a monocular VO). The positions'
        scale then carries the scale estimate's error (1.5-3 % on VO-like references,
        docs/experiments/references.md), which the accelerometer's scales would take up, and along a
        multirotor's thrust axis the bias with them (ORB-SLAM2's poses x0.4: acc x scale 0.972, bias
        -0.26 m/s^2 against -0.03 from the metric poses); the bias alone, the matrix at the identity, averages
        that error out over the motion."""
        ref = self.frame
        if ref is None or not ref.applied.get("scale"):
            return ""
        return (f"the reference's scale was estimated from this accelerometer (x{ref.scale:.4g} ± {ref.scale_std:.2g}) "
                "and applied: the accelerometer's scales and misalignment cannot be told apart from that estimate's "
                "error; kept at the prior (identity), the bias fitted")

    def fit_floor(self, inp: CalibInputs, progress: Progress = lambda s: None, uncertainty: bool = True) -> FloorFit:
        """The affine floor; on a reference whose stamps were moved by its own lag, the time offset kept
        at its prior (what the fit finds on top is the IMU's offset plus the lag's rounding, not
        observable apart from the reference's latency): the zero-order hold's half sample
        (:data:`TIME_OFFSET_PRIOR_SAMPLES`, what an IMU on the reference's clock shows: a sample holds
        the rate at its start over the interval after it). Against a sparse reference the floor is fitted
        on the IMU smoothed as the reference's slerp smooths the motion (:func:`interpolation_kernel`,
        :meth:`match_kernel`; unsmoothed, a 20 Hz reference's gyro scales come out 0.1-0.4 % low), and
        applies to the raw IMU. On a reference whose velocity cannot
        resolve accelerations, the accelerometer's (M_a, b_a) then come from its positions
        (:meth:`acc_from_positions`)."""
        kernel = self.match_kernel(inp)
        if len(kernel) > 1:
            progress(f"the floor sees the IMU through the reference's interpolation (a triangle of "
                     f"{len(kernel) // 2} IMU samples each side, the reference's period)")
            fit = super().fit_floor(matched(inp, kernel), progress, uncertainty)
            fit.log["imu_matched_to_the_reference_interpolation"] = [{"kernel_half_width_samples": len(kernel) // 2,
                                                                     "reference_rate_hz": self.frame.rate_hz}]
        else:
            fit = super().fit_floor(inp, progress, uncertainty)
        if self.frame is not None and self.frame.applied.get("lag"):
            fit.log["time_offset_fitted_on_the_moved_reference"] = [fit.floor.params.time_offset]
            fit.floor = fit.floor.with_params(time_offset=TIME_OFFSET_PRIOR_SAMPLES)
            fit.std = replace(fit.std, time_offset=np.float64(np.nan))
        if self.floor_terms():  # the bias-only accelerometer: its matrix held at the identity, its spread unknown
            fit.std = replace(fit.std, M_a=np.full((3, 3), np.nan))
        if self.frame is not None and not self.frame.resolves_acceleration and self.acc_options is not None:
            fit = self.acc_from_positions(inp, fit, progress, uncertainty)
        return fit

    def match_kernel(self, inp: CalibInputs) -> np.ndarray:
        """The reference's interpolation on the IMU's samples (:func:`interpolation_kernel`; ``[1]``: a
        reference as dense as the IMU, or ``match_interpolation`` off)."""
        if self.frame is None or not self.match_interpolation or not inp.train:
            return np.ones(1)
        imu_period = float(np.median([np.median(np.diff(s.t_ns)) for s in inp.train])) * 1e-9
        return interpolation_kernel(1.0 / self.frame.rate_hz, imu_period)

    def acc_from_positions(self, inp: CalibInputs, fit: FloorFit, progress: Progress = lambda s: None,
                           uncertainty: bool = True) -> FloorFit:
        """The accelerometer's matrix and bias from the reference's positions
        (:func:`imu_learn.calib.acc_positions.fit_acc_from_positions`: second differences over a long
        baseline, no velocity; the lever arm to the reference's origin and each world's tilt jointly;
        the attitude within a baseline the floor's calibrated gyro, held to the reference's over
        ``attitude_smooth_s``), at the floor's time offset, in place of the floor's bias-only fit (kept in the log). Refused
        (the bias-only floor kept, and said why) where the motion leaves a scale's standard error above
        :data:`ACC_MAX_SCALE_STD`. The standard deviations, as the floor's: the spread of the fit on each
        recording alone over sqrt(recordings); the cluster-robust ones of the joint fit in the reference
        entry."""
        _names, recs, gyros = self.positions_data(inp, fit.floor)
        tau = float(fit.floor.params.time_offset)
        opts = self.acc_options
        assert opts is not None
        progress(f"accelerometer from the reference's positions (second differences over +-{opts.baseline_s:g} s)"
                 + (", the bias alone: the reference's scale was estimated" if self.acc_matrix_unobserved() else ""))
        free = BIAS_TERMS if self.acc_matrix_unobserved() else None
        try:
            acc = fit_acc_from_positions(recs, opts, tau, inp.settings.gravity, gyros, free)
        except ValueError as e:
            self.acc_refused = str(e)
            return fit
        worst = float(np.max(np.diag(acc.M_a_std)))
        if not worst <= ACC_MAX_SCALE_STD:
            self.acc_refused = (f"the motion leaves the accelerometer's scale uncertain from the positions "
                                f"(standard error up to {worst:.3g}, limit {ACC_MAX_SCALE_STD:g})")
            progress(f"accelerometer from positions refused: {self.acc_refused}")
            return fit
        self.acc_fit = acc
        fit.log["accelerometer_bias_only_fit"] = [{"M_a": fit.floor.params.M_a.tolist(), "b_a": fit.floor.params.b_a.tolist()}]
        fit.floor = fit.floor.with_params(M_a=acc.M_a, b_a=acc.b_a)
        if uncertainty:
            sp = recording_spread(recs, opts, tau, inp.settings.gravity, gyros, free)
            m_std, b_std = (sp[0], sp[1]) if sp is not None else (acc.M_a_std, acc.b_a_std)
            if free is not None:  # the matrix held at its prior: no spread
                m_std = np.full((3, 3), np.nan)
            fit.std = replace(fit.std, M_a=m_std, b_a=b_std)
        progress("accelerometer from positions: scales " + ", ".join(f"{x:.4f}" for x in np.diag(acc.M_a))
                 + " (± " + ", ".join(f"{x:.4f}" for x in np.diag(acc.M_a_std)) + "), reference origin ("
                 + ", ".join(f"{100 * x:+.1f}" for x in acc.lever_m) + ") cm in the IMU frame")
        return fit

    @staticmethod
    def positions_data(inp: CalibInputs, floor: Any) -> Tuple[List[str], List[List[Segment]], List[List[np.ndarray]]]:
        """The training segments per recording (their names, segments, and the gyro ``floor`` calibrates:
        the attitude within a baseline), as :func:`fit_acc_from_positions` takes them."""
        per: Dict[str, List[Segment]] = {}
        rates: Dict[str, List[np.ndarray]] = {}
        for s, g in zip(inp.train, inp.groups):
            per.setdefault(g, []).append(s)
            rates.setdefault(g, []).append(floor.apply(s.t_ns, s.gyro, s.acc)[0])
        return list(per), list(per.values()), list(rates.values())

    def reference(self) -> Dict[str, Any]:
        out = self.frame.to_dict() if self.frame is not None else {}
        if self.acc_fit is not None:
            out["accelerometer_from_positions"] = self.acc_fit.to_dict()
        return out

    def observed(self) -> Dict[str, Dict[str, Any]]:
        out = super().observed()
        ref = self.frame
        if ref is not None and not ref.resolves_acceleration:
            why = (f"the reference at {ref.rate_hz:.3g} Hz: its velocity, smoothed over several of its poses, "
                   "attenuates the accelerations the fit needs, so it would scale the accelerometer down and choose "
                   "a low-pass the IMU does not need; kept at the prior (identity, no filter)")
            for k in ("accelerometer.matrix", "cutoff_gyro", "cutoff_acc"):
                out[k] = {"observed": False, "why": why}
            if self.acc_refused:
                out["accelerometer.matrix"] = {"observed": False, "why": why + "; from its positions: " + self.acc_refused}
        if ref is not None and ref.applied.get("rotation") and ref.method == ROTATION_FROM_RATES:
            out["gyroscope.matrix"] = {"observed": True, "partly": GYRO_ROTATION_WITH_FRAME.format(
                deg=ref.rotation_deg, std=ref.rotation_std_deg)}
        if ref is not None and ref.applied.get("level"):
            out["accelerometer.bias"] = {
                "observed": True, "partly": "along gravity only: across it the bias and the tilt of the reference's "
                f"world (levelled by calibrate, {ref.tilt_deg:.1f}° off) are one and the same unless the attitude "
                "varies widely; the levelling absorbs part of it (0.1 m/s^2 is 0.6° of tilt)"}
        if self.acc_fit is not None:
            how = ("from the reference's positions, not its velocity: second differences over +-"
                   f"{self.acc_fit.options.baseline_s:g} s (reference.accelerometer_from_positions)")
            out["accelerometer.matrix"] = {"observed": True, "how": how}
            if self.acc_fit.options.fit_tilt:
                out["accelerometer.bias"] = {"observed": True, "how": how + "; each recording's world tilt fitted "
                                             "with it (told apart from the bias by the attitude's changes of heading)"}
        if self.acc_matrix_unobserved():
            out["accelerometer.matrix"] = {"observed": False, "why": self.acc_matrix_unobserved()}
        if ref is not None and ref.applied.get("lag"):
            out["time_offset"] = {"observed": False, "why": f"the reference's stamps were {ref.lag_s * 1e3:+.0f} ms "
                                  "off the IMU's; the IMU's own offset cannot be told apart from the reference's latency: "
                                  "the prior, the zero-order hold's half sample"}
        return out


class StillSource(Source):
    """Recordings without a reference (``--imu-only``): the IMU alone, the noise of its still stretches."""

    kind = "none"

    def __init__(self, inputs: Sequence[Path], fmt: str = "auto", columns: Any = None,
                 device: Optional[str] = None) -> None:
        self.inputs, self.fmt, self.columns, self.device = [Path(p) for p in inputs], fmt, columns, device

    def read(self, progress: Progress = lambda s: None) -> CalibInputs:
        _check_exist(self.inputs)
        recordings, sources, fmts = [], [], []
        for path in self.inputs:
            fmts.append(_format(path, self.fmt, self.columns))
            piece = imu_piece(path, self.fmt, self.columns)
            recordings.append(Recording(piece.name, NOISE, [piece], self.kind, ()))
            sources.append({"recording": str(path), "format": fmts[-1], "role": "noise (IMU only)"})
        device = self.device or device_name(fmts[0] if fmts else "auto", recordings[0].name)
        return CalibInputs(recordings=recordings, device=device, sources=sources, source=self)

    def observed(self) -> Dict[str, Dict[str, Any]]:
        return {}


def imu_piece(path: Path, fmt: str, columns: Any = None) -> StillPiece:
    """A recording's IMU alone (a layout without stamps of its own, BROAD, reads them with its ground truth)."""

    src = read_imu_source(path, fmt, columns=columns)
    if src.t_ns is not None:
        return StillPiece(_name(path), src.t_ns, src.gyro, src.acc)
    imu, _ = read_recording(path, fmt)
    return StillPiece(path.stem, imu.t_ns, imu.gyro, imu.acc)
