"""``imu-learn labels DATASET [--data-root DIR | --dataset-dir DIR]``: build the label cache of a dataset.

Reads every recording of the dataset, aligns ground truth to the IMU stamps, computes Δq/Δβ/Δγ
labels for every window and writes them to ``cache/<dataset>`` (see imu_learn.data.cache for the
format). Re-running is cheap: up-to-date recordings are skipped, stale ones rebuilt.
"""
from __future__ import annotations

import logging
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from tqdm import tqdm

from imu_learn._imu_core import __version__
from imu_learn.core.integration import PAPER_FRACTIONS, window_labels
from imu_learn.data.cache import (
    CACHE_VERSION,
    current_manifest,
    fingerprint,
    holding_cache_lock,
    read_segment,
    recording_problem,
    recording_reusable,
    reusable_recordings,
    write_manifest,
    write_progress,
    write_segment,
)
from imu_learn.data.datasets import dataset_max_gap_s, find_recordings
from imu_learn.data.formats import CsvColumns
from imu_learn.data.loading import AlignOptions, load_recording
from imu_learn.data.types import Segment as SeqType
from imu_learn.errors import TooShortError

LOG = logging.getLogger("imu_learn.data.label_builder")


def source_files(path: Path) -> List[Path]:
    return [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]


@dataclass
class RecordingSource:
    """One recording and how it is read and aligned: everything its cached segments depend on."""

    name: str
    path: Path
    format: str
    groundtruth: Optional[Path] = None  # a separate ground-truth file (fit's data.roots[i].groundtruth)
    options: AlignOptions = AlignOptions()
    topics: Dict[str, str] = field(default_factory=dict)  # rosbag: imu_topic / groundtruth_topic
    columns: Optional[CsvColumns] = None  # a user's CSV: its column map and units

    def settings(self) -> Dict[str, Any]:
        topics = {k: v for k, v in self.topics.items() if v}
        gt = str(self.groundtruth.resolve()) if self.groundtruth is not None else None
        return {"format": self.format, "groundtruth": gt, "align": asdict(self.options),
                **({"topics": topics} if topics else {}),
                **({"columns": asdict(self.columns)} if self.columns is not None else {})}

    def fingerprint(self) -> str:
        """Changes when any source file (the recording's files and the ground-truth file) changes
        size or mtime, or any setting of :meth:`settings` does."""
        files = source_files(self.path) + ([self.groundtruth] if self.groundtruth is not None else [])
        return fingerprint(list({p.resolve(): p for p in files}.values()), self.settings())


def label_settings(dataset: Optional[str], window: int, stride: int, gravity: float,
                   fractions: Sequence[float] = PAPER_FRACTIONS) -> Dict[str, Any]:
    """The manifest's ``settings`` for the per-window label tables."""
    return {"dataset": dataset, "window": int(window), "stride": int(stride),
            "fractions": [float(f) for f in fractions], "gravity": float(gravity)}


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


def build_recording(out: Path, src: RecordingSource, settings: Dict[str, Any]) -> Tuple[Dict[str, Any], List[SeqType]]:
    """Read, align and label one recording, write its segment files to ``out``; returns its
    manifest entry and its aligned segments. ``settings``: the manifest's (window, stride,
    fractions, gravity of the label tables)."""
    t0 = time.perf_counter()
    rec = load_recording(src.path, format=src.format, groundtruth=src.groundtruth, options=src.options,
                         columns=src.columns, **{k: v for k, v in src.topics.items() if v})
    window = int(settings["window"])
    require_one_window(src.path, rec.segments, window)
    segments = []
    for i, seq in enumerate(rec.segments):
        lab = window_labels(seq, window, int(settings["stride"]), tuple(settings["fractions"]), float(settings["gravity"]))
        stored = write_segment(out, f"{src.name}__{i}", seq, lab.__dict__)
        segments.append({"name": seq.name, **stored, "samples": len(seq), "windows": int(len(lab.starts))})
    entry = {
        "name": src.name, "path": str(src.path), "fingerprint": fingerprint(source_files(src.path), settings),
        "source": src.settings(), "source_fingerprint": src.fingerprint(),
        "segments": segments, "report": rec.report, "seconds": round(time.perf_counter() - t0, 3),
    }
    return entry, list(rec.segments)


def dataset_options(dataset: Optional[str]) -> AlignOptions:
    """How ``labels`` aligns a dataset's recordings by default: :class:`AlignOptions` with the dataset's own
    ``max_gap_s`` where its reference needs one (:func:`~imu_learn.data.datasets.dataset_max_gap_s`)."""
    gap = dataset_max_gap_s(dataset)
    return AlignOptions() if gap is None else AlignOptions(max_gap_s=gap)


