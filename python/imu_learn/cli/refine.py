"""``imu-learn refine``: a recording's IMU refined by a checkpoint, in the input's own format
(the windowing and writing are :mod:`imu_learn.infer.refine`)."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import run_command
from imu_learn.data.formats import FORMATS
from imu_learn.errors import ConfigError
from imu_learn.util.extras import require_extra

DESCRIPTION = """Write a recording's IMU refined by a trained model, in the input's own format (ASL/EuRoC
CSV, TUM-VI, Blackbird, BROAD, KAIST, ROS 1/2 bags). The input is never written. Prints the file
written to stdout."""
EPILOG = """examples:
  imu-learn refine --checkpoint models/euroc_adis16448.pt --input datasets/euroc/MH_01_easy --out refined_mh01
  imu-learn refine --checkpoint models/euroc_adis16448_cov.pt --input run.bag --out run_refined.bag --fill-covariance"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", required=True, type=Path, metavar="PT", help="imu_learn checkpoint (.pt)")
    p.add_argument("--input", required=True, type=Path, metavar="PATH",
                   help="recording folder, IMU file or ROS bag (never written)")
    p.add_argument("--out", required=True, type=Path, metavar="PATH",
                   help="folder, or a file (or bag) of the input's kind")
    p.add_argument("--format", default="auto", choices=("auto", *FORMATS))
    p.add_argument("--imu-topic", help="ROS bags: the sensor_msgs/msg/Imu topic (default: the bag's only one)")
    p.add_argument("--window", type=int, help="samples per window (default: the checkpoint's training window; "
                                              "imu_learn.infer.windowing)")
    p.add_argument("--overlap", type=int, help="overlap of consecutive windows (default: half the window)")
    p.add_argument("--batch", type=int, help="windows run at once (default 16)")
    p.add_argument("--device", default="auto", help="auto (cuda if available), cpu, cuda, cuda:1 ...")
    p.add_argument("--copy-folder", action="store_true", help="copy the whole input folder to OUT first")
    p.add_argument("--fill-covariance", action="store_true",
                   help="ROS bags, a checkpoint with a covariance head: write each IMU message's angular_velocity / "
                        "linear_acceleration covariance as the diagonal of its predicted per-sample variances")


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    require_extra("train", "imu-learn refine")
    from imu_learn.infer.checkpoint import load_model
    from imu_learn.infer.refine import refine_recording, require_covariance_head
    from imu_learn.nn.device import pick_device

    try:
        device = pick_device(args.device)
    except RuntimeError as e:  # torch's own message for a device string it does not know
        raise ConfigError(f"--device: {e}") from e
    model = load_model(args.checkpoint).to(device)
    if args.fill_covariance:
        require_covariance_head(model, args.checkpoint)
    target = refine_recording(
        model, args.input, args.out, args.format, args.window, args.overlap, args.copy_folder,
        args.batch, progress=not args.quiet, imu_topic=args.imu_topic, fill_covariance=args.fill_covariance,
    )
    rule = model.windowing.replace(args.window, args.overlap, args.batch)
    kind = f"causal, chunks of {rule.window}" if model.cfg.causal else f"window {rule.window}, overlap {rule.overlap}"
    cov = "; covariance fields: learned per-sample variances" if args.fill_covariance else ""
    print(f"refined IMU ({kind}, {device}{cov}) written to {target}")
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn refine ARGV``."""
    return run_command("refine", argv)
