"""``imu-learn refine``: a recording's IMU through a device profile's floor or a trained model, in the
input's own format (:mod:`imu_learn.infer.rewrite` writes it, :mod:`imu_learn.infer.refiner` runs a
model, :meth:`imu_learn.calib.profile.Profile.apply` the floor, :mod:`imu_learn.infer.rates` checks
that they were made for the recording's rate and device, :mod:`imu_learn.infer.guard` whether the
recording looks like their training data); ``--bias METHOD`` removes the recording's own gyro bias,
bounded by the device's bias spread (:mod:`imu_learn.infer.bias`, the registry). Writes a summary beside
the output (:func:`imu_learn.infer.rewrite.summary_path`)."""
from __future__ import annotations

import argparse
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence

from imu_learn.calib.profile import Profile
from imu_learn.cli.common import add_imu_input_options, csv_layout, run_command
from imu_learn.core.still import MEMS_PRIOR, BiasPrior
from imu_learn.data.formats import FORMATS, USER_CSV, ImuSource, read_imu_source
from imu_learn.data.types import sample_rate_hz
from imu_learn.errors import ConfigError, InvalidInputError
from imu_learn.infer import guard, rates
from imu_learn.infer.bias import REGISTRY, bias_step, choices, help_text
from imu_learn.infer.bias import bias_entry as own_bias_entry
from imu_learn.infer.rewrite import Step, measured, rewrite_recording, summary_path, write_summary
from imu_learn.util.extras import require_extra

logger = logging.getLogger(__name__)

