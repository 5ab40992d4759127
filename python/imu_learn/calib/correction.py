"""The correction plan: one way to apply what the user passed (a device profile's floor, a model with
the profile it carries, or a fit ``imu-learn evaluate`` saved) to a recording's IMU, with the same
checks in the same order; ``imu-learn refine`` and ``imu-learn navigate`` both use it.

1. :func:`build` loads what was passed (before the recording is read: a bad file is refused first):
   ``--profile``'s floor; ``--checkpoint``'s model after the profile it carries (once: a model with
   ``model_args["start"] == "profile"`` holds that floor itself, :func:`imu_learn.infer.checkpoint.imu_record`'s
   ``profile_in_model``, and nothing applies it before the model); ``--calibration``'s saved fit.
   A profile given only for its noise (navigate with a model) is checked, not applied.
2. :func:`check`: the recording's stamps where a step needs them, then its rate and device against
   what each of them was made for (:mod:`imu_learn.infer.rates`: more than 5 % off stops in one line
   unless ``force``; another device is a warning line; what cannot be checked an info line).
3. :meth:`Plan.apply`: the steps in order, in the IMU's own frame: (gyro, acc, per-sample variances
   of a covariance head or None).
4. :func:`guard_entry`: the input guard (:mod:`imu_learn.infer.guard`) on the recording as read and
   on what the model added to it.

:func:`correct` runs 2-4 and returns the corrected samples with a summary (what was applied, what
it was made for, the recording's rate and device, the guard's verdict). torch is imported only for
a checkpoint.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from imu_learn.baselines.registry import REGISTRY, load_method_class
from imu_learn.calib.plausible import applied_floor_finding
from imu_learn.calib.profile import Profile
from imu_learn.core.still import MEMS_PRIOR, BiasPrior
from imu_learn.data.types import Segment, sample_rate_hz
from imu_learn.errors import ConfigError, ImplausibleProfileError, InvalidInputError
from imu_learn.infer import guard, rates
from imu_learn.infer.rewrite import Step, measured
from imu_learn.util.extras import require_extra

logger = logging.getLogger(__name__)

# Variances of a covariance head: never asked for, taken when the model has a head, or required
# (refine --fill-covariance: a model without a head is refused before the recording is read).
VARIANCE = ("never", "if-head", "required")


@dataclass(frozen=True)
class Request:
    """What the user passed: ``profile`` (its floor applied), ``checkpoint``, ``calibration`` (a fit
    ``imu-learn evaluate`` saved), at most one of them; ``noise_profile`` a profile used for its noise
    only (checked, not applied); ``force`` applies one made for another rate; the model's ``device``,
    windowing overrides, progress bar and ``variance`` (one of :data:`VARIANCE`); ``command`` for messages."""

    profile: Optional[Path] = None
    checkpoint: Optional[Path] = None
    calibration: Optional[Path] = None
    noise_profile: Optional[Path] = None
    force: bool = False
    device: str = "cpu"
    window: Optional[int] = None
    overlap: Optional[int] = None
    batch: Optional[int] = None
    progress: bool = False
    variance: str = "never"
    command: str = "imu-learn refine"  # names the command in the missing-extra line


@dataclass
class Recording:
    """The recording's IMU as read: ``name`` names it in messages (the input path), ``fmt`` the layout
    it was read as, ``given_format`` the ``--format`` asked for, ``imu_name`` its device if given,
    ``gyro_unit`` the unit a user's CSV declared for its gyro columns (None: the format fixes it)."""

    name: str
    t_ns: Optional[np.ndarray]
    gyro: np.ndarray
    acc: np.ndarray
    fmt: str = ""
    given_format: str = "auto"
    imu_name: Optional[str] = None
    gyro_unit: Optional[str] = None

    @property
    def device(self) -> Optional[str]:
        return rates.recording_device(self.fmt, self.given_format, self.imu_name)


