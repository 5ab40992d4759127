"""ROS bags: ROS 1 ``.bag`` files and ROS 2 bag folders (sqlite3 or mcap storage), read and written
with ``rosbags`` (pure Python, no ROS install).

- IMU: ``sensor_msgs/msg/Imu`` on a named topic (or the bag's only IMU topic), stamped by its
  header; ``angular_velocity`` and ``linear_acceleration`` are the gyro and acc.
- Ground truth: a topic of ``geometry_msgs/msg/PoseStamped``, ``geometry_msgs/msg/TransformStamped``
  or ``nav_msgs/msg/Odometry`` (pose only: velocity comes from the poses, as for any pose-only
  ground truth), or a separate TUM / ASL file. ``geometry_msgs/msg/PointStamped`` (EuRoC's Leica)
  has no orientation, so it is aiding for :mod:`imu_learn.fuse`, not ground truth for labels.
- ``write_imu``: a new bag of the input's kind (ROS 1 stays ROS 1; ROS 2 keeps its storage plugin
  and compression) in which only the IMU topic's angular_velocity and linear_acceleration change;
  every other message is copied as raw bytes with its connection and stamp.
- ``write_odometry``: a trajectory as ``nav_msgs/msg/Odometry`` in a bag of a given bag's kind
  (:mod:`imu_learn.fuse`'s output for a bag recording).

The arrays read here go to the same Rust alignment path (``imu_learn.data.loading.align``) as those of
the other binary containers (Blackbird's HDF5, BROAD's MAT).
"""
from __future__ import annotations

import logging
import os
import sqlite3
import struct
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Dict, Iterator, List, Optional, Tuple

import numpy as np

from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import (
    BagStampError,
    BagTopicError,
    BagTypeError,
    InvalidInputError,
    MissingExtraError,
    NotABagError,
    TruncatedBagError,
)
from imu_learn.util.atomic import atomic_write_dir, atomic_write_path

from .groundtruth import read_groundtruth
from .source import ImuSource

logger = logging.getLogger(__name__)

NAME = "rosbag"
IMU_TYPE = "sensor_msgs/msg/Imu"
POSITION_TYPE = "geometry_msgs/msg/PointStamped"

# Where each ground-truth type keeps its position and orientation (attribute paths of the message).
POSE_FIELDS: Dict[str, Tuple[str, Optional[str]]] = {
    "geometry_msgs/msg/PoseStamped": ("pose.position", "pose.orientation"),
    "geometry_msgs/msg/TransformStamped": ("transform.translation", "transform.rotation"),
    "nav_msgs/msg/Odometry": ("pose.pose.position", "pose.pose.orientation"),
    POSITION_TYPE: ("point", None),
}
POSE_TYPES = tuple(t for t, (_, q) in POSE_FIELDS.items() if q is not None)

ROS2_METADATA = "metadata.yaml"
ROS2_STORAGE_SUFFIXES = (".db3", ".mcap")
# The first bytes of each container: a file that starts with one but cannot be read is damaged or
# truncated; one that starts with none is not a bag at all.
MAGIC = {b"#ROSBAG V2.0": "ROS 1 bag", b"\x89MCAP": "mcap file", b"SQLite format 3\x00": "sqlite3 file"}


# --------------------------------------------------------------------------------------------
# What is a bag
# --------------------------------------------------------------------------------------------


def detect(path: Path) -> bool:
    """A ROS 1 ``.bag`` file, a ROS 2 bag folder (holding ``metadata.yaml``), or the ``.db3`` /
    ``.mcap`` storage file inside one."""
    path = Path(path)
    if path.suffix.lower() == ".bag":
        return True
    if path.is_dir():
        return (path / ROS2_METADATA).is_file()
    return path.suffix.lower() in ROS2_STORAGE_SUFFIXES and (path.parent / ROS2_METADATA).is_file()


