"""imu-learn: learn a low-cost IMU's error model from recordings with ground truth.

Public API (see README):
    load_sequence, load_recording, read_imu, align, AlignOptions   -- data in
    preintegrate, window_labels, integrate_windows                  -- increments
    BatchConfig, AugmentConfig, BatchSampler, make_batch            -- training batches
    errors: ImuError and its subclasses

The names load on first use (PEP 562): ``import imu_learn`` imports nothing heavy, so the console
command installs its Ctrl-C rule before numpy, torch or the core load.
"""
from __future__ import annotations

import importlib

_EXPORTS = {
    "__version__": "imu_learn._imu_core",
    **dict.fromkeys(("AugmentConfig", "Batch", "BatchConfig", "BatchSampler", "make_batch"), "imu_learn.core.batches"),
    **dict.fromkeys(("PAPER_FRACTIONS", "Increments", "WindowLabels", "integrate_windows", "preintegrate",
                     "window_labels"), "imu_learn.core.integration"),
    **dict.fromkeys(("wxyz_to_xyzw", "xyzw_to_wxyz"), "imu_learn.core.quat"),
    **dict.fromkeys(("AlignOptions", "align", "load_recording", "load_sequence", "read_imu"), "imu_learn.data.loading"),
    **dict.fromkeys(("GroundTruth", "ImuData", "Recording", "Segment"), "imu_learn.data.types"),
    **dict.fromkeys(("AidingError", "AidingOverlapError", "AlignmentError", "CacheError", "ColumnCountError",
                     "FloatTimestampError", "HeaderError", "ImuError", "InvalidInputError", "MissingExtraError",
                     "NonFiniteError", "NoOverlapError", "NoRecordingsError", "NotNumericError", "ParseError",
                     "TimestampError", "TooFewRowsError", "TooShortError"), "imu_learn.errors"),
}

__all__ = [
    "__version__",
    "AlignOptions", "align", "load_recording", "load_sequence", "read_imu",
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


def __dir__() -> list:
    return sorted(set(globals()) | set(_EXPORTS))