DESCRIPTION = """Write a recording's IMU refined by a device profile (the floor: time offset and affine calibration,
from imu-learn calibrate) or by a trained model (with the profile it was trained on top of, if any), in the
input's own format (ASL/EuRoC CSV, TUM-VI, Blackbird, BROAD, KAIST, Fetch, GNSS/IMU CSV, ROS 1/2 bags, or
a CSV of your own: --columns and the units). The input is never written. A recording sampled more than 5 %
off the rate the profile or model was made for is refused (--force applies it anyway); one of another
device, or one whose statistics lie outside those of the training data (the guard), is a warning.
--bias auto removes the recording's own gyro bias, every estimator (still stretches, gravity consistency)
and the device's bias spread combined by their uncertainties; an estimate far outside that spread is
shrunk toward it or rejected. Prints the file
written to stdout; OUT/summary.json (or OUT.summary.json beside a file) holds what was applied, the
guard's figures and the bias estimate."""
EPILOG = """examples:
  imu-learn refine --checkpoint models/euroc_adis16448.pt --input datasets/euroc/MH_01_easy --out refined_mh01
  imu-learn refine --profile calib/profile.json --input my_imu.csv --columns t,_,gz,gy,gx,az,ay,ax \\
      --time-unit s --gyro-unit deg/s --acc-unit g --out my_imu_refined.csv
  imu-learn refine --checkpoint models/euroc_adis16448_cov.pt --input run.bag --out run_refined.bag --fill-covariance
  imu-learn refine --profile calib/profile.json --input datasets/euroc/MH_01_easy --out mh01_floor --bias auto"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--checkpoint", type=Path, metavar="PT",
                      help="a trained model (.pt); one trained on top of a profile applies that profile first")
    what.add_argument("--profile", type=Path, metavar="JSON",
                      help="a device profile (imu-learn calibrate's profile.json): applies its floor (no torch needed)")
    p.add_argument("--input", required=True, type=Path, metavar="PATH",
                   help="recording folder, IMU file or ROS bag (never written)")
    p.add_argument("--out", required=True, type=Path, metavar="PATH",
                   help="folder, or a file (or bag) of the input's kind")
    p.add_argument("--format", default="auto", choices=("auto", *FORMATS, USER_CSV))
    p.add_argument("--imu-topic", help="ROS bags: the sensor_msgs/msg/Imu topic (default: the bag's only one)")
    p.add_argument("--force", action="store_true",
                   help="refine a recording whose rate is more than 5 %% off the profile's or model's (a warning)")
    p.add_argument("--imu-name", metavar="NAME",
                   help="the recording's device, checked against the profile's or model's (default: the dataset "
                        "its format belongs to, else not checked)")
    p.add_argument("--window", type=int, help="samples per window (default: the checkpoint's training window; "
                                              "imu_learn.infer.windowing)")
    p.add_argument("--overlap", type=int, help="overlap of consecutive windows (default: half the window)")
    p.add_argument("--batch", type=int, help="windows run at once (default 16)")
    p.add_argument("--device", default="auto", help="auto (cuda if available), cpu, cuda, cuda:1 ...")
    p.add_argument("--copy-folder", action="store_true", help="copy the whole input folder to OUT first")
    p.add_argument("--bias", choices=choices(), default="none", help=help_text())
    p.add_argument("--bias-model", type=Path, metavar="PT",
                   help="--bias learned (and auto): the bias estimator (python -m imu_learn.train.bias_train writes one; "
                        "models/bias/fetch_bias_net.pt for the Fetch robot's IMU)")
    p.add_argument("--fill-covariance", action="store_true",
                   help="ROS bags, a checkpoint with a covariance head: write each IMU message's angular_velocity / "
                        "linear_acceleration covariance as the diagonal of its predicted per-sample variances")
    add_imu_input_options(p)


@dataclass
class Plan:
    """What refine applies: the steps in order, what they were made for (rate and device), the words
    of the summary line, and whether a step needs the recording's stamps (a profile's time offset)."""

    steps: List[Step] = field(default_factory=list)
    made_for: List[rates.MadeFor] = field(default_factory=list)
    words: List[str] = field(default_factory=list)
    needs_stamps: bool = False
    stamps_for: str = "a profile's time offset"  # what needs them, for the message
    training: Optional[Dict[str, Any]] = None  # the statistics of the training data (guard), None: not recorded
    gravity: float = 9.80665  # [m/s^2] for the still detector's norm check (a profile's own when it has one)
    prior: BiasPrior = MEMS_PRIOR  # the device's bias spread after the steps (a profile's, else a MEMS gyro's)
    measured: Dict[str, Any] = field(default_factory=dict)  # what the steps measure as they run


def profile_step(profile: Profile) -> Step:
    def step(t_ns, gyro, acc):
        g, a = profile.apply(t_ns, gyro, acc)
        return g, a, None

    return step


def describe_profile(profile: Profile, where: str) -> str:
    return f"profile {where} (device {profile.device!r}, {rates.hz(profile.sample_rate_hz)})"


def from_profile(args: argparse.Namespace) -> Plan:
    """The floor of ``--profile``."""
    profile = Profile.load(args.profile)
    made = rates.MadeFor(f"profile {args.profile}", profile.sample_rate_hz, profile.device)
    plan = Plan([profile_step(profile)], [made], [f"the floor of {describe_profile(profile, str(args.profile))}"],
                needs_stamps=True, training=profile.inputs or None)
    plan.gravity = _gravity(profile, plan.gravity)
    plan.prior = _prior(profile, str(args.profile))
    return plan


def _prior(profile: Profile, where: str) -> BiasPrior:
    """The device prior after ``profile``'s floor: zero mean, its gyroscope's bias spread."""
    return BiasPrior.from_bias_std(profile.gyro.bias_std, f"the bias spread of profile {where}")


def _gravity(profile: Profile, default: float) -> float:
    g = profile.gravity_mps2
    return float(g) if g is not None and g == g and g > 0 else default


def from_checkpoint(args: argparse.Namespace) -> Plan:
    """The model of ``--checkpoint``, after the profile it carries, if any."""
    require_extra("train", "imu-learn refine --checkpoint")
    from imu_learn.infer.checkpoint import imu_record, load_checkpoint, model_from_checkpoint
    from imu_learn.infer.refiner import model_step, require_covariance_head
    from imu_learn.nn.device import pick_device

    try:
        device = pick_device(args.device)
    except RuntimeError as e:  # torch's own message for a device string it does not know
        raise ConfigError(f"--device: {e}") from e
    state = load_checkpoint(args.checkpoint)
    model = model_from_checkpoint(state).to(device)
    if args.fill_covariance:
        require_covariance_head(model, args.checkpoint)
    record = imu_record(state)
    made = rates.MadeFor(f"model {args.checkpoint}", record["sample_rate_hz"], record["device"])
    rule = model.windowing.replace(args.window, args.overlap, args.batch)
    kind = f"causal, chunks of {rule.window}" if model.cfg.causal else f"window {rule.window}, overlap {rule.overlap}"
    rate = "rate unknown" if not made.sample_rate_hz else rates.hz(made.sample_rate_hz)
    plan = Plan(made_for=[made],
                words=[f"model {args.checkpoint}: {kind}, {device}, made for {made.device or 'an unknown device'} "
                       f"at {rate}"], training=record.get("inputs"))
    if record["profile"] and record["profile_in_model"]:  # the model's own start: applied once, inside it
        profile = Profile.from_dict(record["profile"], f"{args.checkpoint} (its profile)")
        plan.words.append(f"on top of the floor of its {describe_profile(profile, 'carried')}, held by the model")
        plan.gravity = _gravity(profile, plan.gravity)
        plan.prior = _prior(profile, f"{args.checkpoint} (its profile)")
    elif record["profile"]:
        profile = Profile.from_dict(record["profile"], f"{args.checkpoint} (its profile)")
        plan.steps.append(profile_step(profile))
        plan.words.append(f"after its {describe_profile(profile, 'carried')}")
        plan.needs_stamps = True
        plan.gravity = _gravity(profile, plan.gravity)
        plan.prior = _prior(profile, f"{args.checkpoint} (its profile)")
    step = model_step(model, args.window, args.overlap, args.batch, not args.quiet, args.fill_covariance)
    plan.steps.append(measured(step, plan.measured))  # what the model adds: the guard's residual
    if args.fill_covariance:
        plan.words.append("covariance fields: learned per-sample variances")
    return plan


def check_recording(args: argparse.Namespace, src: ImuSource, plan: Plan) -> Optional[float]:
    """The recording's rate (None: no stamps); stops on a rate more than 5 % off (unless --force)
    and logs a warning line for each mismatch it lets through."""
    if src.t_ns is None and plan.needs_stamps:
        raise InvalidInputError(f"{args.input} has no stamps of its own ({src.fmt}); {plan.stamps_for} needs them")
    rate = sample_rate_hz(src.t_ns) if src.t_ns is not None else None
    device = rates.recording_device(src.fmt, args.format, args.imu_name)
    for line in rates.check(str(args.input), rate, device, plan.made_for, args.force):
        logger.warning(line)
    for line in rates.unchecked(rate, plan.made_for):
        logger.info(line)
    return rate


def add_bias_step(args: argparse.Namespace, plan: Plan) -> None:
    if args.bias_model is not None and args.bias not in ("learned", "auto"):
        raise ConfigError("--bias-model is the estimator of --bias learned (or one of auto's)")
    if args.bias == "learned" or args.bias_model is not None:
        require_extra("train", f"imu-learn refine --bias {args.bias} --bias-model")
    if args.bias != "none":
        plan.steps.append(bias_step(args.bias, plan.gravity, plan.measured, args.bias_model, plan.prior))
        plan.words.append(REGISTRY[args.bias].words)
        plan.stamps_for = plan.stamps_for if plan.needs_stamps else f"--bias {args.bias} (the estimator's windows)"
        plan.needs_stamps = True


def bias_entry(args: argparse.Namespace, plan: Plan) -> Dict[str, Any]:
    """The summary's ``bias`` entry; logs one warning line when nothing was estimated or the bound
    shrank or rejected the estimate."""
    entry, warning = own_bias_entry(args.bias, plan.measured, str(args.input))
    if warning:
        logger.warning(warning)
    return entry


def guard_entry(args: argparse.Namespace, src: ImuSource, plan: Plan, rate: Optional[float]) -> Dict[str, Any]:
    """The summary's ``guard`` entry; logs its warning (or info) line."""
    what = f"model {args.checkpoint}" if args.checkpoint is not None else f"profile {args.profile}"
    stats = guard.input_stats(src.t_ns, src.gyro, src.acc, rate)
    entry, warning, info = guard.verdict(plan.training, stats, what, plan.measured.get("residual_rms"))
    if warning:
        logger.warning(warning)
    if info and args.checkpoint is not None:  # a profile without them: said in the summary only (an affine floor)
        logger.info(info)
    return entry


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    if args.fill_covariance and args.checkpoint is None:
        raise ConfigError("--fill-covariance needs a --checkpoint with a covariance head")
    plan = from_profile(args) if args.profile is not None else from_checkpoint(args)
    add_bias_step(args, plan)
    src = read_imu_source(args.input, args.format, args.imu_topic, csv_layout(args))
    rate = check_recording(args, src, plan)
    target = rewrite_recording(src, args.input, args.out, plan.steps, args.copy_folder, args.fill_covariance)
    summary = {
        "input": str(args.input), "output": str(target), "format": src.fmt,
        "checkpoint": None if args.checkpoint is None else str(args.checkpoint),
        "profile": None if args.profile is None else str(args.profile),
        "applied": plan.words,
        "made_for": [{"what": m.what, "sample_rate_hz": m.sample_rate_hz, "device": m.device} for m in plan.made_for],
        "recording": {"sample_rate_hz": rate, "device": rates.recording_device(src.fmt, args.format, args.imu_name),
                      "samples": int(len(src.gyro))},
        "guard": guard_entry(args, src, plan, rate),
        "bias": bias_entry(args, plan),
    }
    where = summary_path(args.out, target)
    write_summary(where, summary)
    at = f"recording at {rates.hz(rate)}" if rate else "recording without stamps"
    print(f"refined IMU ({'; '.join(plan.words)}; {at}) written to {target}; summary {where}")
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn refine ARGV``."""
    return run_command("refine", argv)