@dataclass
class Plan:
    """What is applied: the steps in order, what they were made for (rate and device), the words of
    the summary line, and whether a step needs the recording's stamps (a profile's time offset)."""

    steps: List[Step] = field(default_factory=list)
    made_for: List[rates.MadeFor] = field(default_factory=list)
    words: List[str] = field(default_factory=list)
    needs_stamps: bool = False
    stamps_for: str = "a profile's time offset"  # what needs them, for the message
    training: Optional[Dict[str, Any]] = None  # the statistics of the training data (guard), None: not recorded
    gravity: float = 9.80665  # [m/s^2] for the still detector's norm check (a profile's own when it has one)
    prior: BiasPrior = MEMS_PRIOR  # the device's bias spread after the steps (a profile's, else a MEMS gyro's)
    measured: Dict[str, Any] = field(default_factory=dict)  # what the steps measure as they run
    what: str = "nothing"  # the guard's name for what is applied ("model X", "profile X")
    corrects: bool = True  # False: a noise-only profile, whose steps pass the readings unchanged
    kind: str = "raw"  # raw, profile, checkpoint, calibration
    covariance: bool = False  # the steps return a covariance head's per-sample variances
    model_profile: str = "none"  # a checkpoint's profile: none, applied (before the model), in-model (held by it)

    def apply(self, t_ns: Optional[np.ndarray], gyro: np.ndarray,
              acc: np.ndarray) -> Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
        """(gyro, acc, variances or None): the samples through every step in order (a step of its own)."""
        var = None
        for step in self.steps:
            gyro, acc, v = step(t_ns, gyro, acc)
            var = v if v is not None else var
        return gyro, acc, var


@dataclass
class Corrected:
    """The corrected samples (IMU frame), a covariance head's variances or None, the summary entry."""

    gyro: np.ndarray
    acc: np.ndarray
    var: Optional[np.ndarray]
    summary: Dict[str, Any]


# -- building the plan -----------------------------------------------------------------------------


def profile_step(profile: Profile) -> Step:
    def step(t_ns, gyro, acc):
        g, a = profile.apply(t_ns, gyro, acc)
        return g, a, None

    return step


def describe_profile(profile: Profile, where: str) -> str:
    return f"profile {where} (device {profile.device!r}, {rates.hz(profile.sample_rate_hz)})"


def _prior(profile: Profile, where: str) -> BiasPrior:
    """The device prior after ``profile``'s floor: zero mean, its gyroscope's bias spread between
    recordings (:meth:`Profile.gyro_bias_prior_std`)."""
    std, how = profile.gyro_bias_prior_std()
    return BiasPrior.from_bias_std(std, f"the bias spread of profile {where} ({how})", measured=profile.bias_prior)


def _gravity(profile: Profile, default: float) -> float:
    g = profile.gravity_mps2
    return float(g) if g is not None and g == g and g > 0 else default


def build(req: Request) -> Plan:
    """The plan of ``req`` (module doc, step 1)."""
    given = [x for x in (req.profile, req.checkpoint, req.calibration) if x is not None]
    if len(given) > 1:
        raise ConfigError("--profile's floor, --checkpoint and --calibration each correct the IMU: pass one")
    if req.variance not in VARIANCE:
        raise ConfigError(f"variance: one of {', '.join(VARIANCE)}, got {req.variance!r}")
    if req.variance == "required" and req.checkpoint is None:
        raise ConfigError("--fill-covariance needs a --checkpoint with a covariance head")
    if req.profile is not None:
        plan = from_profile(req.profile, req.force)
    elif req.checkpoint is not None:
        plan = from_checkpoint(req)
    elif req.calibration is not None:
        plan = from_calibration(req.calibration)
    else:
        plan = Plan()
    if req.noise_profile is not None:
        noise = Profile.load(req.noise_profile)
        plan.made_for.append(rates.MadeFor(f"profile {req.noise_profile}", noise.sample_rate_hz, noise.device, ""))
    return plan


