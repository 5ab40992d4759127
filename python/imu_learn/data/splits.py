"""Train / validation / test split BY SEQUENCE, from the run config, recorded in the run folder.

Every split names recordings (as found under ``data.roots``; all gap-free segments of a recording go
to the same split). A name may carry a time block, ``NAME[a:b]``: the part of the recording from
fraction a to fraction b of its duration (cut on IMU samples, so two blocks of one recording share
no sample and no training window reaches into the other). Blocks of one recording used by
different splits must not overlap; a recording used whole may appear in one split only.

The default run has only the two shipped 60 s EuRoC crops, so:

    train = MH_01_easy[0:0.8]   first 48 s
    val   = MH_01_easy[0.8:1]   last 12 s: a disjoint time block of the same flight, used only for
                                model selection (best.pt); it is not independent of train (same
                                device, same day, same bias), so it is optimistic
    test  = V1_01_easy          another flight in another room, never seen in training or selection

``split.json`` in the run folder lists the data root used (``data_root``: absolute, or null),
then, per split, each entry, the recording path and format, the time block, and the segments with
their sample ranges and durations.

Relative ``data.roots[i].path`` and ``.groundtruth`` are taken from the data root
(``data.data_root``: ``--data-root DIR``, else the environment variable ``IMU_LEARN_DATA``,
else the config file's value) when one is set, else (and for paths not under it) from the working
directory. Only when imu_learn runs from a source checkout (:func:`checkout_root`: an editable or
``maturin develop`` install, never an installed wheel) is the checkout's root tried last, so the
default run's shipped crops (``datasets/euroc/...`` in ``configs/default.toml``) resolve from any
working directory there. A path found nowhere is a :class:`DataPathError` naming the config key,
the paths tried and how to set the data root.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np

from imu_learn.data.config import DataConfig, RootConfig
from imu_learn.data.datasets import DATASETS, find_recordings
from imu_learn.data.formats import USER_CSV, CsvColumns
from imu_learn.data.label_builder import RecordingSource, cached_segments, dataset_options
from imu_learn.data.loading import AlignOptions, load_sequence, recording_label
from imu_learn.data.types import Segment
from imu_learn.errors import (
    ConfigError,
    DataPathError,  # noqa: F401  (defined with every error class)
    TooShortError,
)
from imu_learn.settings import DATA_ROOT_ENV
from imu_learn.util.atomic import atomic_write_bytes

SPLITS = ("train", "val", "test")
_BLOCK = re.compile(r"^(?P<name>.+?)\[(?P<a>[^:\]]*):(?P<b>[^\]]*)\]$")


def checkout_root() -> Optional[Path]:
    """The source checkout imu_learn runs from (the folder holding ``pyproject.toml`` and
    ``python/imu_learn``), or None for an installed package: relative data paths fall back to it
    only in a checkout, so an installed wheel resolves them from the data root or the working
    directory alone."""
    pkg = Path(__file__).resolve().parents[1]  # .../imu_learn
    root = pkg.parents[1]  # <checkout>/python/imu_learn -> <checkout>
    if pkg.parent.name == "python" and (root / "pyproject.toml").is_file():
        return root
    return None


@dataclass(frozen=True)
class SplitEntry:
    name: str  # recording name
    start: float = 0.0  # fraction of the duration
    stop: float = 1.0

    @property
    def label(self) -> str:
        return self.name if (self.start, self.stop) == (0.0, 1.0) else f"{self.name}[{self.start:g}:{self.stop:g}]"


def parse_entry(text: str, key: str = "data.split") -> SplitEntry:
    m = _BLOCK.match(text.strip())
    if not m:
        if "[" in text or "]" in text:
            raise ConfigError(f"{key}: {text!r} is not NAME or NAME[a:b]")
        return SplitEntry(text.strip())
    try:
        a = float(m["a"]) if m["a"].strip() else 0.0
        b = float(m["b"]) if m["b"].strip() else 1.0
    except ValueError:
        raise ConfigError(f"{key}: {text!r}: block bounds must be numbers") from None
    if not (0.0 <= a < b <= 1.0):
        raise ConfigError(f"{key}: {text!r}: need 0 <= a < b <= 1")
    return SplitEntry(m["name"], a, b)


def parse_split(data: DataConfig) -> Dict[str, List[SplitEntry]]:
    out = {s: [parse_entry(t, f"data.split.{s}") for t in getattr(data.split, s)] for s in SPLITS}
    # Overlap check between and within splits, per recording.
    spans: Dict[str, List[Tuple[float, float, str]]] = {}
    for s, entries in out.items():
        for e in entries:
            for a, b, other in spans.get(e.name, []):
                if e.start < b and a < e.stop:
                    raise ConfigError(
                        f"data.split.{s}: {e.label} overlaps {other} (splits must not share data)"
                    )
            spans.setdefault(e.name, []).append((e.start, e.stop, f"{e.label} in {s}"))
    return out


def resolve_path(p: str) -> Path:
    """A config path: as given (absolute, or from the working directory), else from the source
    checkout's root when running from one (:func:`checkout_root`)."""
    path = Path(p).expanduser()
    if path.is_absolute() or path.exists():
        return path
    repo = checkout_root()
    alt = repo / path if repo is not None else path
    return alt if alt.exists() else path


