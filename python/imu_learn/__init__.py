"""imu-learn: learn a low-cost IMU's error model from recordings with ground truth.

Public API (see README):
    load_sequence, load_recording, read_imu, align, AlignOptions   -- data in
    preintegrate, window_labels, integrate_windows                  -- increments
    BatchConfig, AugmentConfig, BatchSampler, make_batch            -- training batches
    errors: ImuError and its subclasses
"""
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