@holding_cache_lock("out")  # two runs on one folder take turns instead of mixing their files
def build_cache(
    dataset: str,
    root: Path,
    out: Path,
    window: int = 200,
    stride: int = 10,
    gravity: float = 9.81,
    options: Optional[AlignOptions] = None,
    rebuild: bool = False,
    progress: bool = True,
    topics: Optional[Dict[str, str]] = None,
) -> dict:
    """``options``: how ground truth is aligned (None: :func:`dataset_options`).
    ``topics``: ``imu_topic`` / ``groundtruth_topic`` for ROS bags (each may be left out where
    every bag has one)."""
    options = dataset_options(dataset) if options is None else options
    topics = {k: v for k, v in (topics or {}).items() if v}
    settings = {
        **label_settings(dataset, window, stride, gravity),
        "align": asdict(options), **({"topics": topics} if topics else {}),
    }
    old = reusable_recordings(out, rebuild, log=LOG.warning)
    recordings = find_recordings(dataset, root)
    manifest = {
        "cache_version": CACHE_VERSION, "imu_learn_version": __version__, "settings": settings,
        "source_root": str(root.resolve()), "recordings": [],
    }
    try:
        bar = tqdm(recordings, desc=f"labels {dataset}", unit="rec", disable=not progress, file=sys.stderr)
    except ImportError:  # tqdm is a dependency, but a missing bar must not stop the job
        bar = recordings
    for name, path in bar:
        src = RecordingSource(name, path, dataset, None, options, topics)
        fp = fingerprint(source_files(path), settings)
        prev = old.get(name)
        if (
            not rebuild and prev is not None and prev.get("fingerprint") == fp
            and prev.get("source_fingerprint") == src.fingerprint()
            and recording_reusable(out, prev, log=LOG.warning)
        ):
            manifest["recordings"].append(prev)
            continue
        entry, _ = build_recording(out, src, settings)
        manifest["recordings"].append(entry)
        # The progress after each recording makes an interrupted run resumable.
        write_progress(out, manifest)
    write_manifest(out, manifest)
    return manifest


@holding_cache_lock("folder")  # not while a labels run is writing the folder
def cached_segments(
    folder: Path,
    sources: List[RecordingSource],
    window: int = 200,
    stride: int = 10,
    gravity: float = 9.81,
    fractions: Sequence[float] = PAPER_FRACTIONS,
    log: Callable[[str], None] = LOG.warning,
) -> Dict[str, List[SeqType]]:
    """The aligned segments of each recording of ``sources`` from the label cache ``folder``
    (what ``fit`` reads with ``data.cache``), by name, without parsing or aligning anything when
    the cache holds them. A recording the cache lacks, or whose source files or alignment settings
    changed since it was cached (``source_fingerprint``), or whose segment files are damaged, is
    read, aligned and labelled again and written into the cache (said through ``log``), so a stale
    entry is never used. A new cache gets label tables of ``window``/``stride``/``gravity``; an
    existing one keeps its own settings. A cache of another format version is a CacheError."""
    folder = Path(folder)
    manifest, problem = current_manifest(folder)
    if problem is not None:
        log(f"label cache {folder}: {problem}; rebuilding the recordings this run reads")
        manifest = None
    if manifest is None:
        manifest = {"cache_version": CACHE_VERSION, "imu_learn_version": __version__,
                    "settings": label_settings(None, window, stride, gravity, fractions),
                    "source_root": None, "recordings": []}
    settings = manifest["settings"]
    recs: List[Dict[str, Any]] = manifest["recordings"]
    out: Dict[str, List[SeqType]] = {}
    changed = False
    for src in sources:
        at = next((i for i, r in enumerate(recs) if r["name"] == src.name), None)
        prev = recs[at] if at is not None else None
        if prev is None:
            why: Optional[str] = "not in the cache"
        elif prev.get("source_fingerprint") != src.fingerprint():
            why = "its source files or how they are read and aligned changed since it was cached"
        else:
            why = recording_problem(folder, prev)
        if why is None and prev is not None:
            out[src.name] = [read_segment(folder, seg, manifest, with_labels=False)[0] for seg in prev["segments"]]
            continue
        log(f"label cache {folder}: building {src.name} ({why})")
        entry, segments = build_recording(folder, src, settings)
        if at is None:
            recs.append(entry)
        else:
            recs[at] = entry
        out[src.name] = segments
        changed = True
    if changed:
        write_manifest(folder, {**manifest, "imu_learn_version": __version__})
    return out


def summary(manifest: dict, out: Path) -> str:
    """What ``imu-learn labels`` prints: one line per recording (segments, windows, samples dropped; a
    recording whose gaps leave more than a fifth of its samples inside the reference's span without a
    window says so, naming ``--max-gap``) and the cache folder."""
    lines = []
    for r in manifest["recordings"]:
        rep = r["report"]
        segs = ", ".join(f"{s['samples']} samples / {s['windows']} windows" for s in r["segments"])
        kept, in_gaps = sum(s["samples"] for s in r["segments"]), rep.get("dropped_in_gaps", 0)
        unused = in_gaps + sum(s["samples"] for s in r["segments"] if not s["windows"])
        lost = (f"; {100 * unused / (kept + in_gaps):.0f} % of its samples inside the reference's span are in its "
                f"gaps or in stretches too short for a window: a larger --max-gap (now "
                f"{manifest['settings']['align']['max_gap_s']:g} s) keeps more") if unused > 0.2 * (kept + in_gaps) else ""
        lines.append(
            f"{r['name']}: {len(r['segments'])} segment(s) [{segs}]; dropped "
            f"{rep.get('dropped_before', 0)} before, {rep.get('dropped_after', 0)} after, "
            f"{in_gaps} in gaps{lost}"
        )
    lines.append(f"cache: {out} (format v{CACHE_VERSION})")
    return "\n".join(lines)