def find_recordings(root: Path) -> List[Path]:
    """Every ROS 1 ``.bag`` file and ROS 2 bag folder under ``root`` (``root`` itself if it is one)."""
    root = Path(root)
    if detect(root):
        return [bag_path(root)]
    ros1: List[Path] = []
    ros2: List[Path] = []
    seen = set()
    for d, dirs, files in os.walk(root, followlinks=True):  # a linked bag folder is a bag too
        real = os.path.realpath(d)
        if real in seen:  # a link back up the tree: once
            dirs[:] = []
            continue
        seen.add(real)
        here = Path(d)
        ros1 += [here / f for f in files if f.lower().endswith(".bag") and (here / f).is_file()]
        ros2 += [here] if ROS2_METADATA in files else []
    return sorted(ros1 + ros2)


def bag_path(path: Path) -> Path:
    """The bag itself: a ``.bag`` file or a ROS 2 folder (the folder of a storage file)."""
    path = Path(path)
    if path.is_file() and path.suffix.lower() in ROS2_STORAGE_SUFFIXES and (path.parent / ROS2_METADATA).is_file():
        return path.parent
    return path


def is_ros1(bag: Path) -> bool:
    return bag.suffix.lower() == ".bag" and not bag.is_dir()


def _container_kind(bag: Path) -> Optional[str]:
    """What the bag's storage file starts like (None: like no bag container)."""
    files = [bag] if bag.is_file() else sorted(p for p in bag.iterdir() if p.suffix in ROS2_STORAGE_SUFFIXES)
    for f in files:
        try:
            with open(f, "rb") as fh:
                head = fh.read(16)
        except OSError:
            continue
        for magic, kind in MAGIC.items():
            if head.startswith(magic):
                return kind
    return None


def _unreadable(bag: Path, err: BaseException, topic: Optional[str] = None) -> Exception:
    """The typed error for a bag ``rosbags`` could not read: truncated / damaged when its storage
    starts like a bag container, else not a bag."""
    reason = " ".join(str(err).split()) or type(err).__name__
    kind = _container_kind(bag) if bag.exists() else None
    where = f"{bag}" + (f" topic {topic}" if topic else "")
    if kind is None:
        return NotABagError(f"{where}: not a ROS bag ({reason})", str(bag), topic)
    return TruncatedBagError(f"{where}: {kind} is truncated or damaged ({reason})", str(bag), topic)


def _reader_errors() -> Tuple[type, ...]:
    """Every exception ``rosbags`` (and the storage below it) raises for an unreadable bag."""
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error
    from rosbags.serde import SerdeError

    return (AnyReaderError, Reader1Error, Reader2Error, SerdeError, sqlite3.DatabaseError, struct.error,
            EOFError, KeyError, IndexError, UnicodeDecodeError, AssertionError)


def require_rosbags(path: Path) -> None:
    """:class:`MissingExtraError` naming the bag when ``rosbags`` (the ``bags`` extra) is absent."""
    try:
        import rosbags  # noqa: F401
    except ImportError as e:
        raise MissingExtraError(f"{path}: reading a ROS bag needs the bags extra "
                                "(pip install 'imu-learn[bags]', or rosbags>=0.11 on Python >= 3.10)") from e


@contextmanager
def open_bag(path: Path, topic: Optional[str] = None) -> Iterator[AnyReader]:  # noqa: F821
    """An open ``rosbags`` AnyReader of ``path``; every read error inside the block becomes
    :class:`NotABagError` or :class:`TruncatedBagError` naming the bag (and ``topic``)."""
    require_rosbags(path)
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    bag = bag_path(path)
    if not bag.exists():
        raise FileNotFoundError(2, "No such file or directory", str(bag))
    if bag.is_dir() and not (bag / ROS2_METADATA).is_file():
        raise NotABagError(f"{bag}: not a ROS bag (a folder without {ROS2_METADATA})", str(bag), topic)
    errors = _reader_errors()
    # Bags without embedded definitions (ROS 2 sqlite3 before Iron) decode with the latest
    # standard messages, which is what sensor_msgs / geometry_msgs / nav_msgs still are.
    reader = AnyReader([bag], default_typestore=get_typestore(Stores.LATEST))
    try:
        reader.open()
    except errors as e:
        raise _unreadable(bag, e, topic) from None
    try:
        yield reader
    except errors as e:
        raise _unreadable(bag, e, topic) from None
    finally:
        try:
            reader.close()
        except errors:  # a truncated bag may fail again on close; the error above says why
            pass


