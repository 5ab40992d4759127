"""Fetch mobile robot recordings of UMich-CURLY/Debias_IMU (Liu et al., RSS 2025; MIT license):
``<recording>/mav0/imu0/data.csv`` (``# timestamp, wx, wy, wz, ax, ay, az``, 100 Hz) and
``<recording>/mav0/mocap0/data.csv`` (``# timestamp, x, y, z, qw, qx, qy, qz``, ~90 Hz).

The layout is ASL-like, but every number, the nanosecond stamps included, is a float64 printed in
full (``1.691116804753040896e+18``). Such a stamp is parsed as the float64 it denotes and converted
to int64 ns exactly; at this epoch (~1.7e18 ns) neighbouring float64 values are 256 ns apart, so the
stamps carry 256 ns resolution, which is what the recorder kept (the IMU period is 10 ms). The Rust
ASL reader does not read these files (it checks the EuRoC header names and refuses float stamps
unless asked); parsing here is plain Python, strict, with a typed error
(:mod:`imu_learn.errors`) naming file, line, column and field for a bad row.

Ground truth is the mocap pose. Its body frame, measured against the IMU on all six recordings
(docs/experiments/groundtruth.md, docs/datasets.md): the axes agree within a few degrees (gravity and the
horizontal accelerations fix the tilt to ~1° and the yaw to -3…+6°; the gyro alone cannot, the
robot turns about z only), and the stamps within 0…9 ms, so the pose is used as it is.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import (
    ColumnCountError,
    HeaderError,
    NotNumericError,
    TimestampError,
    TooFewRowsError,
)
from imu_learn.util.atomic import atomic_write_text

from .asl import sequence_root
from .fields import number
from .source import ImuSource

NAME = "fetch"
IMU_FILE = Path("mav0") / "imu0" / "data.csv"
MOCAP_FILE = Path("mav0") / "mocap0" / "data.csv"
IMU_NAMES = ("timestamp", "wx", "wy", "wz", "ax", "ay", "az")
MOCAP_NAMES = ("timestamp", "x", "y", "z", "qw", "qx", "qy", "qz")
# Spacing of float64 values at the stamps' epoch (2^60 <= t < 2^61 ns, i.e. 2006..2043): 256 ns.
STAMP_RESOLUTION_NS = 256


def _header_names(line: str) -> Tuple[str, ...]:
    return tuple(f.strip() for f in line.strip().lstrip("#").split(","))


def _first_line(f: Path) -> str:
    try:
        with open(f, encoding="utf-8", errors="replace") as fh:
            return fh.readline()
    except OSError:
        return ""


def detect(path: Path) -> bool:
    """A recording folder (holding ``mav0/imu0/data.csv`` with the Fetch header), its ``mav0``
    folder, or that IMU file itself. Asked before the ASL layout, which would claim the folder."""
    path = Path(path)
    if path.is_file():
        f = path
    elif path.name == "mav0":
        f = path / "imu0" / "data.csv"
    else:
        f = path / IMU_FILE
    return f.is_file() and _header_names(_first_line(f)) == IMU_NAMES


def find_recordings(root: Path) -> List[Path]:
    """Every recording folder (holding ``mav0`` with a Fetch IMU file) under ``root``."""
    return [p.parent for p in Path(root).rglob("mav0") if p.is_dir() and detect(p.parent)]


# The folder holding ``mav0`` for a recording folder, its ``mav0`` or a file inside it: the ASL rule.
recording_root = sequence_root


def imu_file(path: Path) -> Path:
    path = Path(path)
    if path.is_file():
        return path
    f = recording_root(path) / IMU_FILE
    if not f.exists():
        raise FileNotFoundError(2, "No such file or directory", str(f))
    return f


def parse_stamp(text: str) -> int:
    """A stamp written as a float64 in any notation -> int64 ns: the float64 the text denotes,
    converted exactly (``1.691116804753040896e+18`` -> 1691116804753040896). Raises ValueError for
    text that is not a finite, integral number of ns within int64."""
    x = float(text)  # ValueError for non-numbers
    if not math.isfinite(x) or x != math.floor(x) or not (-(2**63) <= x < 2**63):
        raise ValueError(text)
    return int(x)


def read_table(path: Path, names: Tuple[str, ...]) -> Tuple[np.ndarray, np.ndarray]:
    """``(t_ns (N,) int64, values (N, len(names) - 1) float64)`` of a Fetch CSV, strictly: the header
    must name ``names``; every row has that many comma-separated numbers, finite, with strictly
    increasing integral ns stamps. Blank lines only at the end. Errors name file, line and field."""
    path = Path(path)
    p = str(path)
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        lines = fh.read().splitlines()
    if not lines:
        raise TooFewRowsError(f"{p}: empty file", p, 0)
    if _header_names(lines[0]) != names:
        raise HeaderError(f"{p}:1: header {lines[0]!r} is not the expected '# {', '.join(names)}'", p, 1)
    n = len(lines)
    while n > 1 and not lines[n - 1].strip():
        n -= 1
    w = len(names)
    t = np.empty(n - 1, dtype=np.int64)
    v = np.empty((n - 1, w - 1), dtype=np.float64)
    prev = None
    for i in range(1, n):
        lineno = i + 1
        fields = lines[i].split(",")
        if len(fields) != w:  # a blank line inside the data too
            raise ColumnCountError(f"{p}:{lineno}: expected {w} columns ({', '.join(names)}), found {len(fields)}",
                                   p, lineno, None, None)
        for c, (text, name) in enumerate(zip(fields, names)):
            text = text.strip()
            x = number(text, p, lineno, c + 1, name)
            if c == 0:
                try:
                    stamp = parse_stamp(text)
                except ValueError:
                    raise NotNumericError(f"{p}:{lineno}: column 1 ({name}): {text!r} is not an integral number "
                                          "of nanoseconds within int64", p, lineno, 1, name) from None
                if prev is not None and stamp <= prev:
                    what = "duplicates" if stamp == prev else "precedes"
                    raise TimestampError(f"{p}:{lineno}: column 1 ({name}): {stamp} ns {what} the previous stamp "
                                         f"{prev} ns (stamps must increase strictly)", p, lineno, 1, name)
                t[i - 1] = prev = stamp
            else:
                v[i - 1, c - 1] = x
    if len(t) < 2:
        raise TooFewRowsError(f"{p}: {len(t)} data row(s); at least 2 are needed", p, n)
    return t, v


def read_imu(path: Path) -> ImuData:
    t, v = read_table(imu_file(path), IMU_NAMES)
    return ImuData(t_ns=t, gyro=np.ascontiguousarray(v[:, :3]), acc=np.ascontiguousarray(v[:, 3:]))


def is_mocap_file(path: Path) -> bool:
    """Whether ``path`` is a file headed as a Fetch recording's motion capture (:data:`MOCAP_NAMES`)."""
    return Path(path).is_file() and _header_names(_first_line(Path(path))) == MOCAP_NAMES


