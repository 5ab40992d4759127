"""Exception classes raised by imu_learn and its Rust core.

Every core error kind has its own class, all under :class:`ImuError`. Parse errors carry the
file, the 1-based line and column and the header's field name as attributes, so callers can
report or fix the exact cell. A missing file is the built-in :class:`FileNotFoundError`.

The Rust core raises these classes itself (pyo3's ``import_exception!`` in
``crates/imu_core/src/python/errors.rs``): one class per core error kind, HeaderError,
ColumnCountError, NotNumericError, NonFiniteError, TimestampError, FloatTimestampError,
TooFewRowsError, AlignmentError, NoOverlapError, InvalidInputError. Nothing re-wraps them, so
renaming one of them, or changing its constructor's keywords, breaks the core's mapping.
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


class TooFewRowsError(ParseError):
    """A file parses but holds too few rows to use: empty, a header alone, or a single IMU sample
    or ground-truth pose (integration needs an interval, interpolation a pose on each side).
    ``line`` is the last line read (0 for an empty file)."""


class AlignmentError(ImuError):
    """IMU samples and ground truth cannot be put on one time base. ``path`` names the
    ground-truth file and ``imu_path`` the IMU file where they are known (None for arrays)."""

    def __init__(self, message: str, path: Optional[str] = None, imu_path: Optional[str] = None) -> None:
        super().__init__(message)
        self.path = path
        self.imu_path = imu_path


class NoOverlapError(AlignmentError):
    """The ground truth's time span and the IMU's are disjoint (another clock or unit, a time
    offset, or the file of another recording); the message gives both spans."""


class TooShortError(ImuError, ValueError):
    """A recording (``path``) holds no stretch as long as one window of ``needed`` samples; the
    message says how long it is and which setting to lower."""

    def __init__(self, message: str, path: Optional[str] = None, samples: int = 0, needed: int = 0) -> None:
        super().__init__(message)
        self.path = path
        self.samples = samples
        self.needed = needed


class InvalidInputError(ImuError, ValueError):
    """Arrays or settings given by the caller are inconsistent."""


class ImplausibleInputError(InvalidInputError):
    """A user's IMU CSV parses, but its numbers do not fit the column map and units given (a sample
    rate no IMU has, gravity of 1 m/s^2, a gyro reading gravity, ...); the message names the likely
    mistake and ``option`` the option that fixes it (``--time-unit``, ``--acc-unit``, ...)."""

    def __init__(self, message: str, path: Optional[str] = None, option: Optional[str] = None) -> None:
        super().__init__(message)
        self.path = path
        self.option = option


class NoRecordingsError(InvalidInputError):
    """A dataset folder (``path``) holds no recording of the layout asked for."""

    def __init__(self, message: str, path: Optional[str] = None) -> None:
        super().__init__(message)
        self.path = path


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


class BagError(ImuError, ValueError):
    """A ROS bag cannot be used as asked. ``path`` names the bag, ``topic`` the topic concerned
    (None where the error is about the whole bag)."""

    def __init__(self, message: str, path: Optional[str] = None, topic: Optional[str] = None) -> None:
        super().__init__(message)
        self.path = path
        self.topic = topic


class NotABagError(BagError):
    """The path is not a ROS 1 bag or a ROS 2 bag folder."""


class TruncatedBagError(BagError):
    """The file starts like a bag (ROS 1, sqlite3 or mcap) but cannot be read to its end."""


class BagTopicError(BagError):
    """The topic asked for is not in the bag (or none was given and the bag has no single one to
    use); ``topics`` maps each of the bag's topics to its message type, and the message lists them."""

    def __init__(self, message: str, path: Optional[str] = None, topic: Optional[str] = None,
                 topics: Optional[dict] = None) -> None:
        super().__init__(message, path, topic)
        self.topics = dict(topics or {})


class BagTypeError(BagError):
    """The topic holds messages of another type than the one it is read as."""


class BagStampError(BagError):
    """A topic's header stamps do not increase (message ``index`` is at or before the one before it)."""

    def __init__(self, message: str, path: Optional[str] = None, topic: Optional[str] = None, index: int = 0) -> None:
        super().__init__(message, path, topic)
        self.index = index


