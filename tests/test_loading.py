"""Real recordings of every shipped/shared format load, align and label."""
from pathlib import Path

import numpy as np
import pytest

import imu_learn as il

REPO = Path(__file__).resolve().parent.parent
KAIST_FIXTURE = REPO / "crates" / "imu_core" / "tests" / "fixtures" / "kaist"


def check_sequence(seq):
    n = len(seq)
    assert n > 10
    assert seq.t_ns.dtype == np.int64 and np.all(np.diff(seq.t_ns) > 0)
    for a, k in ((seq.gyro, 3), (seq.acc, 3), (seq.p, 3), (seq.v, 3), (seq.q_wxyz, 4)):
        assert a.shape == (n, k) and a.dtype == np.float64 and np.isfinite(a).all()
    np.testing.assert_allclose(np.linalg.norm(seq.q_wxyz, axis=1), 1.0, atol=1e-9)


@pytest.mark.parametrize("name", ["MH_01_easy", "V1_01_easy"])
def test_shipped_euroc_crops_load(shipped, name):
    rec = il.load_recording(shipped / "euroc" / name)
    assert len(rec.segments) == 1
    check_sequence(rec.segments[0])
    assert rec.report["velocity_derived"] is True
    assert rec.segments[0].duration_s > 59.0


def test_full_euroc_with_separate_groundtruth(shared):
    root = shared / "euroc" / "V1_01_easy"
    gt20 = root / "groundtruth_state_20hz.csv"
    # 20 Hz poses are 50 ms apart: with the default 50 ms gap limit they split everywhere.
    with pytest.raises(il.AlignmentError, match="gap"):
        il.load_sequence(root, format="euroc", groundtruth=gt20)
    segs = il.load_sequence(root, format="euroc", groundtruth=gt20, options=il.AlignOptions(max_gap_s=0.1))
    assert len(segs) == 1
    check_sequence(segs[0])
    rec = il.load_recording(root / "mav0" / "imu0" / "data.csv", groundtruth=root / "groundtruth_pose.tum")
    check_sequence(rec.segments[0])
    # IMU rows before the first and after the last pose are dropped and counted.
    r = rec.report
    kept = sum(len(s) for s in rec.segments)
    assert kept + r["dropped_before"] + r["dropped_after"] + r["dropped_in_gaps"] + r["dropped_short"] == 29120


def test_blackbird_loads_with_its_own_velocity(shared):
    for split in ("train", "val"):
        rec = il.load_recording(shared / "blackbird" / "clover_yawForward_maxSpeed5p0" / split, format="blackbird")
        assert rec.report["velocity_derived"] is False
        for s in rec.segments:
            check_sequence(s)


def test_broad_nan_gaps_split_segments(shared):
    rec = il.load_recording(shared / "broad" / "04_undisturbed_slow_rotation_with_breaks_A.mat")
    assert len(rec.report["gaps_ns"]) >= 1
    assert len(rec.segments) >= 2
    for s in rec.segments:
        check_sequence(s)


@pytest.mark.parametrize("trial", ["01_undisturbed_slow_rotation_A.mat", "21_undisturbed_fast_combined.mat"])
def test_broad_trials_load(shared, trial):
    for s in il.load_sequence(shared / "broad" / trial):
        check_sequence(s)


def test_kaist_fixture_loads():
    if not KAIST_FIXTURE.exists():
        pytest.fail(f"KAIST fixture missing at {KAIST_FIXTURE}")
    segs = il.load_sequence(KAIST_FIXTURE, format="kaist")
    for s in segs:
        check_sequence(s)


def test_every_shared_euroc_groundtruth_file_reads(shared):
    from imu_learn.formats.groundtruth import read_groundtruth

    for f in sorted((shared / "euroc-groundtruth").glob("*.csv")):
        gt = read_groundtruth(f)
        assert gt.v is not None and len(gt) > 1000
