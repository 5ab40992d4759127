"""imu-learn: learn a low-cost IMU's error model from recordings with ground truth.

Public API (see README):
    load_sequence, load_recording, read_imu, align, AlignOptions   -- data in
    CsvColumns                                                      -- a CSV of your own (columns=)
    preintegrate, window_labels, integrate_windows                  -- increments
    BatchConfig, AugmentConfig, BatchSampler, make_batch            -- training batches
    errors: ImuError and its subclasses

The names load on first use (PEP 562): ``import imu_learn`` imports nothing heavy, so the console
command installs its Ctrl-C rule before numpy, torch or the core load.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, List

if TYPE_CHECKING:  # what __getattr__ loads on first use, for type checkers (kept equal to _EXPORTS by a test)
    from imu_learn._imu_core import __version__
    from imu_learn.core.batches import AugmentConfig, Batch, BatchConfig, BatchSampler, make_batch
    from imu_learn.core.integration import (
        PAPER_FRACTIONS,
        Increments,
        WindowLabels,
        integrate_windows,
        preintegrate,
        window_labels,
    )
    from imu_learn.core.quat import wxyz_to_xyzw, xyzw_to_wxyz
    from imu_learn.data.formats import CsvColumns
    from imu_learn.data.loading import AlignOptions, align, load_recording, load_sequence, read_imu
    from imu_learn.data.types import GroundTruth, ImuData, Recording, Segment
    from imu_learn.errors import (
        AidingError,
        AidingOverlapError,
        AlignmentError,
        CacheError,
        ColumnCountError,
        FloatTimestampError,
        HeaderError,
        ImuError,
        InvalidInputError,
        MissingExtraError,
        NonFiniteError,
        NoOverlapError,
        NoRecordingsError,
        NotNumericError,
        ParseError,
        TimestampError,
        TooFewRowsError,
        TooShortError,
    )

_EXPORTS = {
    "__version__": "imu_learn._imu_core",
    **dict.fromkeys(("AugmentConfig", "Batch", "BatchConfig", "BatchSampler", "make_batch"), "imu_learn.core.batches"),
    **dict.fromkeys(("PAPER_FRACTIONS", "Increments", "WindowLabels", "integrate_windows", "preintegrate",
                     "window_labels"), "imu_learn.core.integration"),
    **dict.fromkeys(("wxyz_to_xyzw", "xyzw_to_wxyz"), "imu_learn.core.quat"),
    **dict.fromkeys(("AlignOptions", "align", "load_recording", "load_sequence", "read_imu"), "imu_learn.data.loading"),
    "CsvColumns": "imu_learn.data.formats",
    **dict.fromkeys(("GroundTruth", "ImuData", "Recording", "Segment"), "imu_learn.data.types"),
    **dict.fromkeys(("AidingError", "AidingOverlapError", "AlignmentError", "CacheError", "ColumnCountError",
                     "FloatTimestampError", "HeaderError", "ImuError", "InvalidInputError", "MissingExtraError",
                     "NonFiniteError", "NoOverlapError", "NoRecordingsError", "NotNumericError", "ParseError",
                     "TimestampError", "TooFewRowsError", "TooShortError"), "imu_learn.errors"),
}

__all__ = [
    "__version__",
    "AlignOptions", "align", "load_recording", "load_sequence", "read_imu", "CsvColumns",
    "preintegrate", "window_labels", "integrate_windows", "Increments", "WindowLabels", "PAPER_FRACTIONS",
    "AugmentConfig", "BatchConfig", "BatchSampler", "Batch", "make_batch",
    "ImuData", "GroundTruth", "Segment", "Recording", "wxyz_to_xyzw", "xyzw_to_wxyz",
    "ImuError", "ParseError", "HeaderError", "ColumnCountError", "NotNumericError", "NonFiniteError",
    "TimestampError", "FloatTimestampError", "AlignmentError", "InvalidInputError", "CacheError",
    "AidingError", "AidingOverlapError", "MissingExtraError", "TooFewRowsError", "NoOverlapError", "TooShortError", "NoRecordingsError",
]


def __getattr__(name: str) -> object:
    """A public name (``_EXPORTS``) or a subpackage, imported on first use."""
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    if not name.startswith("__"):
        try:
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as e:
            if e.name != f"{__name__}.{name}":
                raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> List[str]:
    return sorted(set(globals()) | set(_EXPORTS))