def list_topics(path: Path) -> Dict[str, str]:
    """``{topic: message type}`` of a bag (a topic recorded with two types lists both, joined)."""
    with open_bag(path) as reader:
        return _topics(reader)


def _topics(reader) -> Dict[str, str]:
    types: Dict[str, List[str]] = {}
    for c in reader.connections:
        types.setdefault(c.topic, [])
        if c.msgtype not in types[c.topic]:
            types[c.topic].append(c.msgtype)
    return {t: " | ".join(v) for t, v in sorted(types.items())}


def _topic_list(reader) -> str:
    return ", ".join(f"{t} ({ty})" for t, ty in _topics(reader).items()) or "none"


def _connections(reader, bag: Path, topic: str, types: Tuple[str, ...]) -> list:
    """The connections of ``topic``; :class:`BagTopicError` listing the bag's topics when it has
    none, :class:`BagTypeError` when the topic's type is not one of ``types``."""
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        raise BagTopicError(f"{bag}: no topic {topic}; the bag has: {_topic_list(reader)}", str(bag), topic,
                            _topics(reader))
    wrong = sorted({c.msgtype for c in conns if c.msgtype not in types})
    if wrong:
        raise BagTypeError(f"{bag} topic {topic}: type {', '.join(wrong)}, expected {' or '.join(types)}",
                           str(bag), topic)
    return conns


def _only_topic(reader, bag: Path, types: Tuple[str, ...], what: str, option: str) -> str:
    """The bag's one topic of ``types`` (said on stderr); :class:`BagTopicError` when it has none
    or several."""
    found = sorted({c.topic for c in reader.connections if c.msgtype in types})
    if len(found) == 1:
        logger.info("%s: using %s topic %s (the bag's only one)", bag, what, found[0])
        return found[0]
    why = f"no {what} topic" if not found else f"{len(found)} {what} topics ({', '.join(found)})"
    raise BagTopicError(f"{bag}: {why} of type {' or '.join(types)}; pass {option}; the bag has: "
                        f"{_topic_list(reader)}", str(bag), None, _topics(reader))


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------


