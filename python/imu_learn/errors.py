"""Exception classes raised by imu_learn and its Rust core.

Every core error kind has its own class, all under :class:`ImuError`. Parse errors carry the
file, the 1-based line and column and the header's field name as attributes, so callers can
report or fix the exact cell. A missing file is the built-in :class:`FileNotFoundError`.
"""
from __future__ import annotations

from typing import Optional


class ImuError(Exception):
    """Base class of every error imu_learn raises on purpose."""


class ParseError(ImuError, ValueError):
    """A dataset file is malformed. ``path``, ``line``, ``column`` and ``field`` locate it."""

    def __init__(
        self,
        message: str,
        path: Optional[str] = None,
        line: Optional[int] = None,
        column: Optional[int] = None,
        field: Optional[str] = None,
    ) -> None:
        super().__init__(message)
        self.path = path
        self.line = line
        self.column = column
        self.field = field


class HeaderError(ParseError):
    """The header line is not the one this format expects."""


class ColumnCountError(ParseError):
    """A row has the wrong number of columns."""


class NotNumericError(ParseError):
    """A field that must be a number is empty or not a number."""


class NonFiniteError(ParseError):
    """A field is NaN or infinite."""


class TimestampError(ParseError):
    """Timestamps are not strictly increasing (a duplicate or a step back)."""


class FloatTimestampError(TimestampError):
    """Integer-nanosecond timestamps were written in float notation and have lost precision."""


class AlignmentError(ImuError):
    """IMU samples and ground truth cannot be put on one time base."""


class InvalidInputError(ImuError, ValueError):
    """Arrays or settings given by the caller are inconsistent."""


class CacheError(ImuError):
    """A label cache is missing, stale or written by an incompatible version."""


class AidingError(ImuError, ValueError):
    """Aiding measurements for :mod:`imu_learn.fuse` cannot be used: an aiding file without a single
    fix, or none left after a scenario's outages. ``path`` names the aiding file (None for aiding
    simulated from ground truth), ``label`` the aiding or the scenario."""

    def __init__(self, message: str, path: Optional[str] = None, label: Optional[str] = None) -> None:
        super().__init__(message)
        self.path = path
        self.label = label


class AidingOverlapError(AidingError, AlignmentError):
    """No aiding measurement lies inside the IMU's time span (another clock or unit, a wrong time
    offset, or the file of another recording)."""


__all__ = [
    "ImuError",
    "ParseError",
    "HeaderError",
    "ColumnCountError",
    "NotNumericError",
    "NonFiniteError",
    "TimestampError",
    "FloatTimestampError",
    "AlignmentError",
    "InvalidInputError",
    "CacheError",
    "AidingError",
    "AidingOverlapError",
]


def one_line(e: BaseException) -> str:
    """An error as the one line an entry point prints: ``path: reason`` for a missing file, the
    class name before the message for imu_learn's own errors, whitespace collapsed."""
    if isinstance(e, FileNotFoundError) and e.filename:
        msg = f"{e.filename}: {e.strerror or 'not found'}"
    else:
        msg = str(e) or type(e).__name__
        if isinstance(e, ImuError):
            msg = f"{type(e).__name__}: {msg}"
    return " ".join(msg.split())
