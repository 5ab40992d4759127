"""Real recordings of every shipped/shared format load, align and label."""
from pathlib import Path

import numpy as np
import pytest

import imu_learn as il

REPO = Path(__file__).resolve().parent.parent



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


def write_kaist_recording(root: Path, seconds: float = 4.0):
    """A KAIST-format recording of a known motion: yaw at 0.5 rad/s while moving on a circle.
    xsens_imu.csv at 100 Hz (17 columns), global_pose.csv at 100 Hz (t + 3x4 [R|t] row-major)."""
    (root / "sensor_data").mkdir(parents=True)
    t = np.arange(int(seconds * 100) + 1) / 100.0
    t_ns = 1_544_590_798_711_913_000 + np.round(t * 1e9).astype(np.int64)
    w, r = 0.5, 2.0
    yaw = w * t
    p = np.stack([r * np.cos(yaw), r * np.sin(yaw), np.zeros_like(t)], 1)
    acc_world = np.stack([-r * w * w * np.cos(yaw), -r * w * w * np.sin(yaw), np.zeros_like(t)], 1)
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.zeros((len(t), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1
    f_body = np.einsum("nji,nj->ni", R, acc_world + [0, 0, 9.81])
    gyro = np.tile([0.0, 0.0, w], (len(t), 1))
    with open(root / "sensor_data" / "xsens_imu.csv", "w") as f:
        for i in range(len(t)):
            q = [0, 0, np.sin(yaw[i] / 2), np.cos(yaw[i] / 2)]
            row = [*q, 0, 0, yaw[i], *gyro[i], *f_body[i], 0.1, 0.2, 0.3]
            f.write(f"{t_ns[i]}," + ",".join(f"{x:.12g}" for x in row) + "\n")
    with open(root / "global_pose.csv", "w") as f:
        for i in range(len(t)):
            m = np.concatenate([R[i], p[i][:, None]], 1).ravel()
            f.write(f"{t_ns[i]}," + ",".join(f"{x:.12g}" for x in m) + "\n")
    return t_ns, p


def test_kaist_format_recording_loads_and_its_imu_reproduces_its_labels(tmp_path):
    t_ns, p = write_kaist_recording(tmp_path / "urban00")
    rec = il.load_recording(tmp_path / "urban00", format="kaist")
    assert len(rec.segments) == 1 and rec.report["velocity_derived"] is True
    seq = rec.segments[0]
    check_sequence(seq)
    np.testing.assert_allclose(seq.p, p, atol=1e-9)
    lab = il.window_labels(seq, window=100, stride=20)
    imu = il.integrate_windows(seq, lab.starts, lab.horizons)
    ang = 2 * np.arccos(np.abs(np.sum(imu.dq_wxyz * lab.dq_wxyz, -1)).clip(0, 1))
    assert ang.max() < 1e-6
    # Velocity is derived from 100 Hz poses and the IMU is held per sample: a few mm/s over 1 s.
    assert np.abs(imu.dv - lab.dv).max() < 0.05


def test_every_shared_euroc_groundtruth_file_reads(shared):
    from imu_learn.data.formats.groundtruth import read_groundtruth

    for f in sorted((shared / "euroc-groundtruth").glob("*.csv")):
        gt = read_groundtruth(f)
        assert gt.v is not None and len(gt) > 1000


def _arrays(n: int = 2000, rate: float = 200.0):
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    rng = np.random.default_rng(0)
    imu = il.ImuData(t, 0.01 * rng.standard_normal((n, 3)), np.array([0.0, 0.0, 9.81]) + 0.1 * rng.standard_normal((n, 3)))
    p = np.stack([np.linspace(0, 1, n), np.zeros(n), np.zeros(n)], axis=1)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return imu, t, p, q


def test_align_makes_nan_ground_truth_rows_gaps_and_refuses_a_nan_imu_sample():
    """Arrays handed to ``il.align`` (not through a format's reader): a motion-capture dropout written
    as NaN rows becomes a gap between segments, never NaN labels; a NaN IMU sample is refused."""
    imu, t, p, q = _arrays()
    q[900:950] = np.nan
    rec = il.align(imu, il.GroundTruth(t, p, q))
    assert len(rec.segments) == 2 and rec.report["gt_rows_not_finite"] == 50
    for s in rec.segments:
        assert np.isfinite(s.q_wxyz).all() and np.isfinite(s.v).all() and np.isfinite(s.p).all()
    assert "gt_rows_not_finite" not in il.align(imu, il.GroundTruth(t, p, np.nan_to_num(q, nan=1.0))).report
    gyro = imu.gyro.copy()
    gyro[7, 1] = np.inf
    with pytest.raises(il.InvalidInputError, match="gyro row 7 is not finite"):
        il.align(il.ImuData(imu.t_ns, gyro, imu.acc), il.GroundTruth(t, p, q))
