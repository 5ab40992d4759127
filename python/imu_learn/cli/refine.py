"""``imu-learn refine``: a recording's IMU through a device profile's floor or a trained model, in the
input's own format (:mod:`imu_learn.infer.rewrite` writes it; the correction plan,
:mod:`imu_learn.calib.correction`, which navigate uses too, applies the floor or the model after the
same checks: :mod:`imu_learn.infer.rates` that they were made for the recording's rate and device,
:mod:`imu_learn.infer.guard` whether the recording looks like their training data); ``--bias METHOD`` removes the recording's own gyro bias,
bounded by the device's bias spread (:mod:`imu_learn.infer.bias`, the registry). Writes a summary beside
the output (:func:`imu_learn.infer.rewrite.summary_path`)."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence

from imu_learn.calib import correction
from imu_learn.cli.common import add_imu_input_options, csv_layout, run_command
from imu_learn.data.formats import FORMATS, USER_CSV, ImuSource, read_imu_source
from imu_learn.errors import ConfigError
from imu_learn.infer import rates
from imu_learn.infer.bias import REGISTRY, bias_step, choices, help_text, model_device
from imu_learn.infer.bias import bias_entry as own_bias_entry
from imu_learn.infer.rewrite import rewrite_recording, summary_path, write_summary
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
                        "none ships: models/bias/README.md)")
    p.add_argument("--fill-covariance", action="store_true",
                   help="ROS bags, a checkpoint with a covariance head: write each IMU message's angular_velocity / "
                        "linear_acceleration covariance as the diagonal of its predicted per-sample variances")
    add_imu_input_options(p)


def request(args: argparse.Namespace) -> correction.Request:
    """What refine's command line asks the correction plan for (:mod:`imu_learn.calib.correction`)."""
    return correction.Request(profile=args.profile, checkpoint=args.checkpoint, force=args.force, device=args.device,
                              window=args.window, overlap=args.overlap, batch=args.batch, progress=not args.quiet,
                              variance="required" if args.fill_covariance else "never")


def recording(args: argparse.Namespace, src: ImuSource) -> correction.Recording:
    return correction.Recording(str(args.input), src.t_ns, src.gyro, src.acc, src.fmt, args.format, args.imu_name,
                                src.layout.gyro_unit if src.layout is not None else None)


def add_bias_step(args: argparse.Namespace, plan: correction.Plan) -> None:
    if args.bias_model is not None and args.bias not in ("learned", "auto"):
        raise ConfigError("--bias-model is the estimator of --bias learned (or one of auto's)")
    if args.bias == "learned" or args.bias_model is not None:
        require_extra("train", f"imu-learn refine --bias {args.bias} --bias-model")
    if args.bias_model is not None:  # its device checked as a model's or profile's is (a warning line each)
        made = rates.MadeFor(f"bias model {args.bias_model}", None, model_device(args.bias_model))
        for line in rates.other_devices(made, plan.made_for):
            logger.warning(line)
        plan.made_for.append(made)
    if args.bias != "none":
        plan.steps.append(bias_step(args.bias, plan.gravity, plan.measured, args.bias_model, plan.prior))
        plan.words.append(REGISTRY[args.bias].words)
        plan.stamps_for = plan.stamps_for if plan.needs_stamps else f"--bias {args.bias} (the estimator's windows)"
        plan.needs_stamps = True


def bias_entry(args: argparse.Namespace, plan: correction.Plan) -> Dict[str, Any]:
    """The summary's ``bias`` entry; logs one warning line when nothing was estimated or the bound
    shrank or rejected the estimate."""
    entry, warning = own_bias_entry(args.bias, plan.measured, str(args.input))
    if warning:
        logger.warning(warning)
    return entry


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    if args.fill_covariance and args.checkpoint is None:
        raise ConfigError("--fill-covariance needs a --checkpoint with a covariance head")
    plan = correction.build(request(args))
    if not plan.corrects and args.bias == "none":  # the output would pass for a correction
        logger.warning(f"--profile {args.profile}: it holds the noise only (no reference fitted a floor): the readings "
                       "pass unchanged; calibrate against a reference (--groundtruth) for a correction, or add --bias")
    add_bias_step(args, plan)
    src = read_imu_source(args.input, args.format, args.imu_topic, csv_layout(args))
    rec = recording(args, src)
    rate = correction.check(plan, rec, args.force)
    written: List[Path] = []

    def with_summary(target: Path) -> None:
        """The summary, beside the refined IMU (written with it, Ctrl-C held: :func:`rewrite_recording`)."""
        bias = bias_entry(args, plan)
        if args.bias != "none" and not bias.get("applied"):  # the words said what was asked: say what was done
            plan.words[plan.words.index(REGISTRY[args.bias].words)] = f"--bias {args.bias}: no bias subtracted"
        summary = {
            "input": str(args.input), "output": str(target), "format": src.fmt,
            "checkpoint": None if args.checkpoint is None else str(args.checkpoint),
            "profile": None if args.profile is None else str(args.profile),
            **correction.summary(plan, rec, rate, correction.guard_entry(plan, rec, rate)),
            "bias": bias,
        }
        written[:] = [target, summary_path(args.out, target)]
        write_summary(written[1], summary)

    untouched = " (the input folder's copy in OUT is not refined)" if args.copy_folder else f" ({args.out} is as it was)"
    keep(lambda: f"{written[0]} and {written[1]} are this run's, complete" if written else
         f"nothing of this run's refined IMU is written{untouched}")
    target = rewrite_recording(src, args.input, args.out, [plan.apply], args.copy_folder, args.fill_covariance,
                               with_summary)
    where = written[1]
    at = f"recording at {rates.hz(rate)}" if rate else "recording without stamps"
    print(f"refined IMU ({'; '.join(plan.words)}; {at}) written to {target}; summary {where}")
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn refine ARGV``."""
    return run_command("refine", argv)