def from_profile(path: Path, force: bool = False) -> Plan:
    """The floor of a device profile (a noise-only one has none: ``corrects`` False); a floor outside what a
    MEMS IMU can be (:func:`imu_learn.calib.plausible.parameter_findings`, calibrate's limits: a profile
    edited by hand or written by another tool) is refused unless ``force`` (then a warning line)."""
    profile = Profile.load(path)
    finding = applied_floor_finding(profile.floor, profile.gravity_mps2, str(path))
    if finding is not None:
        text, where = finding
        if not force:
            raise ImplausibleProfileError(text + "; --force applies it anyway", field=where)
        logger.warning("%s; applied (--force)", text)
    made = rates.MadeFor(f"profile {path}", profile.sample_rate_hz, profile.device, profile.rate_terms())
    words = f"the floor of {describe_profile(profile, str(path))}"
    if profile.floor is None:  # calibrate --imu-only: its noise, nothing to correct the readings with
        words = f"no floor: {describe_profile(profile, str(path))} holds noise only (calibrate --imu-only)"
    plan = Plan([profile_step(profile)], [made], [words],
                needs_stamps=True, training=profile.inputs or None, what=f"profile {path}", kind="profile")
    plan.gravity = _gravity(profile, plan.gravity)
    plan.prior = _prior(profile, str(path))
    plan.corrects = profile.floor is not None
    return plan


NOT_SHIPPED_SUFFIX = ".not_shipped.pt"  # calibrate --learned's name for a model its gate did not ship


def not_shipped(path: Path) -> Optional[str]:
    """The one line that names a model calibrate --learned did not ship (None for any other file): refine,
    navigate and evaluate say it where they apply one."""
    if not Path(path).name.endswith(NOT_SHIPPED_SUFFIX):
        return None
    return (f"--checkpoint {path}: this model did not beat its profile on validation (learned.json beside it says "
            "by how much); the profile alone is calibrate's result (--profile profile.json, or profile:profile.json "
            "among evaluate's --methods)")


def from_checkpoint(req: Request) -> Plan:
    """The model of ``req.checkpoint``, after the profile it carries, if any (once)."""
    require_extra("train", f"{req.command} --checkpoint")
    from imu_learn.infer.checkpoint import imu_record, load_checkpoint, model_from_checkpoint
    from imu_learn.infer.refiner import model_step, require_covariance_head
    from imu_learn.nn.device import pick_device

    try:
        device = pick_device(req.device)
    except RuntimeError as e:  # torch's own message for a device string it does not know
        raise ConfigError(f"--device: {e}") from e
    state = load_checkpoint(req.checkpoint)
    model = model_from_checkpoint(state).to(device)
    if not_shipped(req.checkpoint):
        logger.warning(not_shipped(req.checkpoint))
    if req.variance == "required":
        require_covariance_head(model, req.checkpoint)
    record = imu_record(state)
    made = rates.MadeFor(f"model {req.checkpoint}", record["sample_rate_hz"], record["device"])
    rule = model.windowing.replace(req.window, req.overlap, req.batch)
    kind = f"causal, chunks of {rule.window}" if model.cfg.causal else f"window {rule.window}, overlap {rule.overlap}"
    rate = "rate unknown" if not made.sample_rate_hz else rates.hz(made.sample_rate_hz)
    plan = Plan(made_for=[made], words=[f"model {req.checkpoint}: {kind}, {device}, made for "
                                        f"{made.device or 'an unknown device'} at {rate}"],
                training=record.get("inputs"), what=f"model {req.checkpoint}", kind="checkpoint")
    if record["profile"]:
        carried(plan, Profile.from_dict(record["profile"], f"{req.checkpoint} (its profile)"), str(req.checkpoint),
                bool(record["profile_in_model"]))
    plan.covariance = req.variance == "required" or (req.variance == "if-head" and model.cov_head is not None)
    step = model_step(model, req.window, req.overlap, req.batch, req.progress, plan.covariance)
    plan.steps.append(measured(step, plan.measured))  # what the model adds: the guard's residual
    if req.variance == "required":
        plan.words.append("covariance fields: learned per-sample variances")
    return plan


def carried(plan: Plan, profile: Profile, checkpoint: str, in_model: bool) -> None:
    """``plan`` with a checkpoint's profile: held by the model (its own start: applied once, inside
    it), else its floor as a step before the model."""
    if in_model:
        plan.words.append(f"on top of the floor of its {describe_profile(profile, 'carried')}, held by the model")
        plan.model_profile = "in-model"
    else:
        plan.steps.append(profile_step(profile))
        plan.words.append(f"after its {describe_profile(profile, 'carried')}")
        plan.needs_stamps = True
        plan.model_profile = "applied"
    plan.gravity = _gravity(profile, plan.gravity)
    plan.prior = _prior(profile, f"{checkpoint} (its profile)")


