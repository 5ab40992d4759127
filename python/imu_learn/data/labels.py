"""``python -m imu_learn.labels DATASET [--root DIR]``: build the label cache of a dataset.

Reads every recording of the dataset, aligns ground truth to the IMU stamps, computes Δq/Δβ/Δγ
labels for every window and writes them to ``cache/<dataset>`` (see imu_learn.data.cache for the
format). Re-running is cheap: up-to-date recordings are skipped, stale ones rebuilt.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Dict, List, Optional

from imu_learn._imu_core import __version__
from imu_learn.core.integration import PAPER_FRACTIONS, window_labels
from imu_learn.data.cache import (
    CACHE_VERSION,
    fingerprint,
    holding_cache_lock,
    recording_reusable,
    reusable_recordings,
    write_manifest,
    write_progress,
    write_segment,
)
from imu_learn.data.datasets import DATASETS, find_recordings
from imu_learn.data.loading import AlignOptions, load_recording
from imu_learn.errors import ImuError, TooShortError


def source_files(path: Path) -> List[Path]:
    return [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]


def require_one_window(path: Path, segments: list, window: int) -> None:
    """A recording none of whose segments holds one window would add nothing to the cache but an
    entry with zero windows: say so instead, with the setting to change."""
    longest = max((len(s) for s in segments), default=0)
    if longest < window + 1:  # a window of W intervals spans W + 1 samples
        raise TooShortError(
            f"{path}: too short: its longest segment has {longest} samples, one window of {window} "
            f"needs {window + 1}; lower --window or add data",
            str(path), longest, window + 1,
        )


@holding_cache_lock("out")  # two runs on one folder take turns instead of mixing their files
def build_cache(
    dataset: str,
    root: Path,
    out: Path,
    window: int = 200,
    stride: int = 10,
    gravity: float = 9.81,
    options: AlignOptions = AlignOptions(),
    rebuild: bool = False,
    progress: bool = True,
    topics: Optional[Dict[str, str]] = None,
) -> dict:
    """``topics``: ``imu_topic`` / ``groundtruth_topic`` for ROS bags (each may be left out where
    every bag has one)."""
    topics = {k: v for k, v in (topics or {}).items() if v}
    settings = {
        "dataset": dataset, "window": window, "stride": stride, "fractions": list(PAPER_FRACTIONS),
        "gravity": gravity, "align": asdict(options), **({"topics": topics} if topics else {}),
    }
    old = reusable_recordings(out, rebuild, log=lambda m: print(m, file=sys.stderr))
    recordings = find_recordings(dataset, root)
    manifest = {
        "cache_version": CACHE_VERSION, "imu_learn_version": __version__, "settings": settings,
        "source_root": str(root.resolve()), "recordings": [],
    }
    try:
        from tqdm import tqdm
        bar = tqdm(recordings, desc=f"labels {dataset}", unit="rec", disable=not progress, file=sys.stderr)
    except ImportError:  # tqdm is a dependency, but a missing bar must not stop the job
        bar = recordings
    for name, path in bar:
        fp = fingerprint(source_files(path), settings)
        prev = old.get(name)
        if (
            not rebuild and prev is not None and prev.get("fingerprint") == fp
            and recording_reusable(out, prev, log=lambda m: print(m, file=sys.stderr))
        ):
            manifest["recordings"].append(prev)
            continue
        t0 = time.perf_counter()
        rec = load_recording(path, format=dataset, options=options, **topics)
        require_one_window(path, rec.segments, window)
        segments = []
        for i, seq in enumerate(rec.segments):
            lab = window_labels(seq, window, stride, PAPER_FRACTIONS, gravity)
            stored = write_segment(out, f"{name}__{i}", seq, lab.__dict__)
            segments.append({"name": seq.name, **stored, "samples": len(seq), "windows": int(len(lab.starts))})
        manifest["recordings"].append(
            {"name": name, "path": str(path), "fingerprint": fp, "segments": segments, "report": rec.report,
             "seconds": round(time.perf_counter() - t0, 3)}
        )
        # The progress after each recording makes an interrupted run resumable.
        write_progress(out, manifest)
    write_manifest(out, manifest)
    return manifest


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m imu_learn.labels", description=__doc__.splitlines()[0])
    ap.add_argument("dataset", choices=DATASETS)
    ap.add_argument("--root", type=Path, help="dataset folder (default datasets/<dataset>)")
    ap.add_argument("--out", type=Path, help="cache folder (default cache/<dataset>)")
    ap.add_argument("--window", type=int, default=200, help="window length in IMU samples")
    ap.add_argument("--stride", type=int, default=10, help="step between window starts")
    ap.add_argument("--gravity", type=float, default=9.81)
    ap.add_argument(
        "--max-gap", type=float, default=AlignOptions.max_gap_s, help="split at GT gaps longer than this [s]"
    )
    ap.add_argument("--imu-topic", help="rosbag: the sensor_msgs/msg/Imu topic (default: each bag's only one)")
    ap.add_argument("--groundtruth-topic", help="rosbag: the PoseStamped / TransformStamped / Odometry topic")
    ap.add_argument("--rebuild", action="store_true", help="rebuild everything, even an incompatible cache")
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args(argv)
    root = a.root or Path("datasets") / a.dataset
    out = a.out or Path("cache") / a.dataset
    try:
        m = build_cache(
            a.dataset, root, out, a.window, a.stride, a.gravity, AlignOptions(max_gap_s=a.max_gap),
            a.rebuild, not a.quiet, {"imu_topic": a.imu_topic, "groundtruth_topic": a.groundtruth_topic},
        )
    except (ImuError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: finished recordings are kept; run again to resume", file=sys.stderr)
        return 130
    for r in m["recordings"]:
        rep = r["report"]
        segs = ", ".join(f"{s['samples']} samples / {s['windows']} windows" for s in r["segments"])
        print(
            f"{r['name']}: {len(r['segments'])} segment(s) [{segs}]; dropped "
            f"{rep.get('dropped_before', 0)} before, {rep.get('dropped_after', 0)} after, "
            f"{rep.get('dropped_in_gaps', 0)} in gaps"
        )
    print(f"cache: {out} (format v{CACHE_VERSION})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
