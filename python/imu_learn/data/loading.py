"""Load a recording: read it (formats/), put ground truth on the IMU stamps (Rust), split at gaps."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Tuple, Union

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.data.formats import CsvColumns, asl, blackbird, detect_format, fetch, read_recording
from imu_learn.data.types import GroundTruth, ImuData, Recording, Segment
from imu_learn.errors import InvalidInputError

PathLike = Union[str, Path]


@dataclass(frozen=True)
class AlignOptions:
    """How ground truth is put on IMU stamps.

    max_gap_s: ground-truth stamps further apart than this split the recording into segments.
    min_segment_s: shorter segments are dropped (too short to hold a training window).
    velocity_half_window: pose-only ground truth gets velocity from a local quadratic fit over
        +-this many poses (see crates/imu_core/src/align.rs for why).
    """

    max_gap_s: float = 0.05
    min_segment_s: float = 1.0
    velocity_half_window: int = 4
    gt_time_offset_s: float = 0.0


def read_imu(path: PathLike, allow_float_timestamps: bool = False) -> ImuData:
    """Read one ASL IMU CSV (``mav0/imu0/data.csv``, or the sequence folder holding it).

    Raises the typed errors of :mod:`imu_learn.errors` naming file, line, column and field.
    """
    return asl.read_imu(Path(path), allow_float_timestamps)


def align(
    imu: ImuData,
    gt: GroundTruth,
    options: AlignOptions = AlignOptions(),
    name: str = "",
    sources: Tuple[Optional[PathLike], Optional[PathLike]] = (None, None),
) -> Recording:
    """Interpolate ground truth onto the IMU stamps; one ``Segment`` per gap-free segment.

    Ground-truth rows with a non-finite position, rotation or velocity (a motion-capture dropout written
    as NaN) are left out, so they become gaps (``report["gt_rows_not_finite"]`` counts them); a
    non-finite IMU sample is an :class:`~imu_learn.errors.InvalidInputError` naming its row.
    ``sources``: the (IMU, ground-truth) files the data came from, named by alignment errors
    (:class:`~imu_learn.errors.NoOverlapError` and the other :class:`~imu_learn.errors.AlignmentError`).
    """
    imu_source, gt_source = (None if s is None else str(s) for s in sources)
    for what, x in (("gyro", imu.gyro), ("acc", imu.acc)):
        bad = np.flatnonzero(~np.isfinite(np.asarray(x, dtype=np.float64)).all(axis=1))
        if len(bad):
            raise InvalidInputError(f"{imu_source or 'the IMU'}: {what} row {int(bad[0])} is not finite "
                                    f"({len(bad)} such rows): the IMU samples must all be numbers")
    keep = np.isfinite(gt.p).all(axis=1) & np.isfinite(gt.q_wxyz).all(axis=1)
    if gt.v is not None:
        keep &= np.isfinite(gt.v).all(axis=1)
    dropped = int(len(keep) - keep.sum())
    if dropped:
        gt = GroundTruth(t_ns=gt.t_ns[keep], p=gt.p[keep], q_wxyz=gt.q_wxyz[keep],
                         v=None if gt.v is None else gt.v[keep])
    rate = (len(imu) - 1) / max((imu.t_ns[-1] - imu.t_ns[0]) * 1e-9, 1e-9) if len(imu) > 1 else 1.0
    segs, report = core.align(
        np.ascontiguousarray(imu.t_ns, dtype=np.int64),
        np.ascontiguousarray(imu.gyro, dtype=np.float64),
        np.ascontiguousarray(imu.acc, dtype=np.float64),
        np.ascontiguousarray(gt.t_ns, dtype=np.int64) + int(round(options.gt_time_offset_s * 1e9)),
        np.ascontiguousarray(gt.p, dtype=np.float64),
        np.ascontiguousarray(gt.q_wxyz, dtype=np.float64),
        None if gt.v is None else np.ascontiguousarray(gt.v, dtype=np.float64),
        int(round(options.max_gap_s * 1e9)),
        max(2, int(round(options.min_segment_s * rate))),
        int(options.velocity_half_window),
        imu_source=imu_source,
        gt_source=gt_source,
    )
    seqs = [
        Segment(name=f"{name}#{i}" if len(segs) > 1 else name, **seg)  # type: ignore[arg-type]
        for i, seg in enumerate(segs)
    ]
    if dropped:
        report = {**report, "gt_rows_not_finite": dropped}
    return Recording(name=name, segments=seqs, report=report)


def recording_label(path: Path, user_csv: bool = False) -> str:
    """A recording's name from its path: a file's stem (a ``.mat``, a ``.bag``, a user's CSV), a folder's name."""
    return path.stem if path.suffix in (".mat", ".bag") or user_csv else path.name


def load_recording(
    path: PathLike,
    format: str = "auto",
    groundtruth: Optional[PathLike] = None,
    options: AlignOptions = AlignOptions(),
    allow_float_timestamps: bool = False,
    imu_topic: Optional[str] = None,
    groundtruth_topic: Optional[str] = None,
    columns: Optional[CsvColumns] = None,
) -> Recording:
    """Read and align a recording; keeps the alignment report (what was dropped, gaps). The topics
    are for ROS bags only (see :func:`load_sequence`); ``columns`` for a user's CSV."""
    path = Path(path)
    gt_path = None if groundtruth is None else Path(groundtruth)
    imu, gt = read_recording(path, format, gt_path, allow_float_timestamps, imu_topic, groundtruth_topic, columns)
    name = recording_label(path, columns is not None)
    return align(imu, gt, options, name=name, sources=source_files(path, format, gt_path))


def source_files(path: Path, format: str = "auto", groundtruth: Optional[Path] = None) -> Tuple[Path, Path]:
    """The IMU file and the ground-truth file a recording was read from, for error messages. Call
    it after the recording was read, so that the layout is known to hold them."""
    fmt = detect_format(path) if format == "auto" else format
    root = path if path.is_dir() else path.parent
    if fmt in ("asl", "euroc", "tum-vi"):
        imu = asl.imu_file(path)
        return imu, groundtruth or asl.find_groundtruth(asl.sequence_root(path))
    if fmt == "blackbird":
        return root / "data.hdf5", groundtruth or root / blackbird.GROUNDTRUTH_NAME
    if fmt == "fetch":
        return fetch.imu_file(path), groundtruth or fetch.recording_root(path) / fetch.MOCAP_FILE
    if fmt == "kaist":
        imu = path if path.is_file() else path / "sensor_data" / "xsens_imu.csv"
        return imu, groundtruth or imu.parent.parent / "global_pose.csv"
    return path, groundtruth or path  # BROAD: one .mat holds both


def load_sequence(
    path: PathLike,
    format: str = "auto",
    groundtruth: Optional[PathLike] = None,
    options: AlignOptions = AlignOptions(),
    allow_float_timestamps: bool = False,
    imu_topic: Optional[str] = None,
    groundtruth_topic: Optional[str] = None,
    columns: Optional[CsvColumns] = None,
) -> List[Segment]:
    """Load a recording as a list of aligned ``Segment`` segments (one unless ground truth has gaps).

    ``format``: "auto" or one of :data:`imu_learn.data.formats.FORMATS` ("euroc", "tum-vi", "asl",
    "blackbird", "broad", "kaist", "fetch", "gnss-imu", "rosbag": a ROS 1 ``.bag`` or a ROS 2 bag folder).
    ``columns``: a CSV of your own (:class:`~imu_learn.data.formats.CsvColumns`), with ``groundtruth``.
    ``groundtruth``: a separate TUM (``t[s] tx ty tz qx qy qz qw``) or ASL ground-truth file.
    ``imu_topic`` / ``groundtruth_topic`` (bags only): the sensor_msgs/msg/Imu topic and the
    PoseStamped / TransformStamped / Odometry topic; each may be left out when the bag has one.
    """
    return load_recording(path, format, groundtruth, options, allow_float_timestamps, imu_topic,
                          groundtruth_topic, columns).segments