def _stamp_ns(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _vec(obj, dotted: str) -> object:
    for name in dotted.split("."):
        obj = getattr(obj, name)
    return obj


def _messages(reader, conns: list) -> Iterator[object]:
    """The messages of ``conns`` decoded, in the bag's order."""
    for conn, _t, raw in reader.messages(connections=conns):
        yield reader.deserialize(raw, conn.msgtype)


def _check_stamps(t_ns: np.ndarray, bag: Path, topic: str) -> None:
    """Header stamps must increase strictly (the alignment and the integration need it)."""
    if len(t_ns) == 0:
        raise BagTopicError(f"{bag} topic {topic}: no messages", str(bag), topic)
    back = np.flatnonzero(np.diff(t_ns) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise BagStampError(
            f"{bag} topic {topic}: header stamp of message {i} ({int(t_ns[i])} ns) does not come after "
            f"message {i - 1}'s ({int(t_ns[i - 1])} ns)",
            str(bag), topic, i,
        )


def _imu_arrays(reader, bag: Path, topic: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    conns = _connections(reader, bag, topic, (IMU_TYPE,))
    t, g, a = [], [], []
    for msg in _messages(reader, conns):
        t.append(_stamp_ns(msg))
        w, f = msg.angular_velocity, msg.linear_acceleration
        g.append((w.x, w.y, w.z))
        a.append((f.x, f.y, f.z))
    t_ns = np.asarray(t, dtype=np.int64)
    _check_stamps(t_ns, bag, topic)
    gyro = np.asarray(g, dtype=np.float64).reshape(-1, 3)
    acc = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    bad = np.flatnonzero(~(np.isfinite(gyro).all(1) & np.isfinite(acc).all(1)))
    if bad.size:
        raise InvalidInputError(f"{bag} topic {topic}: message {int(bad[0])} has a non-finite gyro or acc value")
    return t_ns, gyro, acc


def imu_topic_of(reader, bag: Path, imu_topic: Optional[str]) -> str:
    return imu_topic or _only_topic(reader, bag, (IMU_TYPE,), "IMU", "imu_topic= / --imu-topic")


def read_imu(path: Path, imu_topic: Optional[str] = None) -> ImuData:
    """The IMU of a bag: header stamps [ns], angular_velocity, linear_acceleration."""
    bag = bag_path(path)
    with open_bag(bag, imu_topic) as reader:
        topic = imu_topic_of(reader, bag, imu_topic)
        t_ns, gyro, acc = _imu_arrays(reader, bag, topic)
    return ImuData(t_ns=t_ns, gyro=gyro, acc=acc)


def _pose_arrays(reader, bag: Path, topic: str, types: Tuple[str, ...]):
    """(t_ns, p, q_wxyz or None) of a pose or position topic; q is None for PointStamped."""
    conns = _connections(reader, bag, topic, types)
    t, p, q = [], [], []
    for msg in _messages(reader, conns):
        pos_field, rot_field = POSE_FIELDS[msg.__msgtype__]
        pos = _vec(msg, pos_field)
        t.append(_stamp_ns(msg))
        p.append((pos.x, pos.y, pos.z))
        if rot_field is not None:
            r = _vec(msg, rot_field)
            q.append((r.w, r.x, r.y, r.z))
    t_ns = np.asarray(t, dtype=np.int64)
    _check_stamps(t_ns, bag, topic)
    p_arr = np.asarray(p, dtype=np.float64).reshape(-1, 3)
    q_arr = np.asarray(q, dtype=np.float64).reshape(-1, 4) if len(q) == len(t) else None
    bad = np.flatnonzero(~np.isfinite(p_arr).all(1) | (False if q_arr is None else ~np.isfinite(q_arr).all(1)))
    if bad.size:
        raise InvalidInputError(f"{bag} topic {topic}: message {int(bad[0])} has a non-finite pose value")
    return t_ns, p_arr, q_arr


def read_groundtruth_topic(path: Path, topic: Optional[str] = None) -> GroundTruth:
    """Ground truth from a PoseStamped / TransformStamped / Odometry topic (poses; no velocity)."""
    bag = bag_path(path)
    with open_bag(bag, topic) as reader:
        if topic is None:
            topic = _only_topic(reader, bag, POSE_TYPES, "ground-truth", "groundtruth_topic= / --groundtruth-topic")
        conns = [c for c in reader.connections if c.topic == topic]
        if conns and all(c.msgtype == POSITION_TYPE for c in conns):
            raise BagTypeError(
                f"{bag} topic {topic}: {POSITION_TYPE} holds positions only; ground truth for labels needs "
                f"orientation ({' or '.join(POSE_TYPES)}); use it as fuse aiding instead",
                str(bag), topic,
            )
        t_ns, p, q = _pose_arrays(reader, bag, topic, POSE_TYPES)
    return GroundTruth(t_ns=t_ns, p=np.ascontiguousarray(p), q_wxyz=np.ascontiguousarray(q), v=None)


def read_positions(path: Path, topic: str) -> Tuple[np.ndarray, np.ndarray]:
    """(t_ns (N,), p (N, 3)) of a position or pose topic (any of :data:`POSE_FIELDS`' types): the
    aiding :mod:`imu_learn.fuse` reads from a bag."""
    bag = bag_path(path)
    with open_bag(bag, topic) as reader:
        t_ns, p, _ = _pose_arrays(reader, bag, topic, tuple(POSE_FIELDS))
    return t_ns, p


NAVSAT_TYPE = "sensor_msgs/msg/NavSatFix"


def read_navsat(path: Path, topic: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t_ns (N,), latitude/longitude/altitude (N, 3) [deg, deg, m], position_covariance (N, 3, 3)
    [m^2, east-north-up], position_covariance_type (N,), status.status (N,)) of a
    ``sensor_msgs/msg/NavSatFix`` topic, by header stamp: GNSS aiding for :mod:`imu_learn.fuse`."""
    bag = bag_path(path)
    with open_bag(bag, topic) as reader:
        conns = _connections(reader, bag, topic, (NAVSAT_TYPE,))
        t, llh, cov, kind, status = [], [], [], [], []
        for msg in _messages(reader, conns):
            t.append(_stamp_ns(msg))
            llh.append((msg.latitude, msg.longitude, msg.altitude))
            cov.append(np.asarray(msg.position_covariance, dtype=np.float64).reshape(3, 3))
            kind.append(int(msg.position_covariance_type))
            status.append(int(msg.status.status))
    t_ns = np.asarray(t, dtype=np.int64)
    _check_stamps(t_ns, bag, topic)
    return (t_ns, np.asarray(llh, dtype=np.float64).reshape(-1, 3), np.asarray(cov).reshape(-1, 3, 3),
            np.asarray(kind, dtype=np.int64), np.asarray(status, dtype=np.int64))


def read_recording(
    path: Path,
    groundtruth: Optional[Path] = None,
    allow_float_timestamps: bool = False,
    imu_topic: Optional[str] = None,
    groundtruth_topic: Optional[str] = None,
) -> Tuple[ImuData, GroundTruth]:
    """IMU and ground truth of a bag; ground truth from ``groundtruth`` (a TUM / ASL file beside
    the bag, as EuRoC ships its state estimate) or else from a pose topic of the bag."""
    if groundtruth is not None and groundtruth_topic is not None:
        raise InvalidInputError("give either a ground-truth file (--groundtruth) or a bag topic (--groundtruth-topic), "
                                "not both")
    imu = read_imu(path, imu_topic)
    if groundtruth is not None:
        return imu, read_groundtruth(Path(groundtruth), allow_float_timestamps)
    return imu, read_groundtruth_topic(path, groundtruth_topic)


def read_imu_source(path: Path, imu_topic: Optional[str] = None) -> ImuSource:
    bag = bag_path(path)
    with open_bag(bag, imu_topic) as reader:
        topic = imu_topic_of(reader, bag, imu_topic)
        t_ns, gyro, acc = _imu_arrays(reader, bag, topic)
    return ImuSource(NAME, bag, bag.parent, Path(bag.name), t_ns, gyro, acc, topic=topic)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray,
              variances: Optional[np.ndarray] = None) -> None:
    """``out``: a bag of ``src``'s kind with the IMU topic's angular_velocity / linear_acceleration
    replaced by ``gyro`` / ``acc`` (in message order) and everything else copied unchanged.
    ``variances`` (N, 6), gyro then acc, per-sample discrete-time variances ((rad/s)^2, (m/s^2)^2):
    each message's angular_velocity_covariance / linear_acceleration_covariance become their
    diagonal 3x3 (row-major, off-diagonals 0); without it the covariance fields are kept."""
    topic = src.topic
    if topic is None:
        raise InvalidInputError(f"{src.imu_file}: no IMU topic recorded in the source")
    vectors = np.concatenate([np.asarray(gyro, np.float64), np.asarray(acc, np.float64)], axis=1)
    if vectors.shape != (len(src.gyro), 6):
        raise InvalidInputError(f"{src.imu_file} topic {topic}: {len(src.gyro)} IMU messages, got {vectors.shape}")
    covariances = None if variances is None else _diagonal_covariances(src, variances)
    copy_bag(src.imu_file, Path(out), {topic: _imu_rewriter(vectors, covariances)})


def _diagonal_covariances(src: ImuSource, variances: np.ndarray) -> np.ndarray:
    """(N, 2, 9): per message the row-major diagonal 3x3 of its gyro and of its acc variances."""
    var = np.asarray(variances, np.float64)
    if var.shape != (len(src.gyro), 6):
        raise InvalidInputError(f"{src.imu_file} topic {src.topic}: {len(src.gyro)} IMU messages, got variances "
                                f"of shape {var.shape} (want (N, 6), gyro then acc)")
    bad = np.flatnonzero(~(np.isfinite(var) & (var >= 0)).all(1))
    if bad.size:
        raise InvalidInputError(f"{src.imu_file} topic {src.topic}: variance of message {int(bad[0])} is negative "
                                f"or not finite")
    cov = np.zeros((len(var), 2, 3, 3))
    diag = np.arange(3)
    cov[:, 0, diag, diag] = var[:, :3]
    cov[:, 1, diag, diag] = var[:, 3:]
    return cov.reshape(len(var), 2, 9)


def _imu_rewriter(vectors: np.ndarray, covariances: Optional[np.ndarray] = None
                  ) -> Callable[[object, object], object]:
    """Replaces the vectors of the i-th IMU message it is given with row i of ``vectors`` and, when
    ``covariances`` (N, 2, 9) is given, its angular_velocity / linear_acceleration covariances."""
    rows = iter(vectors.tolist())
    covs = iter(covariances) if covariances is not None else None

    def rewrite(msg, typestore) -> object:
        g0, g1, g2, a0, a1, a2 = next(rows)
        vec = typestore.types["geometry_msgs/msg/Vector3"]
        msg.angular_velocity = vec(x=g0, y=g1, z=g2)
        msg.linear_acceleration = vec(x=a0, y=a1, z=a2)
        if covs is not None:
            gyro_cov, acc_cov = next(covs)
            msg.angular_velocity_covariance = gyro_cov
            msg.linear_acceleration_covariance = acc_cov
        return msg

    return rewrite


def copy_bag(bag: Path, out: Path, rewrite: Dict[str, Callable[[object, object], object]],
             extra: Optional[Callable[[object], None]] = None) -> None:
    """Write ``bag`` to ``out`` (same kind), passing the messages of each topic in ``rewrite``
    through its function (``fn(msg, typestore) -> msg``) and copying every other message's bytes.
    ``extra(writer_state)`` may add topics (see :func:`add_topic`). Atomic: a ROS 1 file goes through
    :func:`imu_learn.util.atomic.atomic_write_path`, a ROS 2 folder through ``atomic_write_dir``."""
    bag = bag_path(bag)
    if is_ros1(bag):
        def fill(tmp: Path) -> None:
            tmp.unlink()  # rosbags creates the file itself and refuses an existing one
            _copy_ros1(bag, tmp, rewrite, extra)  # created by open(): the usual permissions

        atomic_write_path(out, fill)
    else:
        atomic_write_dir(out, lambda tmp: _copy_ros2(bag, tmp, rewrite, extra))


class WriterState:
    """What ``extra`` callbacks of :func:`copy_bag` get: the open writer and how to serialize."""

    def __init__(self, writer, typestore, ros1: bool) -> None:
        self.writer = writer
        self.typestore = typestore
        self.ros1 = ros1

    def serialize(self, msg, msgtype: str) -> bytes:
        if self.ros1:
            return bytes(self.typestore.serialize_ros1(msg, msgtype))
        return bytes(self.typestore.serialize_cdr(msg, msgtype))


def _ros1_compression(reader) -> Optional[str]:
    """The chunk compression of a ROS 1 bag (none, bz2, lz4) from its first chunk."""
    from rosbags.rosbag1.reader import decompressors

    names = {fn: name for name, fn in decompressors.items()}
    for r in reader.readers:
        for chunk in r.chunks.values():
            return names.get(chunk.decompressor)
    return None


def _copy_ros1(bag: Path, out: Path, rewrite, extra) -> None:
    from rosbags.rosbag1 import Writer

    with open_bag(bag) as reader:
        writer = Writer(out)
        compression = _ros1_compression(reader)
        if compression in ("bz2", "lz4"):
            writer.set_compression(Writer.CompressionFormat[compression.upper()])
        with writer:
            conns = {}
            for c in reader.connections:
                conns[c.id] = writer.add_connection(
                    c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest,
                    callerid=c.ext.callerid, latching=c.ext.latching,
                )
            _copy_messages(reader, writer, conns, rewrite, ros1=True)
            if extra is not None:
                extra(WriterState(writer, reader.typestore, True))


def _ros2_metadata(bag: Path) -> dict:
    from ruamel.yaml import YAML

    return YAML(typ="safe").load((bag / ROS2_METADATA).read_text())["rosbag2_bagfile_information"]


def _copy_ros2(bag: Path, out: Path, rewrite, extra) -> None:
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin

    meta = _ros2_metadata(bag)
    plugin = StoragePlugin[str(meta.get("storage_identifier", "sqlite3")).upper()]
    version = 8 if int(meta.get("version", 9)) <= 8 else 9  # the versions rosbags writes
    with open_bag(bag) as reader:
        writer = Writer(out, version=version, storage_plugin=plugin)
        mode = str(meta.get("compression_mode") or "none").upper()
        if mode != "NONE" and meta.get("compression_format"):
            writer.set_compression(CompressionMode[mode], CompressionFormat.ZSTD)
        with writer:
            conns = {}
            for c in reader.connections:
                has_def = bool(c.msgdef.data) and bool(c.digest)
                conns[c.id] = writer.add_connection(
                    c.topic, c.msgtype,
                    msgdef=c.msgdef.data if has_def else None,
                    rihs01=c.digest if has_def else None,
                    typestore=None if has_def else reader.typestore,
                    serialization_format=c.ext.serialization_format,
                    offered_qos_profiles=c.ext.offered_qos_profiles,
                )
            _copy_messages(reader, writer, conns, rewrite, ros1=False)
            if extra is not None:
                extra(WriterState(writer, reader.typestore, False))


def _copy_messages(reader, writer, conns: dict, rewrite, ros1: bool) -> None:
    ts = reader.typestore
    for conn, stamp, raw in reader.messages():
        fn = rewrite.get(conn.topic)
        if fn is not None:
            msg = fn(reader.deserialize(raw, conn.msgtype), ts)
            raw = ts.serialize_ros1(msg, conn.msgtype) if ros1 else ts.serialize_cdr(msg, conn.msgtype)
        writer.write(conns[conn.id], stamp, raw)


# --------------------------------------------------------------------------------------------
# A trajectory as a bag topic (imu_learn.fuse's output beside its TUM files)
# --------------------------------------------------------------------------------------------

ODOMETRY_TYPE = "nav_msgs/msg/Odometry"


def bag_kind(path: Path) -> str:
    """``"ros1"``, or a ROS 2 bag's storage plugin (``"sqlite3"``, ``"mcap"``)."""
    bag = bag_path(path)
    if is_ros1(bag):
        return "ros1"
    return str(_ros2_metadata(bag).get("storage_identifier", "sqlite3")).lower()


def output_bag_path(base: Path, like: Path) -> Path:
    """Where a bag of ``like``'s kind named ``base`` goes: ``base.bag`` (a ROS 1 file) or the
    folder ``base`` (ROS 2). The suffix is appended, not swapped: a stem may hold dots."""
    base = Path(base)
    return base.with_name(base.name + ".bag") if is_ros1(bag_path(like)) else base


def write_odometry(out: Path, topic: str, t_ns: np.ndarray, p: np.ndarray, q_wxyz: np.ndarray, like: Path,
                   frame_id: str = "world", child_frame_id: str = "imu") -> None:
    """``out``: a bag of ``like``'s kind (ROS 1, or ROS 2 with its storage plugin and metadata
    version) with one ``nav_msgs/msg/Odometry`` message per pose on ``topic``, stamped (header and
    bag) at ``t_ns``; twist and covariances are zero (not estimated here). Written atomically; a
    previous ``out`` is replaced (a ROS 2 folder through ``atomic_write_dir(..., replace=True)``)."""
    t_ns, p, q_wxyz = _trajectory_arrays(t_ns, p, q_wxyz)
    like = bag_path(like)
    if is_ros1(like):
        def fill(tmp: Path) -> None:
            tmp.unlink()  # rosbags creates the file itself and refuses an existing one
            _write_odometry_ros1(tmp, topic, t_ns, p, q_wxyz, frame_id, child_frame_id)

        atomic_write_path(Path(out), fill)
    else:
        meta = _ros2_metadata(like)
        atomic_write_dir(Path(out), lambda tmp: _write_odometry_ros2(
            tmp, meta, topic, t_ns, p, q_wxyz, frame_id, child_frame_id), replace=True)


def _trajectory_arrays(t_ns, p, q_wxyz) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    t_ns = np.asarray(t_ns, np.int64)
    p, q_wxyz = np.asarray(p, np.float64), np.asarray(q_wxyz, np.float64)
    if t_ns.ndim != 1 or p.shape != (len(t_ns), 3) or q_wxyz.shape != (len(t_ns), 4):
        raise InvalidInputError(f"a trajectory needs t_ns (N,), p (N, 3), q_wxyz (N, 4); got {t_ns.shape}, "
                                f"{p.shape}, {q_wxyz.shape}")
    return t_ns, p, q_wxyz


def _odometry(T, header, pos, q, child_frame_id: str):
    """One Odometry message of the typestore types ``T`` (pose only; twist and covariances zero)."""
    zero3 = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        twist=T["geometry_msgs/msg/Twist"](linear=zero3, angular=zero3), covariance=np.zeros(36))
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=pos[0], y=pos[1], z=pos[2]),
        orientation=T["geometry_msgs/msg/Quaternion"](x=q[1], y=q[2], z=q[3], w=q[0]),
    )
    return T[ODOMETRY_TYPE](header=header, child_frame_id=child_frame_id,
                            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                            twist=twist)


