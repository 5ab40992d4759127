"""``imu-learn labels DATASET``: the label cache of a dataset (:mod:`imu_learn.data.label_builder`)."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.calib.frames import gap_hint
from imu_learn.cli.common import DATA_ROOT_ENV, run_command
from imu_learn.data import label_builder as label_cache
from imu_learn.data.config import resolve_data_root
from imu_learn.data.datasets import DATASETS, MAX_GAP_S, find_recordings
from imu_learn.data.formats import read_recording
from imu_learn.data.loading import AlignOptions, source_files
from imu_learn.errors import AlignmentError

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
    own = ", ".join(f"{k} {v:g}" for k, v in MAX_GAP_S.items())
    p.add_argument("--max-gap", type=float, default=None, metavar="S",
                   help=f"split at GT gaps longer than S (default {AlignOptions.max_gap_s:g}; where a dataset's reference "
                        f"is known to drop frames, its own: {own})")
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
    root = dataset_dir(args)
    topics = {"imu_topic": args.imu_topic, "groundtruth_topic": args.groundtruth_topic}
    options = label_cache.dataset_options(args.dataset) if args.max_gap is None else AlignOptions(max_gap_s=args.max_gap)
    try:
        m = label_cache.build_cache(
            args.dataset, root, out, window=args.window, stride=args.stride, gravity=args.gravity,
            options=options, rebuild=args.rebuild, progress=not args.quiet, topics=topics,
        )
    except AlignmentError as e:
        if LIBRARY_ADVICE not in str(e):  # not the refusal of a recording left without a segment
            raise
        raise with_gap_option(e, args.dataset, root, topics, options.max_gap_s) from e
    print(label_cache.summary(m, out))
    return 0


# The aligner's advice (Rust) to a recording left without a segment of min_segment_s, in the library's terms.
LIBRARY_ADVICE = "lower the minimum segment length, min_segment_s in Python, to keep shorter ones"


def with_gap_option(e: AlignmentError, dataset: str, root: Path, topics: dict, gap: float) -> AlignmentError:
    """The aligner's refusal of a recording left without a segment, naming this command's option: where
    frequent ground-truth dropouts are the cause, the --max-gap that bridges them (:func:`gap_hint`, the
    rule groundtruth's --max-gap-s hint follows); else the aligner's counts with its advice in the
    command's words."""
    rec = next((path for _, path in find_recordings(dataset, root)
                if e.imu_path is not None and str(source_files(path, dataset)[0]) == e.imu_path), None)
    if rec is not None:
        _, gt = read_recording(rec, dataset, **{k: v for k, v in topics.items() if v})
        hint = gap_hint(gt, gap, "--max-gap")
        if hint is not None:
            return AlignmentError(f"{rec}: {hint}", e.path, e.imu_path)
    return AlignmentError(str(e).replace(LIBRARY_ADVICE, f"segments under {AlignOptions.min_segment_s:g} s are "
                                         f"dropped; raise --max-gap (now {gap:g} s) where ground-truth gaps split "
                                         "the recording"), e.path, e.imu_path)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn labels ARGV``."""
    return run_command("labels", argv)
