"""imu_learn.data.formats: one module per layout that detects, reads and writes it (refine and loading
both go through it)."""
import hashlib
from pathlib import Path

import numpy as np
import pytest

from imu_learn.data import formats
from imu_learn.data.datasets import DATASETS, find_recordings
from imu_learn.data.formats import DETECTION_ORDER, FORMATS, detect_format, read_imu_source, read_recording, write_imu
from imu_learn.errors import InvalidInputError

REPO = Path(__file__).resolve().parent.parent
SHIPPED_ASL = REPO / "datasets" / "euroc" / "V1_01_easy"
T0_NS = 1_544_590_798_711_913_000


def sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _raw(n: int, seed: int):
    rng = np.random.default_rng(seed)
    return rng.normal(0, 0.3, (n, 3)), rng.normal([0, 0, 9.81], 0.5, (n, 3))


# ---- one small recording per layout, in its documented form ------------------------------------


def make_asl(root: Path) -> Path:
    return SHIPPED_ASL  # read only: the shipped EuRoC crop


def make_kaist(root: Path, n: int = 120) -> Path:
    """xsens_imu.csv (17 columns) and global_pose.csv (t + 3x4 [R|t]), 100 Hz, at rest."""
    g, a = _raw(n, 1)
    (root / "sensor_data").mkdir(parents=True)
    t_ns = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    with open(root / "sensor_data" / "xsens_imu.csv", "w") as f:
        for i in range(n):
            row = [0, 0, 0, 1, 0, 0, 0, *g[i], *a[i], 0.1, 0.2, 0.3]
            f.write(f"{t_ns[i]}," + ",".join(f"{x:.9g}" for x in row) + "\n")
    with open(root / "global_pose.csv", "w") as f:
        for i in range(n):
            f.write(f"{t_ns[i]},1,0,0,{0.01 * i},0,1,0,0,0,0,1,0\n")
    return root


def make_blackbird(root: Path, n: int = 120) -> Path:
    h5py = pytest.importorskip("h5py")
    g, a = _raw(n, 2)
    root.mkdir(parents=True)
    with h5py.File(root / "data.hdf5", "w") as f:
        f["ts"] = 1.5e9 + np.arange(n) * 0.01
        f["gyro_raw"] = g
        f["accel_raw"] = a
        f["gt_p"] = np.ones((n, 3))
    return root


def make_broad(root: Path, n: int = 120) -> Path:
    scipy_io = pytest.importorskip("scipy.io")
    g, a = _raw(n, 3)
    root.mkdir(parents=True)
    path = root / "01_trial.mat"
    scipy_io.savemat(path, {"imu_gyr": g, "imu_acc": a, "opt_quat": np.tile([1.0, 0, 0, 0], (n, 1)),
                            "opt_pos": np.zeros((n, 3)), "sampling_rate": 100.0})
    return path


def make_rosbag(root: Path) -> Path:
    """A ROS 1 bag ``<root>.bag`` of 2 s of the EuRoC crop (tests/rosbag_fixtures.py)."""
    from rosbag_fixtures import write_fixture_bag

    root.parent.mkdir(parents=True, exist_ok=True)
    return write_fixture_bag(root.parent, "ros1", seconds=2.0, name=root.name + ".bag")


def make_fetch(root: Path) -> Path:
    """A Fetch (Debias_IMU) recording: float-notation stamps, IMU and mocap (imu_learn.data.synthetic)."""
    from imu_learn.data.synthetic import write_fetch_recording

    return write_fetch_recording(root, name="")


MAKERS = {"asl": make_asl, "kaist": make_kaist, "blackbird": make_blackbird, "broad": make_broad,
          "rosbag": make_rosbag, "fetch": make_fetch}


@pytest.mark.parametrize("name", sorted(MAKERS))
def test_each_layout_detects_reads_writes_and_reads_back(tmp_path, name):
    rec = MAKERS[name](tmp_path / "in")
    assert detect_format(rec) == name
    src = read_imu_source(rec)
    before = sha(src.imu_file)
    assert src.fmt == name and src.gyro.shape == src.acc.shape == (len(src.gyro), 3)
    # Values that need all 17 significant digits: the writer must keep float64 exactly.
    gyro, acc = src.gyro + 1e-3 / 3, src.acc - 1e-2 / 7
    out = tmp_path / "out" / src.rel
    write_imu(src, out, gyro, acc)
    assert sha(src.imu_file) == before  # the input is only a template
    assert [p.name for p in out.parent.iterdir()] == [out.name]  # no temporary file left beside it
    assert detect_format(out) == name
    back = read_imu_source(out)
    assert back.fmt == name
    np.testing.assert_array_equal(back.gyro, gyro)
    np.testing.assert_array_equal(back.acc, acc)
    if src.t_ns is None:
        assert back.t_ns is None
    else:
        np.testing.assert_array_equal(back.t_ns, src.t_ns)


def test_a_failed_write_leaves_the_old_output_and_no_temporary_file(tmp_path):
    src = read_imu_source(make_blackbird(tmp_path / "in"))
    out = tmp_path / "out" / "data.hdf5"
    write_imu(src, out, src.gyro + 1.0, src.acc)  # differs from the input it is copied from
    before = sha(out)
    with pytest.raises(ValueError):  # a (N-1, 3) gyro cannot fill the (N, 3) dataset
        write_imu(src, out, src.gyro[1:], src.acc)
    assert sha(out) == before
    assert [p.name for p in out.parent.iterdir()] == ["data.hdf5"]


