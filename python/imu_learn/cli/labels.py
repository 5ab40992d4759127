"""``imu-learn labels DATASET``: the label cache of a dataset (:mod:`imu_learn.data.label_builder`)."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import DATA_ROOT_ENV, run_command
from imu_learn.data import label_builder as label_cache
from imu_learn.data.config import resolve_data_root
from imu_learn.data.datasets import DATASETS
from imu_learn.data.loading import AlignOptions

DESCRIPTION = f"""Build the label cache of a dataset: read every recording, align ground truth to the IMU
stamps, compute the Δq/Δβ/Δγ labels of every window (Rust, in parallel) and write them to
cache/<DATASET> (--out). Re-running is cheap: up-to-date recordings are skipped, stale ones rebuilt;
an interrupted run keeps the finished recordings.

Which folder is read: --dataset-dir DIR names the dataset folder itself; otherwise it is
<data root>/<DATASET>, the data root being --data-root DIR, else ${DATA_ROOT_ENV}, else datasets/
(the shipped crops)."""
EPILOG = """examples:
  imu-learn labels euroc                                   datasets/euroc (the shipped crops) -> cache/euroc
  imu-learn labels euroc --data-root ~/data                ~/data/euroc -> cache/euroc
  imu-learn labels rosbag --dataset-dir bags/ --imu-topic /imu0 --groundtruth-topic /vicon --out cache/bags"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", choices=DATASETS, metavar="DATASET", help=f"one of {', '.join(DATASETS)}")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--data-root", metavar="DIR", default=None,
                       help=f"data root: the dataset folder is DIR/DATASET (default: ${DATA_ROOT_ENV}, else datasets)")
    where.add_argument("--dataset-dir", type=Path, metavar="DIR", default=None,
                       help="the dataset folder itself (instead of <data root>/DATASET)")
    p.add_argument("--out", type=Path, metavar="DIR", help="cache folder (default cache/<DATASET>)")
    p.add_argument("--window", type=int, default=200, help="window length in IMU samples")
    p.add_argument("--stride", type=int, default=10, help="step between window starts")
    p.add_argument("--gravity", type=float, default=9.81)
    p.add_argument("--max-gap", type=float, default=AlignOptions.max_gap_s, help="split at GT gaps longer than this [s]")
    p.add_argument("--imu-topic", help="rosbag: the sensor_msgs/msg/Imu topic (default: each bag's only one)")
    p.add_argument("--groundtruth-topic", help="rosbag: the PoseStamped / TransformStamped / Odometry topic")
    p.add_argument("--rebuild", action="store_true", help="rebuild everything, even an incompatible cache")


def dataset_dir(args: argparse.Namespace) -> Path:
    if args.dataset_dir is not None:
        return args.dataset_dir
    return Path(resolve_data_root(args.data_root) or "datasets") / args.dataset


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    out = args.out or Path("cache") / args.dataset
    keep(f"finished recordings are kept in {out}; run again to resume")
    m = label_cache.build_cache(
        args.dataset, dataset_dir(args), out, window=args.window, stride=args.stride, gravity=args.gravity,
        options=AlignOptions(max_gap_s=args.max_gap), rebuild=args.rebuild, progress=not args.quiet,
        topics={"imu_topic": args.imu_topic, "groundtruth_topic": args.groundtruth_topic},
    )
    print(label_cache.summary(m, out))
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn labels ARGV``."""
    return run_command("labels", argv)
