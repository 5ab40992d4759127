"""``imu-learn groundtruth --input REC``: which ground truth of a recording its own IMU agrees with,
and in which body frame it is (:mod:`imu_learn.eval.groundtruth`)."""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import add_imu_input_options, csv_layout, run_command
from imu_learn.data.datasets import MAX_GAP_S, dataset_max_gap_s
from imu_learn.data.formats import detect_format, read_recording
from imu_learn.data.types import GroundTruth
from imu_learn.errors import ConfigError
from imu_learn.eval.groundtruth import (
    CheckOptions,
    check,
    default_gap_s,
    fmt_vec,
    gt_label,
    kept_note,
    pick_best,
    summary_line,
)

DESCRIPTION = """Check a recording's ground truth against its own IMU, before training on it or scoring with it:
bias-removed relative pose RMSE over 10 and 200 IMU samples, the rotation R_off from the ground
truth's body frame to the IMU's and the time offset tau (fitted on the angular rates), the scores
again with R_off and tau applied, and the lever arm of the IMU in the ground truth's body frame.
A ground truth in the IMU frame, on the IMU's clock, shows R_off below 0.5 deg, |tau| below 2.5 ms
and no lever arm. With several --groundtruth files, the last line names the one that agrees best.
The method: the module doc of imu_learn.eval.groundtruth."""
EPILOG = """examples:
  imu-learn groundtruth --input datasets/euroc/MH_04_difficult
  imu-learn groundtruth --input datasets/euroc/V1_01_easy --groundtruth datasets/euroc/V1_01_easy/groundtruth_pose.tum \\
      --groundtruth datasets/euroc/V1_01_easy/groundtruth_state_20hz.csv
  imu-learn groundtruth --input robot/run1 --format fetch                  (its motion capture's gaps: 0.1 s by default)
  imu-learn groundtruth --input my_imu.csv --columns t,_,gx,gy,gz,ax,ay,az --time-unit s --groundtruth mocap.tum"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--input", type=Path, required=True, metavar="REC", help="the recording (folder, file or bag)")
    p.add_argument("--groundtruth", type=Path, action="append", metavar="FILE",
                   help="a ground-truth file to check (repeat for several; default: the format's own)")
    p.add_argument("--format", default="auto", help="the recording's layout (default: detected)")
    own = ", ".join(f"{k} {v:g}" for k, v in MAX_GAP_S.items())
    p.add_argument("--max-gap-s", type=float, default=None, metavar="S",
                   help="split at ground-truth gaps longer than S (default 0.05, or 1.5 periods of sparse ground truth; "
                        f"at least a dataset's own where its reference is known to drop frames: {own})")
    p.add_argument("--yaw-from-acc", action="store_true",
                   help="fit R_off on specific force (a ground robot turning about z only: the gyro leaves its yaw free; "
                        "chosen by itself where the rates turn about one axis only)")
    p.add_argument("--imu-topic", help="rosbag: the sensor_msgs/msg/Imu topic (default: the bag's only one)")
    p.add_argument("--groundtruth-topic", help="rosbag: the pose topic (default: the bag's only one)")
    add_imu_input_options(p)


def label(rec: Path, gt: Optional[Path]) -> str:
    if gt is None:
        return "its own ground truth"
    try:
        return gt_label(str(gt.resolve().relative_to(rec.resolve())))
    except ValueError:  # not inside the recording
        return str(gt)


def describe(row: Any) -> List[str]:
    def score(s) -> str:
        return f"rot {s[0]:.3f}°, trans {s[1]:.4f} m"

    world = (f"  world: tilted {row.world_tilt_deg:.1f}° from gravity (the specific force's mean); levelled before every "
             "translation score and the lever arm" if row.levelled else
             f"  world: z up within {row.world_tilt_deg:.1f}° (the specific force's mean)")
    return [f"{row.recording} / {row.gt}: reference at {row.rate_hz:.0f} Hz, {row.samples} IMU samples in {row.n_segments} segment(s)",
            world,
            f"  bias-removed RMSE over 10 samples: rot {row.n10[0]:.4f}°, trans {row.n10[1]:.5f} m; "
            f"over 200 samples: {score(row.n200)}",
            f"  R_off (GT body -> IMU): {row.off_deg:.2f}° about {fmt_vec(row.off_axis)}; "
            f"tau {row.tau_ms:+.1f} ms (> 0: GT stamps late); R_off {row.rotation_from}",
            f"  over 200 samples after R_off: {score(row.after_rot)}; after R_off and the GT shifted by tau - dt/2: "
            f"{score(row.after_hold)}",
            f"  lever arm (IMU origin in the GT body frame): {fmt_vec(row.lever_cm, 1)} cm ± {max(row.lever_se_cm):.1f}",
            (f"  scale: the positions are x{row.scale:.4f} (± {row.scale_std:.4f}) the distances the accelerometer "
             f"measures{'' if row.scale_off else ' (metric)'}" if math.isfinite(row.scale) else
             f"  scale: not observed ({row.scale_not_observed or 'too little acceleration'})"),
            f"  verdict: {row.verdict}"]


def positions_only(path: Path) -> bool:
    """Whether a trajectory file's first row holds four fields (t x y z): positions without orientation."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                text = line.strip()
                if text and not text.startswith("#") and not text[0].isalpha():
                    return len([f for f in text.replace(",", " ").split() if f]) == 4
    except OSError:
        return False
    return False


def gap_s(args: argparse.Namespace, fmt: Optional[str], gt: GroundTruth) -> float:
    """The ground-truth gap that splits the recording: --max-gap-s, else the check's default
    (:func:`default_gap_s`), raised to the dataset's own where its reference needs one (labels' default)."""
    if args.max_gap_s is not None:
        return args.max_gap_s
    return max(default_gap_s(gt), dataset_max_gap_s(fmt) or 0.0)


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    rows = []
    columns = csv_layout(args)
    for gt_file in args.groundtruth or [None]:
        if gt_file is not None and positions_only(gt_file):
            raise ConfigError(f"{gt_file}: positions only (t x y z): this check needs a reference's orientation; "
                              "calibrate takes positions as --groundtruth (the biases they observe), navigate as --aiding")
        imu, gt = read_recording(args.input, args.format, groundtruth=gt_file, imu_topic=args.imu_topic,
                                 groundtruth_topic=args.groundtruth_topic, columns=columns)
        fmt = None if columns is not None else detect_format(args.input) if args.format == "auto" else args.format
        gap = gap_s(args, fmt, gt)
        row, _ = check(imu, gt, args.input.name, label(args.input, gt_file),
                       CheckOptions(max_gap_s=gap, yaw_from_acc=args.yaw_from_acc))
        rows.append(row)
        print("\n".join(describe(row)), flush=True)
        note = kept_note(imu, gt, row.samples, gap)
        if note is not None:
            print(f"  note: {note}", flush=True)
    best = pick_best(rows)[args.input.name]
    if not best.rates_match:  # no file to use: refused, naming why (the verdict's causes)
        raise ConfigError(f"{args.input.name}: no ground truth matches its IMU: {best.gt}: {best.verdict}")
    print(summary_line(args.input.name, rows, best))
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn groundtruth ARGV``."""
    return run_command("groundtruth", argv)
