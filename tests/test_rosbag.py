"""imu_learn.data.formats.rosbag: ROS 1 and ROS 2 (sqlite3, mcap) bags in and out, on fixture bags
written from the shipped EuRoC crop (tests/rosbag_fixtures.py)."""
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from imu_learn import _imu_core as core
from imu_learn.cli.refine import main as refine_main
from imu_learn.data.formats import detect_format, read_imu_source, rosbag, write_imu
from imu_learn.data.formats.groundtruth import read_groundtruth
from imu_learn.data.loading import AlignOptions, align, load_sequence
from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import (
    BagError,
    BagStampError,
    BagTopicError,
    BagTypeError,
    ImuError,
    NotABagError,
    TruncatedBagError,
)
from imu_learn.infer.refiner import refine_recording, refine_with_variance
from imu_learn.nn.model import ImuRefiner, ModelConfig
from rosbag_fixtures import GT_CSV, IMU_CSV, KINDS, POSE_TOPICS, TOPICS, bag_name, write_fixture_bag

torch.set_num_threads(1)
CROP = IMU_CSV.parents[2]
COV_CHECKPOINT = Path(__file__).resolve().parent.parent / "models" / "euroc_adis16448_cov.pt"
SEQ_FIELDS = ("t_ns", "gyro", "acc", "p", "v", "q_wxyz")


@pytest.fixture(scope="session")
def bags(tmp_path_factory):
    """One fixture bag per container, written once per session."""
    folder = tmp_path_factory.mktemp("bags")
    return {kind: write_fixture_bag(folder, kind) for kind in KINDS}


def assert_same_sequences(a, b):
    assert len(a) == len(b) > 0
    for x, y in zip(a, b):
        for f in SEQ_FIELDS:
            u, w = getattr(x, f), getattr(y, f)
            assert u.dtype == w.dtype and u.shape == w.shape, f
            assert np.array_equal(u, w), f  # bit for bit: the same floats, not close ones


def random_model(seed=0):
    """Random weights with a non-zero head, so refinement changes every sample."""
    torch.manual_seed(seed)
    _t, g, a = core.read_asl_imu(str(IMU_CSV))
    raw = np.c_[g, a]
    m = ImuRefiner(ModelConfig(), mean=torch.tensor(raw.mean(0)), std=torch.tensor(raw.std(0)))
    with torch.no_grad():
        torch.nn.init.normal_(m.head.weight, std=0.5)
        torch.nn.init.normal_(m.head.bias, std=0.1)
    return m.eval()


def messages_by_topic(bag):
    """{topic: [(bag stamp, raw bytes), ...]} and the connections of a bag, read back with rosbags."""
    with rosbag.open_bag(bag) as reader:
        out = {}
        for conn, stamp, raw in reader.messages():
            out.setdefault(conn.topic, []).append((stamp, bytes(raw)))
        conns = [(c.topic, c.msgtype, c.msgdef.data, c.digest, c.ext) for c in reader.connections]
    return out, conns