def data_root_dir(data: DataConfig) -> Optional[Path]:
    """The data root as an absolute folder (a relative one from the working directory, else the
    source checkout's root when running from one), or None when none is set."""
    if not data.data_root:
        return None
    return resolve_path(data.data_root).resolve()


def resolve_data_path(p: str, data_root: Optional[Path], key: str) -> Path:
    """A ``data.roots`` path (``key`` names it in errors): absolute as given; relative, from the
    data root when one is set, else (or when not there) the working directory, else the source
    checkout's root when running from one (:func:`checkout_root`; never for an installed wheel)."""
    path = Path(p).expanduser()
    if path.is_absolute():
        tried = [path]
    else:
        repo = checkout_root()
        tried = (([data_root / path] if data_root is not None else []) + [path]
                 + ([repo / path] if repo is not None else []))
    for cand in tried:
        if cand.exists():
            return cand
    if data_root is None:
        where = "no data root set"
    elif not data_root.is_dir():
        where = f"data root {data_root} is not a folder"
    else:
        where = f"data root {data_root}"
    shown = ", ".join(str(c) for c in dict.fromkeys(tried))
    raise DataPathError(
        f"{key}: {p!r} not found (tried {shown}; {where}); set the data root with "
        f"{DATA_ROOT_ENV}=DIR or --data-root DIR (see docs/datasets.md)"
    )


def groundtruth_paths(roots: List[RootConfig], data_root: Optional[Path]) -> Dict[int, Path]:
    """``id(root)`` -> its resolved ``groundtruth`` file, for the roots that name one."""
    return {id(r): resolve_data_path(r.groundtruth, data_root, f"data.roots[{i}].groundtruth")
            for i, r in enumerate(roots) if r.groundtruth}


def _format_for(root: RootConfig) -> str:
    fmt = root.format
    if fmt not in DATASETS + (USER_CSV,):
        raise ConfigError(f"data.roots: format {fmt!r} unknown; known: {', '.join(DATASETS + (USER_CSV,))}")
    if fmt == USER_CSV and not (root.columns and root.groundtruth):
        raise ConfigError(f"data.roots: format {USER_CSV!r} is one user's CSV recording: give its path, its columns "
                          "(and time_unit, gyro_unit, acc_unit as the commands' options) and its groundtruth file")
    return fmt


def root_columns(root: RootConfig) -> Optional[CsvColumns]:
    """A ``csv-columns`` root's column map and units (None for a dataset layout)."""
    if root.format != USER_CSV:
        return None
    return CsvColumns(root.columns, root.time_unit, root.gyro_unit, root.acc_unit)


