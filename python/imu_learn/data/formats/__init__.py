"""Dataset formats: one module per layout on disk, the only place that knows the layout.

Each of :mod:`.asl` (EuRoC, TUM-VI), :mod:`.blackbird`, :mod:`.broad`, :mod:`.fetch`, :mod:`.gnss_imu`
(an IMU CSV + RTKLIB time tag; no ground truth of its own), :mod:`.kaist` and
:mod:`.rosbag` (ROS 1 / ROS 2 bags; its readers also take ``imu_topic`` / ``groundtruth_topic``) has

- ``NAME`` and ``detect(path) -> bool``: whether ``path`` (a folder or a file) is in this layout;
- ``find_recordings(root)``: every recording of the layout under a dataset folder;
- ``read_recording(path, groundtruth=None, allow_float_timestamps=False)``: ``ImuData`` + ``GroundTruth``;
- ``read_imu_source(path) -> ImuSource``: the IMU alone and where it lives (what refine rewrites);
- ``write_imu(src, out, gyro, acc)``: ``src``'s IMU file written to ``out`` with gyro and acc
  replaced and everything else kept, atomically (:mod:`imu_learn.util.atomic`).

The strict parsing of text formats happens in the Rust core; the modules here only find the files
of a layout and, for binary containers (HDF5, MAT), read arrays with h5py / scipy and hand them to
the same Rust alignment path.
"""
from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Dict, Optional, Tuple

import numpy as np

from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import InvalidInputError

from . import asl, blackbird, broad, fetch, gnss_imu, kaist, rosbag
from .source import ImuSource

# The names ``format=`` / ``--format`` accept, each with its layout's module.
FORMATS: Dict[str, ModuleType] = {
    "asl": asl,
    "euroc": asl,
    "tum-vi": asl,
    "blackbird": blackbird,
    "broad": broad,
    "kaist": kaist,
    "fetch": fetch,
    "gnss-imu": gnss_imu,
    "rosbag": rosbag,
}

# Asked in this order by detect_format; the first layout that claims a path wins. KAIST's
# ``xsens_imu.csv`` is also a ``.csv``, which the ASL rule takes, so KAIST is asked before ASL.
# A ROS 2 bag folder is asked first: nothing else holds a ``metadata.yaml``. Fetch (an ASL-like
# ``mav0`` with its own header) is asked before ASL. A GNSS/IMU log (an IMU ``.csv`` with its RTKLIB
# ``.csv.tag`` beside it) is asked before KAIST and ASL, which would claim a ``.csv``.
DETECTION_ORDER: Tuple[ModuleType, ...] = (rosbag, broad, blackbird, gnss_imu, kaist, fetch, asl)

__all__ = ["FORMATS", "ImuSource", "detect_format", "layout", "read_imu_source", "read_recording", "write_imu"]


def detect_format(path: Path) -> str:
    """The name of the layout that ``path`` (a recording folder or file) is in."""
    path = Path(path)
    for module in DETECTION_ORDER:
        if module.detect(path):
            return module.NAME
    raise InvalidInputError(
        f"{path}: cannot tell the dataset format from its layout; pass format= one of {sorted(FORMATS)}"
    )


def layout(path: Path, format: str = "auto") -> ModuleType:
    """The module of ``format``, or of the layout detected from ``path`` for ``"auto"``."""
    name = detect_format(path) if format == "auto" else format
    if name not in FORMATS:
        raise InvalidInputError(f"unknown format {format!r}; known: {sorted(FORMATS)} or 'auto'")
    return FORMATS[name]


def _existing(path: Path) -> Path:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    return path


def _topics(module: ModuleType, **topics: Optional[str]) -> Dict[str, str]:
    """The bag topics given, for the rosbag layout; an error for any other layout (no topics)."""
    given = {k: v for k, v in topics.items() if v is not None}
    if given and module is not rosbag:
        raise InvalidInputError(f"{', '.join(given)} only apply to ROS bags, not to the {module.NAME} format")
    return given


def read_recording(
    path: Path,
    format: str = "auto",
    groundtruth: Optional[Path] = None,
    allow_float_timestamps: bool = False,
    imu_topic: Optional[str] = None,
    groundtruth_topic: Optional[str] = None,
) -> Tuple[ImuData, GroundTruth]:
    path = _existing(path)
    module = layout(path, format)
    topics = _topics(module, imu_topic=imu_topic, groundtruth_topic=groundtruth_topic)
    return module.read_recording(path, groundtruth=groundtruth, allow_float_timestamps=allow_float_timestamps,
                                 **topics)


def read_imu_source(path: Path, format: str = "auto", imu_topic: Optional[str] = None) -> ImuSource:
    """The IMU of a recording (no ground truth needed) and where it lives, for refine."""
    path = _existing(path)
    module = layout(path, format)
    return module.read_imu_source(path, **_topics(module, imu_topic=imu_topic))


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray) -> None:
    """Write ``src``'s IMU file to ``out`` in its own layout with ``gyro`` / ``acc`` replaced."""
    FORMATS[src.fmt].write_imu(src, Path(out), gyro, acc)
