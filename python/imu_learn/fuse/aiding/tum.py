"""Aiding trajectories read from text files: poses (or positions) with their stamps, strictly.

Three layouts, one reader: the core's (``imu_core::io::tum::read_trajectory``, through
:func:`imu_learn._imu_core.read_trajectory`), the same reader that reads TUM ground truth:

* ``tum``: ``t tx ty tz qx qy qz qw`` separated by white space, ``t`` in seconds (what evo, ORB-SLAM2
  and most SLAM systems write); positions only: ``t tx ty tz``;
* ``csv``: the same columns separated by commas;
* ``asl``: an ASL CSV (EuRoC/Kalibr): ``timestamp [ns], px, py, pz, qw, qx, qy, qz`` (quaternion
  scalar first), positions only: ``timestamp, px, py, pz``.

ASL stamps in float notation of 1e12 or more (ns since an epoch printed as float64, as Fetch's motion
capture writes them) are read as ns to float64's resolution; a smaller float there is an error.
Lines starting with ``#`` and blank lines are skipped anywhere (a trailing ``# ...`` comment after a
row's fields too); a CSV header line of names (not numbers) is skipped when it is the first line
that is not a comment. Every row must have the column count of the first row. Seconds are
converted to integer nanoseconds from their decimal text (no float rounding: ``1403638127.295097``
is ``1403638127295097000`` ns exactly); digits past the ninth decimal round half to even on the
digits (``1.0000000005`` is ``1000000000`` ns, ``1.0000000015`` is ``1000000002``).

Errors (each a :class:`imu_learn.errors.ParseError` subclass with ``path``, the 1-based ``line``, the
``column`` and the ``field``): a row with another column count (:class:`ColumnCountError`), a cell
that is not a number (:class:`NotNumericError`), NaN or infinity (:class:`NonFiniteError`), a stamp
at or before the one before it (:class:`TimestampError`), a quaternion far from unit length
(:class:`AidingQuaternionError`, checked once the file has parsed), fewer than two rows
(:class:`TooFewRowsError`). :func:`check_overlap` raises :class:`AidingOverlapError` when the
trajectory and the IMU share no time.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Tuple, Union

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.errors import (
    AidingOverlapError,
    AidingQuaternionError,
    ColumnCountError,
    FloatTimestampError,
    NonFiniteError,
    NotNumericError,
    ParseError,
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
    """Decimal seconds (``1403638127.295097``, ``-1.5``, ``12``, ``1.5e-3``) as integer ns, exactly, by
    the readers' rule (digits past the ninth decimal round half to even). ValueError for text that is
    not a number; OverflowError for NaN, infinity or a value past the int64 ns range."""
    return core.seconds_to_ns(text)


def _stamp_text(ns: int, layout: str) -> str:
    if layout == "asl":
        return f"{ns} ns"
    sign, m = ("-" if ns < 0 else ""), abs(ns)
    return f"{sign}{m // 1_000_000_000}.{m % 1_000_000_000:09d} s"


def _reworded(e: ParseError, src: str, layout: str) -> ParseError:
    """The core reader's error in this module's wording (``path:line: column c (name): ...``), same
    class, place and field; the reader's rules are the core's, only the message is worded here."""
    names = ASL_FIELDS if layout == "asl" else TUM_FIELDS
    col = e.column
    name = names[col - 1] if col is not None and 1 <= col <= len(names) else e.field
    where = f"{src}:{e.line}: column {col} ({name})"
    value = getattr(e, "value", None)
    if isinstance(e, FloatTimestampError):
        msg = f"{where}: {value!r} is not an integer ns stamp"
    elif isinstance(e, TimestampError):
        prev = e.previous
        msg = (f"{src}:{e.line}: stamp {_stamp_text(value, layout)} is {'equal to' if value == prev else 'before'} "
               f"the stamp before it ({_stamp_text(prev, layout)}): stamps must increase")
    elif isinstance(e, NotNumericError):
        what = ("an integer ns stamp" if layout == "asl" else "a number of seconds") if col == 1 else "a number"
        msg = f"{where}: {value!r} is not {what}"
        if col == 1 and layout != "asl" and str(value).strip().isdigit() and len(str(value).strip()) >= 16:
            msg += ": it looks like ns since an epoch; TUM stamps are seconds (divide the first column by 1e9)"
    elif isinstance(e, NonFiniteError):
        msg = f"{where}: {value!r} is not finite"
    elif isinstance(e, ColumnCountError):
        msg = f"{src}:{e.line}: {e.found} columns, expected {e.expected} ({' '.join(names[:e.expected])})"
    elif isinstance(e, TooFewRowsError):
        msg = f"{src}: {e.found} trajectory row(s); at least 2 needed"
    else:
        return e
    return type(e)(msg, e.path, e.line, col, name if col is not None else e.field)


EPOCH_NS_MIN = 1e12  # a stamp this large is ns since an epoch (seconds since 1970 are ~1.7e9)


def is_epoch_ns(text: str) -> bool:
    """Whether a stamp's text is ns since an epoch: an integer of 13 digits or more, or a number of
    :data:`EPOCH_NS_MIN` or more in float notation (float64 printed in full, as Fetch's motion capture)."""
    text = str(text).strip()
    if text.isdigit():
        return len(text) >= 13
    try:
        return float(text) >= EPOCH_NS_MIN
    except ValueError:
        return False


def epoch_ns_in_float_notation(e: FloatTimestampError) -> bool:
    """Whether the stamp ``e`` names is ns since an epoch (:func:`is_epoch_ns`; a small float there is more
    likely seconds or a mistake, and stays an error)."""
    value = getattr(e, "value", None)
    return value is not None and is_epoch_ns(str(value))


def read_trajectory(path: Union[str, Path], layout: str = "tum", need_orientation: bool = True) -> Trajectory:
    """The trajectory in ``path`` (module docstring: layouts, comments, errors). With
    ``need_orientation`` rows must carry a quaternion (8 columns); otherwise 4 columns
    (positions) are accepted too."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    src = str(path)
    try:
        d = core.read_trajectory(src, layout, positions_only=not need_orientation)
    except FloatTimestampError as e:
        if not epoch_ns_in_float_notation(e):
            raise _reworded(e, src, layout) from None
        # ns of an epoch in float notation (float64 printed in full, as Fetch's motion capture): read as
        # ns to float64's resolution (256 ns at this epoch), as the Fetch reader reads its IMU
        log.info(f"{src}: stamps in float notation, read as ns (float64 resolution)")
        try:
            d = core.read_trajectory(src, layout, positions_only=not need_orientation, allow_float_timestamps=True)
        except ParseError as e2:
            raise _reworded(e2, src, layout) from None
    except ParseError as e:
        raise _reworded(e, src, layout) from None
    lines = d["lines"]
    q = None
    if d["q_wxyz"] is not None:
        q = d["q_wxyz"][:, [1, 2, 3, 0]]
        norm = np.linalg.norm(q, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOL)
        if len(bad):
            i = int(bad[0])
            names = ASL_FIELDS if layout == "asl" else TUM_FIELDS
            line = int(lines[i])
            raise AidingQuaternionError(
                f"{src}:{line}: quaternion ({', '.join(names[4:])}) has norm {norm[i]:.4g}, expected 1",
                src, line, 5, names[4])
        q = q / norm[:, None]
    return Trajectory(d["t_ns"], d["p"], q, src, lines)


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
