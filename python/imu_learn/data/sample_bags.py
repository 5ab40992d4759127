"""Small ROS bags written with ``rosbags`` itself from an EuRoC ASL recording (the shipped crops:
real EuRoC bags are gigabytes), in the three containers: ROS 1 ``.bag``, ROS 2 sqlite3 and ROS 2
mcap. The test fixtures of the bag reader and writer, and bench/bench_rosbag.py's input.

Topics (EuRoC's own bags carry ``/imu0`` and ``/leica/position``; the others stand for what a
robot's bag holds beside them):

- ``/imu0`` (sensor_msgs/msg/Imu): the recording's IMU, header stamps = the CSV's ns stamps, frame
  ``imu4``, orientation and covariances set to distinctive values so a writer that touched them
  would be seen;
- ``/groundtruth/pose`` (PoseStamped), ``/groundtruth/odom`` (Odometry), ``/groundtruth/tf``
  (TransformStamped): the recording's ground-truth state estimate (poses);
- ``/leica/position`` (PointStamped): ground-truth positions every 10th pose (20 Hz). EuRoC's Leica
  is a separate instrument; these are derived from the state estimate, since the crops ship none;
- ``/cam0/image_raw`` (Image, 752x480 mono8 random bytes, every 5 s) and ``/status`` (String).

Bag receive stamps are the header stamps plus 0.3 ms (a recorder's delay), so code that confused
the two would read other stamps. Writing needs the ``bags`` extra (``rosbags``).
"""
from __future__ import annotations

from pathlib import Path
from typing import Dict

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.data.formats.groundtruth import read_groundtruth
from imu_learn.errors import MissingExtraError

IMU_CSV = Path("mav0") / "imu0" / "data.csv"  # inside an EuRoC ASL recording
GT_CSV = Path("mav0") / "state_groundtruth_estimate0" / "data.csv"
KINDS = ("ros1", "sqlite3", "mcap")
RECEIVE_DELAY_NS = 300_000
TOPICS: Dict[str, str] = {
    "/imu0": "sensor_msgs/msg/Imu",
    "/groundtruth/pose": "geometry_msgs/msg/PoseStamped",
    "/groundtruth/odom": "nav_msgs/msg/Odometry",
    "/groundtruth/tf": "geometry_msgs/msg/TransformStamped",
    "/leica/position": "geometry_msgs/msg/PointStamped",
    "/cam0/image_raw": "sensor_msgs/msg/Image",
    "/status": "std_msgs/msg/String",
}
POSE_TOPICS = ("/groundtruth/pose", "/groundtruth/odom", "/groundtruth/tf")


def bag_name(kind: str) -> str:
    return "run.bag" if kind == "ros1" else f"run_{kind}"