def test_kaist_write_refuses_a_sample_count_that_does_not_match_its_rows(tmp_path):
    src = read_imu_source(make_kaist(tmp_path / "in"))
    out = tmp_path / "out" / "xsens_imu.csv"
    out.parent.mkdir()
    with pytest.raises(InvalidInputError, match="xsens_imu.csv: 120 non-empty rows but 119 samples"):
        write_imu(src, out, src.gyro[1:], src.acc[1:])
    assert not any(out.parent.iterdir())


# ---- detection: one set of rules, the same for loading and refine ------------------------------


def _forms(tmp_path: Path):
    """(path, layout) for every form of path a caller may pass."""
    kaist = make_kaist(tmp_path / "urban00")
    bb = make_blackbird(tmp_path / "bb")
    broad = make_broad(tmp_path / "broad")
    upper = broad.with_name("02_TRIAL.MAT")
    upper.write_bytes(broad.read_bytes())
    h5 = tmp_path / "other.h5"
    h5.write_bytes((bb / "data.hdf5").read_bytes())
    return [
        (SHIPPED_ASL, "asl"), (SHIPPED_ASL / "mav0", "asl"), (SHIPPED_ASL / "mav0" / "imu0" / "data.csv", "asl"),
        (kaist, "kaist"), (kaist / "sensor_data" / "xsens_imu.csv", "kaist"),
        (bb, "blackbird"), (bb / "data.hdf5", "blackbird"), (h5, "blackbird"),
        (broad, "broad"), (upper, "broad"),
    ]


def test_every_path_form_is_detected_as_its_layout_and_opened_by_it(tmp_path):
    for path, name in _forms(tmp_path):
        assert detect_format(path) == name, path
        claims = [m.NAME for m in DETECTION_ORDER if m.detect(path)]
        # Only KAIST's xsens_imu.csv is claimed twice (it is a .csv); KAIST is asked first.
        assert claims == (["kaist", "asl"] if path.name == "xsens_imu.csv" else [name]), path
        assert read_imu_source(path).fmt == name, path


def test_kaist_loads_from_its_imu_file_as_from_its_folder(tmp_path):
    root = make_kaist(tmp_path / "urban00")
    imu, gt = read_recording(root)
    imu2, gt2 = read_recording(root / "sensor_data" / "xsens_imu.csv")
    np.testing.assert_array_equal(imu2.gyro, imu.gyro)
    np.testing.assert_array_equal(gt2.p, gt.p)


def test_an_unknown_layout_or_format_is_an_invalid_input_error(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(InvalidInputError, match="cannot tell the dataset format"):
        read_imu_source(tmp_path / "empty")
    with pytest.raises(InvalidInputError, match="unknown format 'csv'"):
        read_recording(SHIPPED_ASL, format="csv")
    with pytest.raises(FileNotFoundError):
        read_imu_source(tmp_path / "missing")


def _dataset_roots(shared_root):
    roots = [(d, REPO / "datasets" / d) for d in ("euroc", "tum-vi")]
    if shared_root is not None:
        roots += [(d, shared_root / d) for d in ("euroc", "tum-vi", "blackbird", "broad")]
    return [(d, r) for d, r in roots if r.exists()]


def test_every_shipped_and_shared_recording_is_detected_as_its_dataset(request):
    shared_root = REPO.parent / "shared" / "data"
    checked = 0
    for dataset, root in _dataset_roots(shared_root if shared_root.exists() else None):
        for _name, path in find_recordings(dataset, root):
            assert formats.layout(path) is FORMATS[dataset], path
            checked += 1
    assert checked >= 4  # the shipped crops alone are four


@pytest.mark.parametrize("dataset", DATASETS)
def test_find_recordings_uses_each_layouts_own_rule(tmp_path, dataset):
    name = FORMATS[dataset].NAME
    if name == "asl":
        for seq in ("a/MH_01", "b/V1_01"):
            (tmp_path / seq / "mav0").mkdir(parents=True)
    else:
        for seq in ("a/one", "b/two"):
            MAKERS[name](tmp_path / seq)
    names = [n for n, _p in find_recordings(dataset, tmp_path)]
    assert names == (["a_one_01_trial", "b_two_01_trial"] if name == "broad" else
                     ["a_MH_01", "b_V1_01"] if name == "asl" else ["a_one", "b_two"])


@pytest.mark.parametrize("end", [b"\r\n", b"\n"])
def test_an_asl_imu_file_is_written_back_with_its_own_line_ends(tmp_path, end):
    """EuRoC's zips hold CRLF files: a refined copy keeps them (and LF stays LF), every line."""
    src_file = SHIPPED_ASL / "mav0" / "imu0" / "data.csv"
    lines = src_file.read_bytes().replace(b"\r\n", b"\n").split(b"\n")[:300]
    rec = tmp_path / "rec"
    (rec / "mav0" / "imu0").mkdir(parents=True)
    (rec / "mav0" / "imu0" / "data.csv").write_bytes(end.join(lines) + end)
    src = read_imu_source(rec)
    out = tmp_path / "out.csv"
    write_imu(src, out, src.gyro + 1e-3, src.acc)
    raw = out.read_bytes()
    assert raw.count(b"\n") == len(lines) and raw.count(b"\r\n") == (len(lines) if end == b"\r\n" else 0)
    back = read_imu_source(out, "asl")
    np.testing.assert_array_equal(back.gyro, src.gyro + 1e-3)