def _odometry_messages(ts, ros1: bool, t_ns, p, q_wxyz, frame_id: str, child_frame_id: str
                       ) -> Iterator[Tuple[int, bytes]]:
    """(stamp, serialized Odometry) per pose; ROS 1 headers carry ``seq``, ROS 2 ones do not."""
    T = ts.types
    for i, (t, pos, q) in enumerate(zip(t_ns.tolist(), p.tolist(), q_wxyz.tolist())):
        stamp = T["builtin_interfaces/msg/Time"](sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)
        header = T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id, **({"seq": i} if ros1 else {}))
        msg = _odometry(T, header, pos, q, child_frame_id)
        raw = ts.serialize_ros1(msg, ODOMETRY_TYPE) if ros1 else ts.serialize_cdr(msg, ODOMETRY_TYPE)
        yield t, bytes(raw)


def _write_odometry_ros1(path: Path, topic: str, t_ns, p, q_wxyz, frame_id: str, child_frame_id: str) -> None:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    with Writer(path) as writer:
        conn = writer.add_connection(topic, ODOMETRY_TYPE, typestore=ts)
        for t, raw in _odometry_messages(ts, True, t_ns, p, q_wxyz, frame_id, child_frame_id):
            writer.write(conn, t, raw)


def _write_odometry_ros2(path: Path, meta: dict, topic: str, t_ns, p, q_wxyz, frame_id: str,
                         child_frame_id: str) -> None:
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.LATEST)
    plugin = StoragePlugin[str(meta.get("storage_identifier", "sqlite3")).upper()]
    version = 8 if int(meta.get("version", 9)) <= 8 else 9  # the versions rosbags writes, as in _copy_ros2
    with Writer(path, version=version, storage_plugin=plugin) as writer:
        conn = writer.add_connection(topic, ODOMETRY_TYPE, typestore=ts)
        for t, raw in _odometry_messages(ts, False, t_ns, p, q_wxyz, frame_id, child_frame_id):
            writer.write(conn, t, raw)