def read_mocap(path: Path) -> GroundTruth:
    """The mocap pose (``mav0/mocap0/data.csv`` of a recording, or the file itself)."""
    path = Path(path)
    f = path if path.is_file() else recording_root(path) / MOCAP_FILE
    t, v = read_table(f, MOCAP_NAMES)
    return GroundTruth(t_ns=t, p=np.ascontiguousarray(v[:, :3]), q_wxyz=np.ascontiguousarray(v[:, 3:]), v=None)


def read_recording(
    path: Path, groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
) -> Tuple[ImuData, GroundTruth]:
    """IMU and mocap pose of a recording. ``allow_float_timestamps`` is accepted for the common
    signature and has no effect: float-notation stamps are this format's own, read exactly."""
    imu = read_imu(path)
    gt = read_mocap(Path(groundtruth) if groundtruth is not None else recording_root(Path(path)))
    return imu, gt


def read_imu_source(path: Path) -> ImuSource:
    f = imu_file(Path(path))
    imu = read_imu(f)
    root = recording_root(f)
    return ImuSource(NAME, f, root, f.relative_to(root), imu.t_ns, imu.gyro, imu.acc)


def format_row(t_ns: int, values) -> str:
    """One row as the recorder writes them: the stamp as the float64 it is, printed in full."""
    return ",".join([f"{float(t_ns):.18e}"] + [repr(float(x)) for x in values])


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray) -> None:
    """``out``: ``src``'s IMU CSV with gyro and acc replaced; header and stamps kept (the stamps are
    float64 values, so ``%.18e`` writes each one back to the same text's value)."""
    header = _first_line(src.imu_file).rstrip("\r\n")
    g, a = np.asarray(gyro, dtype=np.float64), np.asarray(acc, dtype=np.float64)
    rows = [format_row(int(t), np.concatenate([g[i], a[i]])) for i, t in enumerate(src.t_ns)]
    atomic_write_text(out, "\n".join([header] + rows) + "\n")