def find_all(roots: List[RootConfig], data_root: Optional[Path] = None) -> Dict[str, Tuple[Path, RootConfig]]:
    """Recording name -> (path, root) over all roots (relative paths from ``data_root``, see
    :func:`resolve_data_path`); duplicate names are an error."""
    found: Dict[str, Tuple[Path, RootConfig]] = {}
    for i, root in enumerate(roots):
        fmt = _format_for(root)
        path = resolve_data_path(root.path, data_root, f"data.roots[{i}].path")
        if root.groundtruth:
            recs = [(recording_label(path, fmt == USER_CSV), path)]
        else:
            recs = find_recordings(fmt, path)
        for name, p in recs:
            if name in found and found[name][0] != p:
                raise ConfigError(f"data.roots[{i}]: recording name {name!r} also found at {found[name][0]}")
            found[name] = (p, root)
    return found


def recording_name(segment_name: str) -> str:
    """The recording a segment came from (``MH_01_easy#2[0:0.85]`` -> ``MH_01_easy``)."""
    return re.split(r"[#\[]", segment_name, maxsplit=1)[0]


def cut(segments: List[Segment], start: float, stop: float, name: str) -> List[Segment]:
    """The part [start, stop) (fractions of the recording's total time span) of its segments."""
    if (start, stop) == (0.0, 1.0):
        return list(segments)
    t0 = min(int(s.t_ns[0]) for s in segments)
    t1 = max(int(s.t_ns[-1]) for s in segments)
    lo = t0 + start * (t1 - t0)
    hi = t0 + stop * (t1 - t0)
    out = []
    for s in segments:
        keep = (s.t_ns >= lo) & ((s.t_ns < hi) if stop < 1.0 else (s.t_ns <= hi))
        idx = np.flatnonzero(keep)
        if len(idx) < 2:
            continue
        a, b = int(idx[0]), int(idx[-1]) + 1
        out.append(
            Segment(
                name=f"{s.name}[{start:g}:{stop:g}]",
                t_ns=s.t_ns[a:b], gyro=s.gyro[a:b], acc=s.acc[a:b], p=s.p[a:b], v=s.v[a:b], q_wxyz=s.q_wxyz[a:b],
            )
        )
    return out


def recording_source(name: str, path: Path, root: RootConfig, groundtruth: Optional[Path]) -> RecordingSource:
    """How recording ``name`` of config root ``root`` is read and aligned (what its cache entry
    depends on)."""
    topics = {"imu_topic": root.imu_topic, "groundtruth_topic": root.groundtruth_topic}
    return RecordingSource(name, path, root.format, groundtruth,
                           AlignOptions(max_gap_s=root_max_gap_s(root), gt_time_offset_s=root.gt_time_offset_s),
                           {k: v for k, v in topics.items() if v}, root_columns(root))


def root_max_gap_s(root: RootConfig) -> float:
    """The ground-truth gap [s] that splits a root's recordings: its ``max_gap_s``, else the one ``labels``
    aligns its format with (:func:`~imu_learn.data.label_builder.dataset_options`)."""
    return float(root.max_gap_s) if root.max_gap_s is not None else dataset_options(root.format).max_gap_s


def from_label_cache(data: DataConfig, entries: Dict[str, List[SplitEntry]],
                     found: Dict[str, Tuple[Path, RootConfig]], gt_paths: Dict[int, Path]) -> Dict[str, List[Segment]]:
    """``data.cache``: the aligned segments of every recording the split names, by name, from the
    label cache (rebuilt there first where missing or stale, see :func:`cached_segments`)."""
    names = [e.name for s in SPLITS for e in entries[s] if e.name in found]
    sources = [recording_source(n, found[n][0], found[n][1], gt_paths.get(id(found[n][1])))
               for n in dict.fromkeys(names)]
    return cached_segments(Path(data.cache).expanduser(), sources, window=data.window,
                           gravity=data.gravity, fractions=data.fractions)


