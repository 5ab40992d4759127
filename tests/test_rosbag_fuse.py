"""imu_learn.fuse on a ROS bag: real position fixes from a bag topic, and the fused trajectory
written as a nav_msgs/msg/Odometry bag topic beside the TUM file."""
import numpy as np
import pytest

from imu_learn import _imu_core as core
from imu_learn.errors import BagTopicError
from imu_learn.formats import rosbag
from imu_learn.fuse.aiding import bag_position_source, leica_fixes
from imu_learn.fuse.config import FuseConfig, RecordingSpec, ScenarioSpec, validate
from imu_learn.fuse.run import run_experiment
from rosbag_fixtures import GT_CSV, write_fixture_bag


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


def test_fuse_a_bag_with_its_position_topic_writes_odometry(bag, tmp_path):
    spec = RecordingSpec(str(bag), "rosbag", str(GT_CSV), imu_topic="/imu0", aiding_topic="/leica/position")
    cfg = validate(FuseConfig(name="t", data_root=str(tmp_path), inputs=["raw"], recordings=[spec],
                              scenarios=[ScenarioSpec("leica", "leica", 1.0, 0.05)]))
    res = run_experiment(cfg, tmp_path / "out", lambda m: None)
    assert set(res) == {"run_mcap|leica|raw"}
    (r,) = res.values()
    assert r["aiding_count"] > 0 and r["smoothed"]["pos_rmse_m"] < 0.5
    for kind in ("causal", "smoothed"):
        tum = tmp_path / "out" / "trajectories" / f"run_mcap_leica_raw_{kind}.tum"
        odom = tum.with_suffix(".bag")
        d = core.read_tum(str(tum))
        t, p = rosbag.read_positions(odom, "/imu_learn/odometry")
        assert np.array_equal(t, d["t_ns"]) and np.allclose(p, d["p"], atol=1e-6, rtol=0)
        assert rosbag.list_topics(odom) == {"/imu_learn/odometry": "nav_msgs/msg/Odometry"}
