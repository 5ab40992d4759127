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

A user's own CSV (:mod:`.csv_columns`: the file's column order and units given by the caller, format
name ``csv-columns``) is no layout of its own: :func:`read_imu_source` and :func:`read_recording` take
it with ``columns=`` (a :class:`CsvColumns`), the one input resolver every command that reads IMU
calls (the CLI's options: :func:`imu_learn.cli.common.add_imu_input_options`). Its
:class:`ImuSource` carries the layout, so :func:`write_imu` writes the user's columns and units back.
Both go through :func:`.csv_columns.read_imu_source`, which checks that the numbers fit the map and
units (:mod:`imu_learn.data.formats.input_checks`) before any work.

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

from . import asl, blackbird, broad, csv_columns, fetch, gnss_imu, kaist, rosbag
from .csv_columns import CsvColumns
from .groundtruth import read_groundtruth
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

# A user's CSV read by its column map (``--format csv-columns``, or implied by ``columns=``).
USER_CSV = csv_columns.NAME

__all__ = ["FORMATS", "USER_CSV", "CsvColumns", "ImuSource", "detect_format", "layout", "read_imu_source",
           "read_recording", "write_imu"]


def detect_format(path: Path) -> str:
    """The name of the layout that ``path`` (a recording folder or file) is in."""
    path = Path(path)
    for module in DETECTION_ORDER:
        if module.detect(path):
            return module.NAME
    raise InvalidInputError(
        f"{path}: cannot tell the dataset format from its layout; give it with --format (format= in Python), one of "
        f"{', '.join(sorted(FORMATS))}, or a CSV of your own with --columns"
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


def user_csv(format: str = "auto", columns: Optional[CsvColumns] = None) -> Optional[CsvColumns]:
    """The layout of a user's CSV when the input is one (``columns`` given, or ``format`` is
    ``csv-columns``: then the default map ``t,gx,gy,gz,ax,ay,az`` in ns, rad/s, m/s^2), else None."""
    if columns is None:
        return CsvColumns(columns_named=False) if format == USER_CSV else None
    if format not in ("auto", USER_CSV):
        raise InvalidInputError(f"the column map and units describe a user's CSV (format {USER_CSV}); "
                                f"the {format} format has its own layout")
    return columns


def _no_topics(**topics: Optional[str]) -> None:
    given = [k for k, v in topics.items() if v is not None]
    if given:
        raise InvalidInputError(f"{', '.join(given)} only apply to ROS bags, not to a user's CSV")


def read_recording(
    path: Path,
    format: str = "auto",
    groundtruth: Optional[Path] = None,
    allow_float_timestamps: bool = False,
    imu_topic: Optional[str] = None,
    groundtruth_topic: Optional[str] = None,
    columns: Optional[CsvColumns] = None,
) -> Tuple[ImuData, GroundTruth]:
    """The IMU and ground truth of a recording in any layout, or of a user's CSV (``columns``;
    its ground truth is the file ``groundtruth``, a TUM trajectory or an ASL state / pose CSV)."""
    path = _existing(path)
    csv = user_csv(format, columns)
    if csv is not None:
        _no_topics(imu_topic=imu_topic, groundtruth_topic=groundtruth_topic)
        if groundtruth is None:
            raise InvalidInputError(f"{path}: a user's CSV holds the IMU only; name its reference trajectory "
                                    "(--groundtruth FILE: TUM, or an ASL state or pose CSV)")
        src = csv_columns.read_imu_source(path, csv)
        imu = ImuData(t_ns=src.t_ns, gyro=src.gyro, acc=src.acc)
        return imu, read_groundtruth(_existing(groundtruth), allow_float_timestamps)
    module = layout(path, format)
    topics = _topics(module, imu_topic=imu_topic, groundtruth_topic=groundtruth_topic)
    return module.read_recording(path, groundtruth=groundtruth, allow_float_timestamps=allow_float_timestamps,
                                 **topics)


def read_imu_source(path: Path, format: str = "auto", imu_topic: Optional[str] = None,
                    columns: Optional[CsvColumns] = None) -> ImuSource:
    """The one input resolver: the IMU of a recording (no ground truth needed) and where it lives,
    in any layout (``format``: a name of :data:`FORMATS`, ``csv-columns`` or ``auto``) or a user's
    CSV (``columns``: its column map and units, carried by the source for :func:`write_imu`)."""
    path = _existing(path)
    csv = user_csv(format, columns)
    if csv is not None:
        _no_topics(imu_topic=imu_topic)
        return csv_columns.read_imu_source(path, csv)
    module = layout(path, format)
    return module.read_imu_source(path, **_topics(module, imu_topic=imu_topic))


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray) -> None:
    """Write ``src``'s IMU file to ``out`` in its own layout with ``gyro`` / ``acc`` replaced (a
    user's CSV in its own columns and units)."""
    module = csv_columns if src.fmt == USER_CSV else FORMATS[src.fmt]
    module.write_imu(src, Path(out), gyro, acc)