def from_calibration(path: Path) -> Plan:
    """A fit ``imu-learn evaluate`` saved (``<out>/methods/timing.json``, ``traditional+timing.json``;
    the method is the file's name): the floor a learned input is judged by. It records no rate."""
    name = Path(path).stem
    if name not in REGISTRY:
        raise ConfigError(f"--calibration: {path}: the file name must be a method's ({', '.join(REGISTRY)}), as "
                          "imu-learn evaluate writes it")
    if not Path(path).is_file():
        raise FileNotFoundError(f"--calibration: {path} not found (imu-learn evaluate --methods {name} writes it)")
    method = load_method_class(name)().load(Path(path))

    def step(t_ns, gyro, acc):
        n = len(gyro)
        z = np.zeros((n, 3))
        seq = Segment(name, t_ns, gyro, acc, z, z, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))
        g, a = method.refine(seq)
        return np.ascontiguousarray(g), np.ascontiguousarray(a), None

    return Plan([step], [], [f"{name} ({Path(path).name})"], needs_stamps=True, stamps_for=f"--calibration {name}",
                what=f"calibration {path}", kind="calibration")


# -- the checks and the application ----------------------------------------------------------------


def check(plan: Plan, rec: Recording, force: bool = False) -> Optional[float]:
    """The recording's rate (None: no stamps); stops on a rate more than 5 % off or on a gyro unit the
    training data contradict (:func:`imu_learn.infer.guard.unit_mistake`), unless ``force``, and logs a
    warning line for each mismatch it lets through."""
    if rec.t_ns is None and plan.needs_stamps:
        raise InvalidInputError(f"{rec.name} has no stamps of its own ({rec.fmt}); {plan.stamps_for} needs them")
    rate = sample_rate_hz(rec.t_ns) if rec.t_ns is not None else None
    for line in rates.check(rec.name, rate, rec.device, plan.made_for, force):
        logger.warning(line)
    for line in rates.unchecked(rate, plan.made_for):
        logger.info(line)
    unit = guard.unit_mistake(plan.training, rec.gyro, rec.gyro_unit, plan.what)
    if unit and not force:
        raise InvalidInputError(f"{rec.name}: {unit}, or --force to apply it anyway")
    if unit:
        logger.warning("%s: %s (applied: --force)", rec.name, unit)
    return rate


def guard_entry(plan: Plan, rec: Recording, rate: Optional[float]) -> Dict[str, Any]:
    """The summary's ``guard`` entry; logs its warning (or, for a model, info) line."""
    stats = guard.input_stats(rec.t_ns, rec.gyro, rec.acc, rate)
    entry, warning, info = guard.verdict(plan.training, stats, plan.what, plan.measured.get("residual_rms"),
                                         device_only=plan.kind == "profile")
    if warning:
        logger.warning(warning)
    if info and plan.kind == "checkpoint":  # a profile without them: said in the summary only (an affine floor)
        logger.info(info)
    return entry


def summary(plan: Plan, rec: Recording, rate: Optional[float], guard_verdict: Dict[str, Any]) -> Dict[str, Any]:
    """What was applied, what it was made for, the recording and the guard's verdict (plain values)."""
    return {
        "applied": plan.words,
        "made_for": [{"what": m.what, "sample_rate_hz": m.sample_rate_hz, "device": m.device} for m in plan.made_for],
        "recording": {"sample_rate_hz": rate, "device": rec.device, "samples": int(len(rec.gyro))},
        "guard": guard_verdict,
    }


def correct(plan: Plan, rec: Recording, force: bool = False) -> Corrected:
    """``rec`` checked and corrected by ``plan`` (module doc, steps 2-4)."""
    rate = check(plan, rec, force)
    gyro, acc, var = plan.apply(rec.t_ns, rec.gyro, rec.acc)
    entry = summary(plan, rec, rate, guard_entry(plan, rec, rate) if plan.kind != "raw" else {"verdict": "nothing applied"})
    return Corrected(gyro, acc, var, {**entry, "kind": plan.kind, "model_profile": plan.model_profile})