__all__ = [
    "ImuError",
    "ParseError",
    "HeaderError",
    "ColumnCountError",
    "NotNumericError",
    "NonFiniteError",
    "TimestampError",
    "FloatTimestampError",
    "TooFewRowsError",
    "AlignmentError",
    "NoOverlapError",
    "TooShortError",
    "InvalidInputError",
    "ImplausibleInputError",
    "NoRecordingsError",
    "CacheError",
    "AidingError",
    "AidingOverlapError",
    "BagError",
    "NotABagError",
    "TruncatedBagError",
    "BagTopicError",
    "BagTypeError",
    "BagStampError",
]


def one_line(e: BaseException) -> str:
    """An error as the one line an entry point prints: always ``<Class>: <message>``, the message of
    an OSError with a file being ``path: reason`` (``FileNotFoundError: runs/x: No such file or
    directory``), whitespace collapsed; the notes a reader added to it (``add_note``: a hint at the likely
    mistake) follow after "; "."""
    if isinstance(e, OSError) and e.filename and e.strerror:
        msg = f"{e.filename}: {e.strerror}"
        if e.filename2:
            msg = f"{e.filename} -> {e.filename2}: {e.strerror}"
    elif isinstance(e, FileNotFoundError) and e.filename:
        msg = f"{e.filename}: not found"
    else:
        msg = str(e)
    notes = [str(n) for n in getattr(e, "__notes__", ())]  # hints a reader added (BaseException.add_note)
    msg = "; ".join([msg] + notes) if msg and notes else msg
    return " ".join(f"{type(e).__name__}: {msg}".split()) if msg else type(e).__name__


class ConfigError(ImuError, ValueError):
    """A configuration file or override names an unknown key or gives a value of the wrong type."""


class CheckpointError(ImuError):
    """A checkpoint is missing, corrupt, or of an unknown format."""


class DataPathError(ConfigError, FileNotFoundError):
    """A recording or ground-truth path of ``data.roots`` exists under none of the places tried."""

    def __str__(self) -> str:  # FileNotFoundError's own str would show errno and filename
        return str(self.args[0]) if self.args else ""


class MethodError(ImuError):
    """A method failed to fit, load or predict."""


class MissingExtraError(ImuError, ImportError):
    """A stage needs an optional dependency that is not installed; the message names the extra."""


# navigation aiding (fuse)
class AidingQuaternionError(ParseError):
    """An aiding trajectory row's quaternion is far from unit length (``line`` names the row)."""


class ExtrinsicsError(ParseError):
    """A sensor-to-body extrinsic (``T_BS`` of a Kalibr/ASL ``sensor.yaml``) is missing or malformed;
    ``path`` names the file, ``field`` the entry (``T_BS``, ``T_BS.data``) and ``line`` where known."""


# GNSS/IMU (fuse)
class SolutionQualityError(ParseError):
    """An RTKLIB solution row has a quality flag Q outside 1-6 or an unusable standard deviation."""


# device profiles (calib)
class ProfileError(ParseError):
    """A device profile (``profile.json``) is malformed; ``path`` names the file, ``field`` the entry."""


class ReferenceFrameError(ImuError, ValueError):
    """A reference trajectory cannot be put into the IMU's frame and clock: its rotation does not follow
    the IMU's, its lag is beyond the search, its motion leaves the rotation unobservable, or it holds
    positions only. The message names the cause and the fix."""


class ImplausibleProfileError(ImuError, ValueError):
    """A fitted profile parameter lies outside what a MEMS IMU can be (``field`` names it), or the profile
    does not lower the error against the reference on the held-back block: the symptom of a wrong frame,
    unit or lag, not a finding. ``imu-learn calibrate --force`` writes it anyway, with a warning."""

    def __init__(self, message: str, field: Optional[str] = None) -> None:
        super().__init__(message)
        self.field = field


class NothingObservedError(ImuError, ValueError):
    """The recordings observe nothing of what the command would write: ``calibrate --imu-only`` on a
    recording that never rests measures no noise figure (a profile of class defaults would pass for a
    measurement). ``imu-learn calibrate --force`` writes the class defaults, each marked not measured."""
