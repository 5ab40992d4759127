"""Aiding trajectories read from text files: poses (or positions) with their stamps, strictly.

Three layouts, one parser (:func:`read_trajectory`):

* ``tum``: ``t tx ty tz qx qy qz qw`` separated by white space, ``t`` in seconds (what evo, ORB-SLAM2
  and most SLAM systems write); positions only: ``t tx ty tz``;
* ``csv``: the same columns separated by commas;
* ``asl``: an ASL CSV (EuRoC/Kalibr): ``timestamp [ns], px, py, pz, qw, qx, qy, qz`` (quaternion
  scalar first), positions only: ``timestamp, px, py, pz``.

Lines starting with ``#`` and blank lines are skipped (a trailing ``# ...`` comment too); a CSV
header line of names (not numbers) is skipped when it is the first line that is not a comment.
Every row must have the column count of the first row. Seconds are converted to integer
nanoseconds from their decimal text (no float rounding: ``1403638127.295097`` is
``1403638127295097000`` ns exactly).

Errors (each a :class:`imu_learn.errors.ParseError` subclass with ``path``, the 1-based ``line``, the
``column`` and the ``field``): a row with another column count (:class:`ColumnCountError`), a cell
that is not a number (:class:`NotNumericError`), NaN or infinity (:class:`NonFiniteError`), a stamp
at or before the one before it (:class:`TimestampError`), a quaternion far from unit length
(:class:`AidingQuaternionError`), fewer than two rows (:class:`TooFewRowsError`).
:func:`check_overlap` raises :class:`AidingOverlapError` when the trajectory and the IMU share no
time.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Tuple, Union

import numpy as np

from imu_learn.data.formats.fields import number
from imu_learn.errors import (
    AidingOverlapError,
    AidingQuaternionError,
    ColumnCountError,
    NonFiniteError,
    NotNumericError,
    TimestampError,
    TooFewRowsError,
)

log = logging.getLogger(__name__)

LAYOUTS = ("tum", "csv", "asl")
TUM_FIELDS = ("t", "tx", "ty", "tz", "qx", "qy", "qz", "qw")
ASL_FIELDS = ("timestamp", "px", "py", "pz", "qw", "qx", "qy", "qz")
# A quaternion whose norm is further than this from 1 is an error, not a rounding to renormalise.
QUAT_NORM_TOL = 1e-2


@dataclass(frozen=True)
class Trajectory:
    """Stamps ``t_ns`` (N,) int64 and positions ``p`` (N, 3); ``q_xyzw`` (N, 4) unit quaternions
    (Hamilton, the pose's rotation into the trajectory's world frame) or None for positions only.
    ``lines``: each row's 1-based line in ``path`` (for messages about a row)."""

    t_ns: np.ndarray
    p: np.ndarray
    q_xyzw: Optional[np.ndarray]
    path: str
    lines: np.ndarray

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def duration_s(self) -> float:
        return (int(self.t_ns[-1]) - int(self.t_ns[0])) * 1e-9 if len(self.t_ns) else 0.0


def seconds_to_ns(text: str) -> int:
    """Decimal seconds (``1403638127.295097``, ``-1.5``, ``12``) as integer ns, exactly; scientific
    notation through float. ValueError for anything else (NaN / infinity included)."""
    s = text.strip()
    body = s[1:] if s[:1] in "+-" else s
    if body and "e" not in body.lower() and body.replace(".", "", 1).isdigit():
        whole, _, frac = body.partition(".")
        frac = (frac + "000000000")[:9]
        ns = int(whole or "0") * 1_000_000_000 + int(frac)
        return -ns if s.startswith("-") else ns
    v = float(s)
    if not math.isfinite(v):
        raise OverflowError(s)
    return int(round(v * 1e9))


def _is_header(cells: List[str]) -> bool:
    def number(c: str) -> bool:
        try:
            float(c)
            return True
        except ValueError:
            return False

    return bool(cells) and not any(number(c) for c in cells)


