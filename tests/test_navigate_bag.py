"""``imu-learn navigate`` with aiding from ROS bag topics (``--aiding BAG --aiding-topic TOPIC``):
PoseStamped and Odometry poses, NavSatFix GNSS fixes with their covariance, and the fused
trajectories written back as nav_msgs/Odometry bags of the input's kind. Small bags written by the
tests (from the MH_04 crop, and from the synthetic car of tests/test_navigate_gnss.py)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from rosbag_fixtures import write_fixture_bag
from test_navigate_gnss import DELAY_S, LEVER, RPY, run, synthetic_car

pytest.importorskip("rosbags")

from imu_learn.data import formats  # noqa: E402
from imu_learn.data.formats.rosbag import list_topics, read_groundtruth_topic  # noqa: E402
from imu_learn.data.sample_bags import write_sample_bag  # noqa: E402
from imu_learn.fuse.aiding import rtklib  # noqa: E402
from imu_learn.fuse.aiding.detect import detect  # noqa: E402

NOISE = ["--imu-noise", "1.7e-4,2e-3,1.9e-5,3e-3"]


@pytest.mark.parametrize("kind,topic", [("ros1", "/groundtruth/pose"), ("sqlite3", "/groundtruth/odom")])
def test_pose_topics_as_aiding_and_odometry_bags_out(tmp_path, capsys, kind, topic):
    bag = write_fixture_bag(tmp_path, kind, seconds=8.0)
    assert detect(bag) == "bag"
    out = tmp_path / "nav"
    rc, stdout, err = run(["--input", bag, "--aiding", bag, "--aiding-topic", topic, "--aiding-kind", "pose",
                           "--quiet", "--out", out] + NOISE, capsys)
    assert rc == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["aiding_format"] == "bag" and s["aiding_topic"] == topic and s["aiding_rows_used"] > 100
    assert s["aiding_label"].startswith(bag.name)
    tum = np.loadtxt(out / "smoothed.tum", ndmin=2)
    written = out / ("smoothed.bag" if kind == "ros1" else "smoothed_bag")
    assert s["outputs"]["smoothed_bag"] == str(written) and (out / ("causal.bag" if kind == "ros1" else "causal_bag")).exists()
    assert list_topics(written) == {"/imu_learn/odometry": "nav_msgs/msg/Odometry"}
    back = read_groundtruth_topic(written, "/imu_learn/odometry")
    np.testing.assert_array_equal(back.t_ns, np.round(tum[:, 0] * 1e9).astype(np.int64))
    np.testing.assert_allclose(back.p, tum[:, 1:4], atol=1e-6)
    # the fused poses follow the aided ones (ground truth here; the navigation frame is their world
    # levelled by the start's tilt, a few centimetres over a few metres)
    gt = read_groundtruth_topic(bag, topic)
    i = np.searchsorted(gt.t_ns, back.t_ns)
    assert np.sqrt(np.mean(np.sum((gt.p[i] - back.p) ** 2, axis=1))) < 0.15


def test_bag_aiding_needs_its_topic_and_the_right_type(tmp_path, capsys):
    bag = write_fixture_bag(tmp_path, "ros1", seconds=4.0)
    rc, _out, err = run(["--input", bag, "--aiding", bag, "--aiding-kind", "pose", "--quiet"], capsys)
    assert rc == 2 and "is a ROS bag: name its topic with --aiding-topic" in err
    rc, _out, err = run(["--input", bag, "--aiding", bag, "--aiding-topic", "/nope", "--aiding-kind", "pose"], capsys)
    assert rc == 2 and "no topic /nope; the bag has:" in err and "/groundtruth/pose" in err
    rc, _out, err = run(["--input", bag, "--aiding", bag, "--aiding-topic", "/leica/position", "--aiding-kind",
                         "pose"], capsys)
    assert rc == 2 and "holds no orientation" in err
    rc, _out, err = run(["--input", bag, "--aiding", bag, "--aiding-topic", "/groundtruth/pose"], capsys)
    assert rc == 2 and "--aiding-kind" in err  # poses: the kind is the user's to say


def car_bag(folder, imu, pos):
    """The synthetic car as a ROS 1 bag: /imu (sensor_msgs/Imu, SI, IMU frame) and /fix (NavSatFix
    from the .pos file's fixes, their covariance in ENU; the float stretch reported as status 0 with
    its larger covariance, and one no-fix message)."""
    src = formats.read_imu_source(imu, "gnss-imu")
    sol = rtklib.read_pos(pos)
    lines = [ln.split() for ln in pos.read_text().splitlines() if not ln.startswith("%")]

    def messages(m):
        items = [(int(t), "/imu", m.imu(int(t), g, a, i)) for i, (t, g, a) in enumerate(zip(src.t_ns, src.gyro,
                                                                                               src.acc))]
        T = m.T
        for k, (t, row) in enumerate(zip(sol.t_ns.tolist(), lines)):
            sd = float(row[7])
            cov = np.diag([sd ** 2, sd ** 2, float(row[9]) ** 2]).ravel()
            status = -1 if k == 5 else 0
            fix = T["sensor_msgs/msg/NavSatFix"](
                header=m.header(t, "gps"), status=T["sensor_msgs/msg/NavSatStatus"](status=status, service=1),
                latitude=float(row[2]), longitude=float(row[3]), altitude=float(row[4]) + (50.0 if k == 5 else 0.0),
                position_covariance=cov, position_covariance_type=3)
            items.append((t, "/fix", fix))
        return sorted(items, key=lambda x: x[0])

    return write_sample_bag(folder, "ros1", None, messages=messages, name="car.bag")


def test_navsatfix_topic_is_gnss_aiding_like_the_pos_file(tmp_path, capsys):
    imu, pos, _ = synthetic_car(tmp_path, seconds=16.0)
    bag = car_bag(tmp_path, imu, pos)
    common = ["--imu-rotation-rpy-deg", ",".join(map(str, RPY)), "--lever-arm", ",".join(map(str, LEVER)),
              "--keyframe-hz", 4, "--quiet"] + NOISE
    rc, _out, err = run(["--input", imu, "--format", "gnss-imu", "--imu-delay-s", -DELAY_S, "--aiding", pos,
                         "--out", tmp_path / "pos"] + common, capsys)
    assert rc == 0, err
    # the bag's IMU stamps are the log's (DELAY_S late, as the .pos run reads them): the same delay removed
    rc, _out, err = run(["--input", bag, "--aiding", bag, "--aiding-topic", "/fix", "--imu-delay-s", -DELAY_S,
                         "--out", tmp_path / "bag"] + common, capsys)
    assert rc == 0, err
    s = json.loads((tmp_path / "bag" / "summary.json").read_text())
    assert s["aiding_kind"] == "position" and s["aiding_dropped"]["quality_not_used"] == 1  # the no-fix message
    assert s["time_system"].startswith("the header stamps of /fix")
    ref = json.loads((tmp_path / "pos" / "summary.json").read_text())
    assert s["enu_origin"]["latitude_deg"] == pytest.approx(ref["enu_origin"]["latitude_deg"], abs=1e-9)
    for f in ("track.kml", "track.geojson", "smoothed_llh.csv", "smoothed.bag"):
        assert (tmp_path / "bag" / f).exists(), f
    a = np.loadtxt(tmp_path / "bag" / "smoothed.tum", ndmin=2)
    b = np.loadtxt(tmp_path / "pos" / "smoothed.tum", ndmin=2)
    _, ia, ib = np.intersect1d(np.round(a[:, 0] * 1e3), np.round(b[:, 0] * 1e3), return_indices=True)
    assert len(ia) > 0.9 * min(len(a), len(b))  # the same keyframes (a start a fix apart at most)
    assert np.sqrt(np.mean(np.sum((a[ia, 1:4] - b[ib, 1:4]) ** 2, axis=1))) < 0.05