def decoded(bag, topic):
    with rosbag.open_bag(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [reader.deserialize(raw, c.msgtype) for c, _t, raw in reader.messages(connections=conns)]


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", KINDS)
def test_detects_and_lists_topics(bags, kind):
    assert detect_format(bags[kind]) == "rosbag"
    assert rosbag.list_topics(bags[kind]) == dict(sorted(TOPICS.items()))
    if kind != "ros1":  # the storage file inside a ROS 2 bag folder is the bag too
        storage = next(p for p in bags[kind].iterdir() if p.suffix in (".db3", ".mcap"))
        assert detect_format(storage) == "rosbag" and rosbag.bag_path(storage) == bags[kind]


@pytest.mark.parametrize("kind", KINDS)
def test_load_equals_asl_folder_bit_for_bit(bags, kind, caplog):
    """The bag's IMU with EuRoC's ground-truth file beside it loads exactly as the ASL folder."""
    caplog.set_level("INFO", logger="imu_learn")
    from_asl = load_sequence(CROP, "euroc")
    from_bag = load_sequence(bags[kind], "rosbag", groundtruth=GT_CSV)
    assert_same_sequences(from_bag, from_asl)
    assert "using IMU topic /imu0" in caplog.text  # the bag's only IMU topic, said so (logged)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("topic", POSE_TOPICS)
def test_pose_topic_loads_as_the_same_poses_from_the_asl_folder(bags, kind, topic):
    """Each pose type gives the ASL ground truth's poses (no velocity: it is fitted from poses)."""
    t, g, a = core.read_asl_imu(str(IMU_CSV))
    gt = read_groundtruth(GT_CSV)
    expected = align(ImuData(t, g, a), GroundTruth(gt.t_ns, gt.p, gt.q_wxyz, None)).segments
    got = load_sequence(bags[kind], format="rosbag", imu_topic="/imu0", groundtruth_topic=topic)
    assert_same_sequences(got, expected)


def test_several_pose_topics_need_one_named(bags):
    with pytest.raises(BagTopicError, match="3 ground-truth topics.*groundtruth_topic"):
        load_sequence(bags["mcap"], "rosbag")


def test_topics_are_for_bags_only():
    with pytest.raises(ImuError, match="imu_topic only apply to ROS bags"):
        load_sequence(CROP, "euroc", imu_topic="/imu0")


@pytest.mark.parametrize("kind", KINDS)
def test_positions_topic(bags, kind):
    gt = read_groundtruth(GT_CSV)
    t, p = rosbag.read_positions(bags[kind], "/leica/position")
    assert np.array_equal(t, gt.t_ns[::10]) and np.array_equal(p, gt.p[::10])


# --------------------------------------------------------------------------------------------
# Writing: refine, byte-identical copies, round trips
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def refined(bags, tmp_path_factory):
    """Each bag and the ASL folder refined by the same random model."""
    out = tmp_path_factory.mktemp("refined")
    model = random_model()
    asl = refine_recording(model, CROP, out / "asl.csv")
    return {"asl": asl, **{k: refine_recording(model, bags[k], out / bag_name(k)) for k in KINDS}}


@pytest.mark.parametrize("kind", KINDS)
def test_refine_on_a_bag_equals_refine_on_the_asl_folder(bags, refined, kind):
    _t, g_asl, a_asl = core.read_asl_imu(str(refined["asl"]))
    src = read_imu_source(refined[kind], imu_topic="/imu0")
    assert np.array_equal(src.gyro, g_asl) and np.array_equal(src.acc, a_asl)
    raw = read_imu_source(bags[kind], imu_topic="/imu0")
    assert not np.array_equal(src.gyro, raw.gyro)  # the model did change the IMU
    assert np.array_equal(src.t_ns, raw.t_ns)


@pytest.mark.parametrize("kind", KINDS)
def test_output_is_the_same_kind_of_bag(bags, refined, kind):
    out = refined[kind]
    if kind == "ros1":
        assert out.is_file() and out.read_bytes().startswith(b"#ROSBAG V2.0")
    else:
        meta_in, meta_out = rosbag._ros2_metadata(bags[kind]), rosbag._ros2_metadata(out)
        assert meta_out["storage_identifier"] == meta_in["storage_identifier"] == kind
        assert meta_out["message_count"] == meta_in["message_count"]
        assert [p.name for p in out.iterdir()] and all(p.stem == out.name for p in out.iterdir()
                                                       if p.name != "metadata.yaml")


@pytest.mark.parametrize("kind", KINDS)
def test_every_other_message_is_byte_identical(bags, refined, kind):
    before, conns_before = messages_by_topic(bags[kind])
    after, conns_after = messages_by_topic(refined[kind])
    assert conns_after == conns_before  # topic, type, definition, hash, QoS / callerid
    assert sorted(after) == sorted(before)
    for topic in before:
        if topic != "/imu0":
            assert after[topic] == before[topic], topic  # stamps and bytes
    assert [s for s, _ in after["/imu0"]] == [s for s, _ in before["/imu0"]]
    # An Imu message ends in fixed-size doubles in both encodings: angular_velocity is bytes
    # [-192, -168) from the end, linear_acceleration [-96, -72); nothing else may differ.
    vectors = set(range(169, 193)) | set(range(73, 97))  # distances from the end, len - index
    for (_, b0), (_, b1) in zip(before["/imu0"], after["/imu0"]):
        assert len(b0) == len(b1)
        diff = np.flatnonzero(np.frombuffer(b0, np.uint8) != np.frombuffer(b1, np.uint8))
        assert set((len(b0) - diff).tolist()) <= vectors


@pytest.mark.parametrize("kind", KINDS)
def test_imu_headers_and_covariances_are_kept(bags, refined, kind):
    old, new = decoded(bags[kind], "/imu0"), decoded(refined[kind], "/imu0")
    assert len(old) == len(new)
    for m0, m1 in zip(old, new):
        # each reader builds its own message classes, so compare their text, not the objects
        assert repr(m1.header) == repr(m0.header) and repr(m1.orientation) == repr(m0.orientation)
        for f in ("orientation_covariance", "angular_velocity_covariance", "linear_acceleration_covariance"):
            assert np.array_equal(getattr(m1, f), getattr(m0, f)), f
    assert any(m1.angular_velocity != m0.angular_velocity for m0, m1 in zip(old, new))


@pytest.mark.parametrize("kind", KINDS)
def test_round_trip_unchanged_imu_gives_the_same_messages(bags, tmp_path, kind):
    """Writing the IMU back as read re-serializes every IMU message to its original bytes."""
    src = read_imu_source(bags[kind])
    out = tmp_path / bag_name(kind)
    write_imu(src, out, src.gyro, src.acc)
    assert messages_by_topic(out) == messages_by_topic(bags[kind])


@pytest.mark.parametrize("kind", KINDS)
def test_round_trip_written_values_read_back_exactly(bags, tmp_path, kind):
    src = read_imu_source(bags[kind])
    rng = np.random.default_rng(1)
    g, a = rng.normal(size=src.gyro.shape), rng.normal(size=src.acc.shape) * 9.81
    out = tmp_path / bag_name(kind)
    write_imu(src, out, g, a)
    back = read_imu_source(out)
    assert np.array_equal(back.gyro, g) and np.array_equal(back.acc, a) and np.array_equal(back.t_ns, src.t_ns)
    # and the refined bag is itself a bag the loader takes
    assert len(load_sequence(out, "rosbag", groundtruth=GT_CSV)[0]) > 0


def test_refine_never_overwrites_the_input(bags, tmp_path):
    bag = shutil.copy(bags["ros1"], tmp_path / "in.bag")
    before = Path(bag).read_bytes()
    with pytest.raises(ImuError, match="refusing to overwrite the input"):
        refine_recording(random_model(), Path(bag), Path(bag))
    assert Path(bag).read_bytes() == before


def test_existing_ros2_output_folder_is_refused(bags, tmp_path):
    out = tmp_path / "exists"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    src = read_imu_source(bags["sqlite3"])
    with pytest.raises(FileExistsError):
        write_imu(src, out, src.gyro, src.acc)
    assert [p.name for p in out.iterdir()] == ["keep.txt"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary folder left



def test_refining_into_a_previous_ros2_output_bag_is_refused_not_nested(bags, tmp_path):
    """A second refine into the same OUT: the first run's bag folder is refused, no bag written into it."""
    out = tmp_path / "refined"
    refine_recording(random_model(), bags["sqlite3"], out)
    before = sorted(p.name for p in out.iterdir())
    with pytest.raises(ImuError, match="exists already and is a ROS 2 bag"):
        refine_recording(random_model(), bags["sqlite3"], out)
    assert sorted(p.name for p in out.iterdir()) == before

# --------------------------------------------------------------------------------------------
# --fill-covariance: the learned per-sample variances in the IMU covariance fields
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cov_refined(bags, tmp_path_factory):
    """Each bag refined by the shipped covariance model with --fill-covariance, and what
    refine_with_variance gives for the recording (gyro, acc, variances)."""
    from imu_learn.infer.checkpoint import load_model

    out = tmp_path_factory.mktemp("cov_refined")
    for kind in KINDS:
        rc = refine_main(["--checkpoint", str(COV_CHECKPOINT), "--input", str(bags[kind]),
                          "--out", str(out / bag_name(kind)), "--fill-covariance", "--device", "cpu", "--quiet"])
        assert rc == 0
    raw = read_imu_source(bags["ros1"])
    expected = refine_with_variance(load_model(COV_CHECKPOINT), raw.gyro, raw.acc)
    return {kind: out / bag_name(kind) for kind in KINDS}, expected


@pytest.mark.parametrize("kind", KINDS)
def test_fill_covariance_writes_the_predicted_variances(bags, cov_refined, kind):
    outs, (gyro, acc, var) = cov_refined
    old, new = decoded(bags[kind], "/imu0"), decoded(outs[kind], "/imu0")
    assert len(old) == len(new) == len(var)
    gyro_cov = np.array([m.angular_velocity_covariance for m in new])
    acc_cov = np.array([m.linear_acceleration_covariance for m in new])
    assert gyro_cov.dtype == acc_cov.dtype == np.float64
    # row-major 3x3 diagonals of the variances, float64 exact; off-diagonals exactly 0
    assert np.array_equal(gyro_cov.reshape(-1, 3, 3), np.stack([np.diag(v) for v in var[:, :3]]))
    assert np.array_equal(acc_cov.reshape(-1, 3, 3), np.stack([np.diag(v) for v in var[:, 3:]]))
    assert np.unique(var[:, 0]).size > 1  # per-sample values, not one level
    got = read_imu_source(outs[kind])
    assert np.array_equal(got.gyro, gyro) and np.array_equal(got.acc, acc)
    for m0, m1 in zip(old, new):
        assert repr(m1.header) == repr(m0.header) and repr(m1.orientation) == repr(m0.orientation)
        assert np.array_equal(m1.orientation_covariance, m0.orientation_covariance)


@pytest.mark.parametrize("kind", KINDS)
def test_fill_covariance_changes_nothing_else(bags, cov_refined, kind):
    outs, _ = cov_refined
    before, conns_before = messages_by_topic(bags[kind])
    after, conns_after = messages_by_topic(outs[kind])
    assert conns_after == conns_before and sorted(after) == sorted(before)
    for topic in before:
        if topic != "/imu0":
            assert after[topic] == before[topic], topic
    assert [s for s, _ in after["/imu0"]] == [s for s, _ in before["/imu0"]]
    # From the end of an Imu message: linear_acceleration_covariance [-72, 0), linear_acceleration
    # [-96, -72), angular_velocity_covariance [-168, -96), angular_velocity [-192, -168); the header,
    # orientation and orientation_covariance before them may not change.
    may_change = set(range(1, 193))
    for (_, b0), (_, b1) in zip(before["/imu0"], after["/imu0"]):
        assert len(b0) == len(b1)
        diff = np.flatnonzero(np.frombuffer(b0, np.uint8) != np.frombuffer(b1, np.uint8))
        assert set((len(b0) - diff).tolist()) <= may_change


def test_fill_covariance_needs_a_covariance_head(bags, tmp_path, capsys):
    from imu_learn.infer.checkpoint import save_checkpoint

    ckpt = tmp_path / "no_head.pt"
    save_checkpoint(ckpt, random_model(), {"test": True}, epoch=1, step=1, best_metric=None)
    rc = refine_main(["--checkpoint", str(ckpt), "--input", str(bags["ros1"]), "--out", str(tmp_path / "o.bag"),
                      "--fill-covariance", "--device", "cpu", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert str(ckpt) in err[0] and "no covariance head" in err[0] and "--fill-covariance" in err[0]
    assert not (tmp_path / "o.bag").exists()


def test_fill_covariance_needs_a_bag(tmp_path, capsys):
    rc = refine_main(["--checkpoint", str(COV_CHECKPOINT), "--input", str(CROP), "--out", str(tmp_path / "o"),
                      "--fill-covariance", "--device", "cpu", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert str(CROP) in err[0] and "not a bag" in err[0] and "--fill-covariance" in err[0]
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------------------------
# Errors: typed, naming bag and topic; one line from the CLI
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", KINDS)
def test_missing_topic_lists_the_bags_topics(bags, kind):
    with pytest.raises(BagTopicError) as e:
        rosbag.read_imu(bags[kind], "/imu1")
    msg = str(e.value)
    assert str(bags[kind]) in msg and "/imu1" in msg and e.value.topic == "/imu1"
    assert all(t in msg for t in TOPICS) and "/imu0 (sensor_msgs/msg/Imu)" in msg
    assert e.value.topics == dict(sorted(TOPICS.items()))


@pytest.mark.parametrize("kind", KINDS)
def test_topic_of_the_wrong_type(bags, kind):
    with pytest.raises(BagTypeError, match="/groundtruth/pose: type geometry_msgs/msg/PoseStamped, expected sensor"):
        rosbag.read_imu(bags[kind], "/groundtruth/pose")
    with pytest.raises(BagTypeError, match="positions only"):
        load_sequence(bags[kind], "rosbag", groundtruth_topic="/leica/position")
    with pytest.raises(BagTypeError, match="/cam0/image_raw"):
        load_sequence(bags[kind], "rosbag", groundtruth_topic="/cam0/image_raw")


def _stamps_going_back(msgs):
    """Ten IMU messages whose 6th header stamp is before the 5th's (bag stamps still in order)."""
    t = [1_000_000_000 + 5_000_000 * i for i in range(10)]
    t[5], t[4] = t[4], t[5]
    return [(1_000_000_000 + 5_000_000 * i, "/imu0", msgs.imu(s, (0, 0, 0), (0, 0, 9.81), i))
            for i, s in enumerate(t)]


@pytest.mark.parametrize("kind", KINDS)
def test_stamps_going_back(tmp_path, kind):
    bag = write_fixture_bag(tmp_path, kind, messages=_stamps_going_back)
    with pytest.raises(BagStampError, match="topic /imu0: header stamp of message 5") as e:
        rosbag.read_imu(bag, "/imu0")
    assert e.value.path == str(bag) and e.value.topic == "/imu0" and e.value.index == 5


def test_not_a_bag(tmp_path):
    text = tmp_path / "notes.bag"
    text.write_text("not a bag\n" * 100)
    folder = tmp_path / "folder"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("just: text\n")
    for path in (text, folder):
        with pytest.raises(NotABagError, match=str(path)):
            rosbag.read_imu(path, "/imu0")
    with pytest.raises(NotABagError, match="without metadata.yaml"):
        rosbag.read_imu(tmp_path, "/imu0")


def _truncate(bag: Path) -> Path:
    f = bag if bag.is_file() else next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))
    data = f.read_bytes()
    f.write_bytes(data[: len(data) // 2])
    return f


@pytest.mark.parametrize("kind", KINDS)
def test_truncated_bag(bags, tmp_path, kind):
    bag = tmp_path / bag_name(kind)
    (shutil.copytree if bags[kind].is_dir() else shutil.copy)(bags[kind], bag)
    _truncate(bag)
    with pytest.raises(TruncatedBagError) as e:
        rosbag.read_imu(bag, "/imu0")
    assert str(bag) in str(e.value) and "truncated or damaged" in str(e.value)


def test_cli_prints_one_line_naming_bag_and_topic(bags, tmp_path, capsys):
    from imu_learn.infer.checkpoint import save_checkpoint

    ckpt = tmp_path / "m.pt"
    save_checkpoint(ckpt, random_model(), {"test": True}, epoch=1, step=1, best_metric=None)
    rc = refine_main(["--checkpoint", str(ckpt), "--input", str(bags["mcap"]), "--out", str(tmp_path / "o"),
                      "--imu-topic", "/imu1", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert "BagTopicError" in err[0] and str(bags["mcap"]) in err[0] and "/imu1" in err[0] and "/imu0" in err[0]
    assert not (tmp_path / "o").exists()


def test_every_bag_error_is_an_imu_error():
    for cls in (NotABagError, TruncatedBagError, BagTopicError, BagTypeError, BagStampError):
        assert issubclass(cls, BagError) and issubclass(cls, ImuError)


# --------------------------------------------------------------------------------------------
# Labels and fit configs take bags
# --------------------------------------------------------------------------------------------


def test_labels_cli_on_a_folder_of_bags(bags, tmp_path, capsys):
    from imu_learn.cli.labels import main as labels_main

    root = bags["ros1"].parent
    rc = labels_main(["rosbag", "--dataset-dir", str(root), "--out", str(tmp_path / "cache"), "--quiet",
                      "--imu-topic", "/imu0", "--groundtruth-topic", "/groundtruth/pose"])
    out = capsys.readouterr().out
    assert rc == 0, out
    for name in ("run:", "run_sqlite3:", "run_mcap:"):  # a .bag's name drops the suffix
        assert name in out
    rc = labels_main(["rosbag", "--dataset-dir", str(root), "--out", str(tmp_path / "cache2"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and "3 ground-truth topics" in err[-1] and len(err[-1].splitlines()) == 1


def test_fit_config_root_can_be_a_bag(bags):
    from imu_learn.data.config import DataConfig, RootConfig, SplitConfig
    from imu_learn.data.splits import make_split

    root = RootConfig(str(bags["mcap"]), "rosbag", str(GT_CSV), max_gap_s=0.06, imu_topic="/imu0")
    data = DataConfig(roots=[root], split=SplitConfig(train=["run_mcap[0:0.8]"], val=["run_mcap[0.8:1]"], test=[]))
    split = make_split(data)
    whole = load_sequence(CROP, "euroc", options=AlignOptions(max_gap_s=0.06))
    n = sum(len(s) for s in split.train) + sum(len(s) for s in split.val)
    assert n == sum(len(s) for s in whole)
    assert np.array_equal(split.train[0].gyro, whole[0].gyro[: len(split.train[0])])


def test_a_bag_without_the_bags_extra_is_one_line_naming_the_extra(bags):
    """With rosbags absent (blocked in a child process), reading a bag is a MissingExtraError and
    the CLI prints one line naming the extra, not a ModuleNotFoundError traceback."""
    import subprocess
    import sys

    block = ("import importlib.abc, sys\n"
             "class NoBags(importlib.abc.MetaPathFinder):\n"
             "    def find_spec(self, name, path=None, target=None):\n"
             "        if name == 'rosbags' or name.startswith('rosbags.'):\n"
             "            raise ImportError('rosbags is blocked in this test')\n"
             "sys.meta_path.insert(0, NoBags())\n")
    bag = bags["ros1"]
    api = block + ("from imu_learn.data.formats.rosbag import open_bag\n"
                   "from imu_learn.errors import MissingExtraError\n"
                   f"try:\n    open_bag({str(bag)!r}).__enter__()\nexcept MissingExtraError as e:\n    print('OK', e)\n")
    r = subprocess.run([sys.executable, "-c", api], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.startswith("OK ") and "bags extra" in r.stdout, r.stderr[-2000:]
    cli = block + ("from imu_learn.cli import main\n"
                   f"sys.exit(main(['refine', '--checkpoint', 'models/euroc_adis16448.pt', '--input', {str(bag)!r}, "
                   "'--out', 'never_written.bag']))\n")
    r = subprocess.run([sys.executable, "-c", cli], capture_output=True, text=True, cwd=Path(__file__).resolve().parents[1])
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr[-2000:]
    assert lines[0].startswith("imu-learn refine: error: MissingExtraError: ") and "imu-learn[bags]" in lines[0]


def test_a_linked_bag_folder_is_found_and_a_link_loop_ends(bags, tmp_path):
    """labels rosbag's search: a ROS 2 bag folder linked into the dataset folder is a recording (it was
    skipped), a ROS 1 bag linked in too; a link back up the tree is walked once."""
    from imu_learn.data.formats.rosbag import find_recordings

    d = tmp_path / "bags"
    d.mkdir()
    (d / "one.bag").symlink_to(Path(bags["ros1"]).resolve())
    (d / "two").symlink_to(Path(bags["sqlite3"]).resolve(), target_is_directory=True)
    (d / "loop").symlink_to(d, target_is_directory=True)
    found = find_recordings(d)
    assert d / "one.bag" in found and d / "two" in found and len(found) == 2, found
