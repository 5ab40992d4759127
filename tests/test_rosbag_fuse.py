"""imu_learn.fuse on a ROS bag: real position fixes from a bag topic, and the fused trajectory
written as a nav_msgs/msg/Odometry topic, in a bag of the recording's own kind, beside the TUM file."""
import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from imu_learn import _imu_core as core
from imu_learn.data.formats import rosbag
from imu_learn.errors import BagTopicError
from imu_learn.fuse.aiding import bag_position_source, leica_fixes
from imu_learn.fuse.experiments.batch import run_experiment
from imu_learn.fuse.experiments.config import FuseConfig, RecordingSpec, ScenarioSpec, validate
from rosbag_fixtures import GT_CSV, KINDS, bag_name, write_fixture_bag


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    return write_fixture_bag(tmp_path_factory.mktemp("fusebag"), "mcap")


def test_bag_topic_gives_the_fixes_of_its_positions(bag):
    t, p, lever, source = bag_position_source(bag, "/leica/position", [0.1, 0.0, -0.02])
    imu_t = rosbag.read_imu(bag, "/imu0").t_ns
    fixes = leica_fixes(t, p, lever, imu_t, None, 0.01, source=source)
    assert len(fixes) == len(t) and np.array_equal(fixes.p, p) and np.array_equal(fixes.lever, [0.1, 0.0, -0.02])
    assert np.abs(imu_t[fixes.idx] - t).max() <= 2_500_000  # the nearest 200 Hz sample
    assert str(bag) in fixes.source and "/leica/position" in fixes.source
    _, p_pose, _, _ = bag_position_source(bag, "/groundtruth/pose")  # a pose topic's positions
    assert np.array_equal(p_pose[::10], p)
    with pytest.raises(BagTopicError, match="/leica/pos"):
        bag_position_source(bag, "/leica/pos")


def read_odometry(bag):
    """(kind, stamps, header stamps, positions, quaternions wxyz, topics) of an Odometry bag, read with
    rosbags itself (not through imu_learn's reader)."""
    with AnyReader([bag]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        t, th, p, q = [], [], [], []
        for conn, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            pose = msg.pose.pose
            t.append(stamp)
            th.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            p.append((pose.position.x, pose.position.y, pose.position.z))
            q.append((pose.orientation.w, pose.orientation.x, pose.orientation.y, pose.orientation.z))
    return rosbag.bag_kind(bag), np.array(t), np.array(th), np.array(p), np.array(q), topics


@pytest.mark.parametrize("kind", KINDS)
def test_fuse_a_bag_with_its_position_topic_writes_odometry_in_its_kind(tmp_path, kind):
    bag = write_fixture_bag(tmp_path, kind)
    spec = RecordingSpec(str(bag), "rosbag", str(GT_CSV), imu_topic="/imu0", aiding_topic="/leica/position")
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(tmp_path), inputs=["raw"], recordings=[spec],
                              scenarios=[ScenarioSpec("leica", "leica", 1.0, 0.05)]))
    res = run_experiment(cfg, tmp_path / "out", lambda m: None)
    stem = f"{bag_name(kind)}_leica_raw"
    assert set(res) == {f"{bag_name(kind)}|leica|raw"}
    (r,) = res.values()
    assert r["aiding_count"] > 0 and r["smoothed"]["pos_rmse_m"] < 0.5
    traj = tmp_path / "out" / "trajectories"
    for part in ("causal", "smoothed"):
        d = core.read_tum(str(traj / f"{stem}_{part}.tum"))
        odom = traj / (f"{stem}_{part}.bag" if kind == "ros1" else f"{stem}_{part}")
        got_kind, t, t_header, p, q, topics = read_odometry(odom)
        assert got_kind == kind and topics == {"/imu_learn/odometry": "nav_msgs/msg/Odometry"}
        assert np.array_equal(t, d["t_ns"]) and np.array_equal(t_header, d["t_ns"])
        assert np.array_equal(p, d["p"]) and np.array_equal(q, d["q_wxyz"])  # the same floats as the TUM file
    if kind != "ros1":
        assert rosbag._ros2_metadata(odom)["storage_identifier"] == kind
    assert not [f for f in traj.iterdir() if f.name.startswith(".")]  # no temporary left


@pytest.mark.parametrize("kind", KINDS)
def test_odometry_bag_is_replaced_on_a_rerun(tmp_path, kind):
    """A second write replaces the first (ROS 2: the folder is swapped, never merged); a write that
    fails leaves the previous bag as it was."""
    like = write_fixture_bag(tmp_path, kind, seconds=1.0)
    out = rosbag.output_bag_path(tmp_path / "traj", like)
    t = np.array([1, 2, 3]) * 1_000_000_000
    q = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    rosbag.write_odometry(out, "/odom", t, np.zeros((3, 3)), q, like=like)
    rosbag.write_odometry(out, "/odom", t[:2], np.ones((2, 3)), q[:2], like=like)
    _, _, _, p, _, _ = read_odometry(out)
    assert np.array_equal(p, np.ones((2, 3)))
    with pytest.raises(ZeroDivisionError):
        rosbag.write_odometry(out, "/odom", t, np.full((3, 3), 2.0), q, like=like, frame_id=_Explodes())
    _, _, _, p, _, _ = read_odometry(out)
    assert np.array_equal(p, np.ones((2, 3)))
    assert not [f for f in tmp_path.iterdir() if f.name.startswith(".")]  # nothing left aside


class _Explodes(str):
    """A frame id whose serialization fails part-way through writing the bag."""

    def encode(self, *args, **kwargs):
        raise ZeroDivisionError("injected")