@dataclass
class Split:
    train: List[Segment]
    val: List[Segment]
    test: List[Segment]
    record: Dict[str, object]

    def __getitem__(self, key: str) -> List[Segment]:
        return getattr(self, key)


def make_split(data: DataConfig, min_len: Optional[int] = None) -> Split:
    """Load every named recording and cut it into the configured splits.

    Segments shorter than ``min_len`` samples (default ``window + 1``, one window) are dropped and
    reported; a train or val split left empty is an error.
    """
    entries = parse_split(data)
    root_dir = data_root_dir(data)
    found = find_all(data.roots, root_dir)
    gt_paths = groundtruth_paths(data.roots, root_dir)
    min_len = data.window + 1 if min_len is None else min_len
    cache: Dict[str, List[Segment]] = {}
    if data.cache:  # the label cache's aligned segments instead of the raw files
        cache = from_label_cache(data, entries, found, gt_paths)
    result: Dict[str, List[Segment]] = {}
    record: Dict[str, object] = {"rule": "by sequence; NAME[a:b] is a time block (fractions of the duration)",
                                 "data_root": str(root_dir) if root_dir is not None else None,
                                 "cache": data.cache or None}
    for split in SPLITS:
        seqs: List[Segment] = []
        rows = []
        for e in entries[split]:
            if e.name not in found:
                raise ConfigError(
                    f"data.split.{split}: no recording named {e.name!r} under data.roots "
                    f"(found: {', '.join(sorted(found)) or 'none'})"
                )
            path, root = found[e.name]
            if e.name not in cache:
                src = recording_source(e.name, path, root, gt_paths.get(id(root)))
                cache[e.name] = load_sequence(src.path, src.format, src.groundtruth, options=src.options,
                                              imu_topic=root.imu_topic or None, groundtruth_topic=root.groundtruth_topic or None,
                                              columns=src.columns)
            parts = cut(cache[e.name], e.start, e.stop, e.name)
            kept = [s for s in parts if len(s) >= min_len]
            if not kept:  # the entry would silently add nothing to its split
                longest = max((len(s) for s in parts), default=0)
                raise TooShortError(
                    f"data.split.{split}: {e.label} ({path}) is too short: its longest segment has {longest} "
                    f"samples, fewer than the {min_len} one window needs (data.window = {data.window}); lower data.window "
                    "or add data",
                    str(path), longest, min_len,
                )
            rows.append({
                "entry": e.label,
                "recording": e.name,
                "path": str(path),
                "format": root.format,
                "groundtruth": root.groundtruth or None,
                "groundtruth_path": str(gt_paths[id(root)]) if root.groundtruth else None,
                "block": [e.start, e.stop],
                "segments": [
                    {"name": s.name, "samples": len(s), "t0_ns": int(s.t_ns[0]), "t1_ns": int(s.t_ns[-1]),
                     "duration_s": round(s.duration_s, 3), "used": len(s) >= min_len}
                    for s in parts
                ],
            })
            seqs += kept
        if split in ("train", "val") and not seqs:
            raise ConfigError(f"data.split.{split}: no segment of at least {min_len} samples")
        result[split] = seqs
        record[split] = rows
    return Split(result["train"], result["val"], result["test"], record)


def write_split(split: Split, path: Path) -> None:
    text = json.dumps(split.record, indent=2)
    atomic_write_bytes(Path(path), lambda f: f.write(text.encode()))


def split_signature(record: Dict[str, Any], splits: Seq[str] = SPLITS) -> Dict[str, Any]:
    """What a split record (``Split.record``, ``split.json``) holds for ``splits``: segment names,
    sizes and stamps, not where they were read from. Two runs on the same data compare equal."""
    return {k: [[(g["name"], g["samples"], g["t0_ns"], g["t1_ns"]) for g in e["segments"]] for e in record.get(k, [])]
            for k in splits}