def read_trajectory(path: Union[str, Path], layout: str = "tum", need_orientation: bool = True) -> Trajectory:
    """The trajectory in ``path`` (module docstring: layouts, comments, errors). With
    ``need_orientation`` rows must carry a quaternion (8 columns); otherwise 4 columns
    (positions) are accepted too."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    path = Path(path)
    src = str(path)
    names = ASL_FIELDS if layout == "asl" else TUM_FIELDS
    sep = None if layout == "tum" else ","
    rows: List[List[float]] = []
    stamps: List[int] = []
    lines: List[int] = []
    ncol: Optional[int] = None
    first_content = True
    with open(path, encoding="utf-8", errors="replace") as f:
        for lineno, raw in enumerate(f, start=1):
            text = raw.split("#", 1)[0].strip()
            if not text:
                continue
            cells = [c.strip() for c in text.split(sep)]
            if first_content and sep is not None and _is_header(cells):
                first_content = False
                continue
            first_content = False
            if ncol is None:
                allowed = (8,) if need_orientation else (4, 8)
                if len(cells) not in allowed:
                    want = " or ".join(str(a) for a in allowed)
                    raise ColumnCountError(
                        f"{src}:{lineno}: {len(cells)} columns, expected {want} ({' '.join(names[:max(allowed)])})",
                        src, lineno, None, None)
                ncol = len(cells)
            elif len(cells) != ncol:
                raise ColumnCountError(f"{src}:{lineno}: {len(cells)} columns, expected {ncol} like the first row",
                                       src, lineno, None, None)
            try:
                stamp = int(cells[0]) if layout == "asl" else seconds_to_ns(cells[0])
            except OverflowError:
                raise NonFiniteError(f"{src}:{lineno}: column 1 ({names[0]}): {cells[0]!r} is not finite",
                                     src, lineno, 1, names[0]) from None
            except ValueError:
                raise NotNumericError(f"{src}:{lineno}: column 1 ({names[0]}): {cells[0]!r} is not "
                                      + ("an integer ns stamp" if layout == "asl" else "a number of seconds"),
                                      src, lineno, 1, names[0]) from None
            vals = []
            for c, cell in enumerate(cells[1:], start=2):
                vals.append(number(cell, src, lineno, c, names[c - 1]))
            if stamps and stamp <= stamps[-1]:
                prev = lines[-1]
                raise TimestampError(
                    f"{src}:{lineno}: stamp {cells[0]} is {'equal to' if stamp == stamps[-1] else 'before'} the "
                    f"stamp on line {prev}: stamps must increase", src, lineno, 1, names[0])
            if ncol == 8:
                q = np.array(vals[3:])
                norm = float(np.linalg.norm(q))
                if abs(norm - 1.0) > QUAT_NORM_TOL:
                    raise AidingQuaternionError(
                        f"{src}:{lineno}: quaternion ({', '.join(names[4:])}) has norm {norm:.4g}, expected 1",
                        src, lineno, 5, names[4])
            stamps.append(stamp)
            rows.append(vals)
            lines.append(lineno)
    if len(rows) < 2:
        last = lines[-1] if lines else 0
        raise TooFewRowsError(f"{src}: {len(rows)} trajectory row(s); at least 2 needed", src, last, None, None)
    arr = np.asarray(rows, dtype=np.float64)
    q = None
    if ncol == 8:
        q = arr[:, 3:7] if layout != "asl" else arr[:, [4, 5, 6, 3]]
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return Trajectory(np.asarray(stamps, dtype=np.int64), arr[:, :3].copy(), q, src,
                      np.asarray(lines, dtype=np.int64))


def read_tum(path: Union[str, Path], need_orientation: bool = True) -> Trajectory:
    """A TUM trajectory file (``t tx ty tz qx qy qz qw``, seconds): :func:`read_trajectory`."""
    return read_trajectory(path, "tum", need_orientation)


def check_overlap(traj: Trajectory, imu_t_ns: np.ndarray, what: str = "aiding") -> Tuple[int, int]:
    """How many rows lie before / after the IMU's time span; :class:`AidingOverlapError` naming the
    file and its lines when none lies inside it."""
    imu_t_ns = np.asarray(imu_t_ns, dtype=np.int64)
    inside = (traj.t_ns >= imu_t_ns[0]) & (traj.t_ns <= imu_t_ns[-1])
    if not inside.any():
        def span(a: int, b: int) -> str:
            return f"[{a * 1e-9:.6f}, {b * 1e-9:.6f}] s ({(b - a) * 1e-9:.3f} s)"

        raise AidingOverlapError(
            f"{traj.path}: lines {int(traj.lines[0])}-{int(traj.lines[-1])}: the {what} and the IMU do not overlap "
            f"in time: the {what} spans {span(int(traj.t_ns[0]), int(traj.t_ns[-1]))}, the IMU "
            f"{span(int(imu_t_ns[0]), int(imu_t_ns[-1]))} (same clock? seconds, not ns? the file of another "
            "recording?)", traj.path, what)
    return int((traj.t_ns < imu_t_ns[0]).sum()), int((traj.t_ns > imu_t_ns[-1]).sum())