class BagMessages:
    """Message constructors of one typestore (ROS 1 headers carry ``seq``, ROS 2 ones do not)."""

    def __init__(self, typestore, ros1: bool) -> None:
        self.T = typestore.types
        self.ros1 = ros1
        self.seq = 0

    def header(self, t_ns: int, frame: str):
        time = self.T["builtin_interfaces/msg/Time"](sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)
        kw = {"seq": self.seq} if self.ros1 else {}
        self.seq += 1
        return self.T["std_msgs/msg/Header"](stamp=time, frame_id=frame, **kw)

    def vec(self, v):
        return self.T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def point(self, v):
        return self.T["geometry_msgs/msg/Point"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quat(self, q_wxyz):
        w, x, y, z = (float(c) for c in q_wxyz)
        return self.T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)

    def pose(self, p, q):
        return self.T["geometry_msgs/msg/Pose"](position=self.point(p), orientation=self.quat(q))

    def imu(self, t, g, a, i):
        cov = np.arange(9, dtype=np.float64) * 1e-4 + i * 1e-9  # distinctive, different per message
        return self.T["sensor_msgs/msg/Imu"](
            header=self.header(t, "imu4"), orientation=self.quat((1.0, 0.0, 0.0, 0.0)),
            orientation_covariance=np.full(9, -1.0), angular_velocity=self.vec(g),
            angular_velocity_covariance=cov, linear_acceleration=self.vec(a),
            linear_acceleration_covariance=cov * 2,
        )

    def pose_stamped(self, t, p, q):
        return self.T["geometry_msgs/msg/PoseStamped"](header=self.header(t, "world"), pose=self.pose(p, q))

    def odometry(self, t, p, q):
        cov = np.zeros(36)
        pose = self.T["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(p, q), covariance=cov)
        twist = self.T["geometry_msgs/msg/TwistWithCovariance"](
            twist=self.T["geometry_msgs/msg/Twist"](linear=self.vec((0, 0, 0)), angular=self.vec((0, 0, 0))),
            covariance=cov,
        )
        return self.T["nav_msgs/msg/Odometry"](header=self.header(t, "world"), child_frame_id="body", pose=pose,
                                               twist=twist)

    def transform(self, t, p, q):
        tf = self.T["geometry_msgs/msg/Transform"](translation=self.vec(p), rotation=self.quat(q))
        return self.T["geometry_msgs/msg/TransformStamped"](header=self.header(t, "world"), child_frame_id="body",
                                                            transform=tf)

    def point_stamped(self, t, p):
        return self.T["geometry_msgs/msg/PointStamped"](header=self.header(t, "world"), point=self.point(p))

    def image(self, t, rng):
        h, w = 480, 752
        return self.T["sensor_msgs/msg/Image"](
            header=self.header(t, "cam0"), height=h, width=w, encoding="mono8", is_bigendian=0, step=w,
            data=rng.integers(0, 256, h * w, dtype=np.uint8),
        )

    def string(self, text):
        return self.T["std_msgs/msg/String"](data=text)


def sample_messages(msgs: BagMessages, recording: Path, seconds: float = 0.0):
    """(bag stamp, topic, message) of every message of the EuRoC ASL ``recording``, in stamp order;
    ``seconds`` > 0 keeps only the first that many seconds of it."""
    t_imu, gyro, acc = core.read_asl_imu(str(Path(recording) / IMU_CSV))
    gt = read_groundtruth(Path(recording) / GT_CSV)
    if seconds > 0:
        keep_imu = t_imu < t_imu[0] + int(seconds * 1e9)
        t_imu, gyro, acc = t_imu[keep_imu], gyro[keep_imu], acc[keep_imu]
        keep_gt = gt.t_ns < t_imu[0] + int(seconds * 1e9)
    else:
        keep_gt = np.ones(len(gt.t_ns), bool)
    rng = np.random.default_rng(0)
    out = []
    for i, (t, g, a) in enumerate(zip(t_imu.tolist(), gyro, acc)):
        out.append((t, "/imu0", msgs.imu(t, g, a, i)))
    for i, t in enumerate(gt.t_ns[keep_gt].tolist()):
        p, q = gt.p[i], gt.q_wxyz[i]
        out.append((t, "/groundtruth/pose", msgs.pose_stamped(t, p, q)))
        out.append((t, "/groundtruth/odom", msgs.odometry(t, p, q)))
        out.append((t, "/groundtruth/tf", msgs.transform(t, p, q)))
        if i % 10 == 0:
            out.append((t, "/leica/position", msgs.point_stamped(t, p)))
    t0 = int(t_imu[0])
    for k, t in enumerate(range(t0, int(t_imu[-1]), 5_000_000_000)):
        out.append((t, "/cam0/image_raw", msgs.image(t, rng)))
        out.append((t, "/status", msgs.string(f"status {k}")))
    out.sort(key=lambda m: m[0])  # stable: equal stamps keep the order above
    return [(t + RECEIVE_DELAY_NS, topic, m) for t, topic, m in out]


def write_sample_bag(folder: Path, kind: str, recording: Path, seconds: float = 0.0, messages=None,
                     name: str = "") -> Path:
    """A bag of ``kind`` (ros1, sqlite3, mcap) in ``folder`` holding :data:`TOPICS` from the EuRoC
    ASL ``recording``; returns its path. ``messages``: a function of the message constructors
    (:class:`BagMessages`) returning (stamp, topic, msg) to write instead of
    :func:`sample_messages` (for the error cases). ``name``: the bag's file or folder name (default
    :func:`bag_name`)."""
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError as e:
        raise MissingExtraError("writing a ROS bag needs the bags extra "
                                "(pip install 'imu-learn[bags]', or rosbags>=0.11 on Python >= 3.10)") from e

    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    msgs = BagMessages(ts, ros1)
    items = messages(msgs) if messages is not None else sample_messages(msgs, recording, seconds)
    path = Path(folder) / (name or bag_name(kind))
    if ros1:
        from rosbags.rosbag1 import Writer as Writer1

        writer = Writer1(path)
    else:
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        plugin = StoragePlugin.SQLITE3 if kind == "sqlite3" else StoragePlugin.MCAP
        writer = Writer2(path, version=9, storage_plugin=plugin)
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    with writer:
        conns = {}
        for stamp, topic, msg in items:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=ts)
            writer.write(conns[topic], stamp, serialize(msg, msg.__msgtype__))
    return path
