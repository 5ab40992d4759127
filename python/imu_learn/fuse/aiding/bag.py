"""Aiding from a ROS bag topic (``imu-learn navigate --aiding BAG --aiding-topic TOPIC``), read
through :mod:`imu_learn.data.formats.rosbag` (the ``bags`` extra), by header stamp:

* ``geometry_msgs/msg/PoseStamped``, ``TransformStamped``, ``nav_msgs/msg/Odometry``: poses (the
  pose part; an Odometry's twist is not read), as a :class:`~.tum.Trajectory` like a TUM file's;
* ``geometry_msgs/msg/PointStamped``: positions only;
* ``sensor_msgs/msg/NavSatFix``: GNSS fixes, as an :class:`~.rtklib.RtkSolution` in a local
  east-north-up frame at the first fix (the same WGS-84 formulas as RTKLIB files). Each fix's
  sigmas are the square roots of its ``position_covariance`` diagonal (east, north, up, as the
  message defines it); a fix of covariance type 0 (unknown) takes ``sigma_m``. A message with
  ``status.status`` -1 (no fix) is kept out (counted as a quality not used).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_learn.data.formats import rosbag
from imu_learn.data.formats.rosbag import POSE_TYPES, list_topics, read_groundtruth_topic, read_positions
from imu_learn.errors import BagTopicError, InvalidInputError

from .rtklib import RtkSolution, ecef_to_enu_rotation, llh_to_ecef
from .tum import Trajectory

NAVSAT = "sensor_msgs/msg/NavSatFix"
NO_FIX = -1
Q_FIX, Q_NONE = 1, 5  # the RTKLIB quality flags the fixes take (5 is not fused by default)


def topic_type(bag: Path, topic: str) -> str:
    """The message type of ``topic``; :class:`BagTopicError` listing the bag's topics when absent."""
    topics = list_topics(bag)
    if topic not in topics:
        have = ", ".join(f"{t} ({ty})" for t, ty in topics.items()) or "none"
        raise BagTopicError(f"{bag}: no topic {topic}; the bag has: {have}", str(bag), topic, topics)
    return topics[topic]


def is_geodetic(bag: Path, topic: str) -> bool:
    """Whether ``topic`` holds GNSS fixes (NavSatFix) rather than poses or positions."""
    return topic_type(bag, topic) == NAVSAT


def read_trajectory(bag: Path, topic: str, need_orientation: bool = True) -> Trajectory:
    """A pose topic as a :class:`Trajectory` (quaternions x, y, z, w), or with ``need_orientation``
    False also a PointStamped topic (positions only). ``lines`` are the messages' 1-based indices."""
    kind = topic_type(bag, topic)
    if kind in POSE_TYPES:
        gt = read_groundtruth_topic(bag, topic)
        q = np.ascontiguousarray(gt.q_wxyz[:, [1, 2, 3, 0]])
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        t_ns, p = gt.t_ns, gt.p
    elif not need_orientation:
        t_ns, p = read_positions(bag, topic)
        q = None
    else:
        raise InvalidInputError(f"{bag} topic {topic}: {kind} holds no orientation; pose aiding needs "
                                f"{' or '.join(POSE_TYPES)} (or use --aiding-kind position)")
    return Trajectory(np.asarray(t_ns, dtype=np.int64), np.asarray(p, dtype=np.float64), q, f"{bag} topic {topic}",
                      np.arange(1, len(t_ns) + 1, dtype=np.int64))


def read_navsat(bag: Path, topic: str, sigma_m: float) -> RtkSolution:
    """A NavSatFix topic as a solution in local ENU at its first fix (module docstring)."""
    t_ns, llh, cov, cov_type, status = rosbag.read_navsat(bag, topic)
    where = f"{bag} topic {topic}"
    fix = status > NO_FIX
    if not fix.any():
        raise InvalidInputError(f"{where}: no message with a fix (every status.status is -1)")
    bad = np.flatnonzero(fix & ~np.isfinite(llh).all(axis=1))
    if bad.size:
        raise InvalidInputError(f"{where}: message {int(bad[0]) + 1} has a non-finite latitude, longitude or altitude")
    first = int(np.flatnonzero(fix)[0])
    origin = (float(llh[first, 0]), float(llh[first, 1]), float(llh[first, 2]))
    ecef = llh_to_ecef(llh[:, 0], llh[:, 1], np.where(np.isfinite(llh[:, 2]), llh[:, 2], 0.0))
    enu = (np.nan_to_num(ecef) - ecef[first]) @ ecef_to_enu_rotation(origin[0], origin[1]).T
    diag = np.sqrt(np.clip(np.einsum("kii->ki", cov), 0.0, None))
    known = (cov_type > 0)[:, None] & (diag > 0)
    sigma = np.where(known, diag, float(sigma_m))
    q = np.where(fix, Q_FIX, Q_NONE).astype(np.int8)
    return RtkSolution(where, t_ns, enu, sigma, None, q, np.arange(1, len(t_ns) + 1, dtype=np.int64), origin, "llh")
