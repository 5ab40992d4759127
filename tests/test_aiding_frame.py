"""The aiding frame check (imu_learn.fuse.aiding.frame) against known mountings: a synthetic IMU turning
about every axis (or about one), its body poses at 20 Hz seen through a known rotation, the gyro with a
constant bias and white noise. The estimated angle is compared with the rotation put in."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_learn.calib.frames import kabsch, trimmed_kabsch
from imu_learn.fuse.aiding.frame import MAX_ROTATION_DEG, TURN_MIN_DEG, check_frame, turned_onto_gyro
from imu_learn.fuse.aiding.noise import pose_noise
from imu_learn.fuse.aiding.pairs import rotation_pairs
from imu_learn.fuse.aiding.types import AidingRows

RATE_HZ, AID_HZ, SECONDS = 200, 20, 60.0


def motion(planar: bool, seed: int = 0):
    """(t_ns, body rates (N, 3), body-to-world rotations (N,)): smooth random rates, yaw only if planar."""
    rng = np.random.default_rng(seed)
    n = int(SECONDS * RATE_HZ)
    t = np.arange(n) / RATE_HZ
    w = np.zeros((n, 3))
    for k in range(3):
        f = rng.uniform(0.1, 0.6, 3)
        ph = rng.uniform(0, 2 * np.pi, 3)
        w[:, k] = sum(0.4 * np.sin(2 * np.pi * fi * t + p) for fi, p in zip(f, ph))
    if planar:
        w[:, :2] = 0.0
    R = [Rotation.identity()]
    for k in range(n - 1):
        R.append(R[-1] * Rotation.from_rotvec(w[k] / RATE_HZ))
    return (t * 1e9).astype(np.int64), w, Rotation.concatenate(R)


def rows_seen_through(R_WB: Rotation, mount: Rotation) -> AidingRows:
    """The poses of a sensor whose frame is the body's turned by ``mount`` (R_B_S), every 10th sample."""
    idx = np.arange(0, len(R_WB), RATE_HZ // AID_HZ)
    R_WS = (R_WB[idx] * mount).as_matrix()
    return AidingRows(idx, idx.astype(np.int64), idx.astype(np.int64), np.zeros((len(idx), 3)), R_WS)


def gyro_of(w: np.ndarray, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return w + np.array([0.08, -0.03, 0.05]) + rng.normal(0, 0.01, w.shape)  # EuRoC-sized bias


@pytest.mark.parametrize("deg", [0.0, 0.6, 3.0, 10.0, 90.0, 119.0, 180.0])
def test_the_estimated_angle_is_the_mounting_put_in(deg):
    t, w, R = motion(planar=False)
    mount = Rotation.from_rotvec(np.deg2rad(deg) * np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5]))
    c = check_frame(t, gyro_of(w), rows_seen_through(R, mount))
    assert not c.axis_only and c.pairs > 1000
    assert c.rotation_deg == pytest.approx(deg, abs=0.3)
    want = "refused" if deg > MAX_ROTATION_DEG else ("warned" if deg > 1.0 else "same frame")
    assert c.verdict == want


def test_planar_motion_compares_the_axis_only():
    t, w, R = motion(planar=True)
    g = gyro_of(w)
    # turned about the yaw axis itself: not observable, and harmless for the axis
    c = check_frame(t, g, rows_seen_through(R, Rotation.from_euler("z", 70, degrees=True)))
    assert c.axis_only and c.verdict == "same frame" and c.rotation_deg < 1.0
    # a camera looking forward (its z along the body's x): the yaw axis lands on another axis
    c = check_frame(t, g, rows_seen_through(R, Rotation.from_euler("y", 90, degrees=True)))
    assert c.axis_only and c.verdict == "refused" and c.rotation_deg == pytest.approx(90, abs=1)
    # upside down (180 deg about x): the axis is reversed, not hidden by a sign
    c = check_frame(t, g, rows_seen_through(R, Rotation.from_euler("x", 180, degrees=True)))
    assert c.verdict == "refused" and c.rotation_deg == pytest.approx(180, abs=1)


def test_too_little_motion_or_too_few_rows_is_not_checked():
    t, w, R = motion(planar=False)
    still = check_frame(t, gyro_of(0.001 * w), rows_seen_through(Rotation.identity(len(t)), Rotation.identity()))
    assert still.verdict == "not checked" and "turns too little" in still.why
    rows = rows_seen_through(R, Rotation.identity())
    few = AidingRows(rows.sample[:10], rows.t_ns[:10], rows.imu_t_ns[:10], rows.p[:10], rows.R[:10])
    assert check_frame(t, gyro_of(w), few).verdict == "not checked"


def test_the_frame_check_and_the_noise_estimate_pair_the_same_rows():
    """One pairing (imu_learn.fuse.aiding.pairs), used by the frame check and the pose noise estimate:
    consecutive rows pair when their IMU samples are more than zero and at most --max-relative-gap-s
    apart; the gyro's rotation over a pair is its samples' SO(3) chain (here the motion's own rotation,
    composed apart by scipy from the same rates)."""
    t, w, R = motion(planar=False)
    rows = rows_seen_through(R, Rotation.identity())
    keep = np.ones(len(rows.sample), dtype=bool)
    keep[50:58] = False  # a 0.45 s gap (rows every 0.05 s)
    keep[200:209] = False  # a 0.50 s gap
    keep[400:420] = False  # a 1.05 s gap
    idx = np.sort(np.r_[np.flatnonzero(keep), 600])  # row 600 twice: one IMU sample, no span
    s = rows.sample[idx]
    cut = AidingRows(s, s.astype(np.int64), s.astype(np.int64), np.zeros((len(s), 3)), rows.R[idx])
    dt = np.diff(t[s]) * 1e-9
    for gap in (0.5, 0.46, 0.3):
        want = int(np.sum((dt > 0) & (dt <= gap + 1e-9)))
        pairs = rotation_pairs(t, s, cut.R, gap, gyro=w)
        assert len(pairs) == want == check_frame(t, gyro_of(w), cut, gap).pairs
        est = pose_noise(t, gyro_of(w), np.zeros((len(t), 3)), (s, cut.R, cut.p), 1, gap)
        assert est is not None and est.n_rot == want
        truth = (R[s[pairs.a]].inv() * R[s[pairs.b]]).as_matrix()
        np.testing.assert_allclose(pairs.gyro, truth, atol=1e-9)  # 12000 steps composed two ways
        np.testing.assert_allclose(pairs.aiding, truth, atol=1e-12)
    assert len(set(np.diff(s)[dt > 0.3])) == 3  # the gaps the rule is tested on


def test_rates_that_match_in_no_frame_are_the_files_fault_not_an_extrinsics():
    """A mirrored gyro axis (or another recording's poses, the quaternions' order): no rotation maps the aiding's
    rates onto the gyro's; refused as the file's (navigate blamed the extrinsic: 'check its direction')."""
    t, w, R = motion(planar=False)
    rows = rows_seen_through(R, Rotation.from_euler("z", 30, degrees=True))
    good = check_frame(t, gyro_of(w), rows)
    assert good.matches and good.verdict == "refused" and "30.0° from the IMU's" in good.why  # an extrinsic's
    c = check_frame(t, gyro_of(w * [1.0, 1.0, -1.0]), rows)
    assert c.verdict == "refused" and not c.matches and "do not match the IMU's in any frame" in c.why
    assert c.to_dict()["matches_a_frame"] is False


def test_a_frame_the_rates_fix_is_turned_onto_the_gyros():
    """Poses 0.6° off the IMU's frame (a stereo VO's rectified camera behind the raw camera's T_BS): the rates
    fix the rotation to a few hundredths of a degree, so the poses are turned onto the gyro's frame and then
    are the body's own; a rotation below the rule's 0.3°, or one that only the main axis tells (planar
    motion), is left as it is."""
    t, w, R = motion(planar=False)
    g = gyro_of(w)
    axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    rows = rows_seen_through(R, Rotation.from_rotvec(np.deg2rad(0.6) * axis))
    c = check_frame(t, g, rows)
    assert c.verdict == "same frame" and c.resolved and c.spread_deg < 0.05
    assert c.rotation_deg == pytest.approx(0.6, abs=0.05)
    turned = turned_onto_gyro(rows, c)
    assert turned.frame.turned and turned.frame.to_dict()["turned"] is True
    left = (Rotation.from_matrix(turned.R) * R[rows.sample].inv()).magnitude()  # the body's own poses
    assert np.degrees(left.max()) < 0.05
    np.testing.assert_array_equal(turned.p, rows.p)
    assert check_frame(t, g, turned).rotation_deg < 0.05
    small = rows_seen_through(R, Rotation.from_rotvec(np.deg2rad(0.5 * TURN_MIN_DEG) * axis))
    c_small = check_frame(t, g, small)
    assert not c_small.resolved and turned_onto_gyro(small, c_small) is small
    tp, wp, Rp = motion(planar=True)
    planar = rows_seen_through(Rp, Rotation.from_euler("x", 2.0, degrees=True))
    c_planar = check_frame(tp, gyro_of(wp), planar)
    assert c_planar.axis_only and not c_planar.resolved and turned_onto_gyro(planar, c_planar) is planar


def test_a_few_glitched_pairs_do_not_tilt_the_trimmed_rotation():
    """Rate pairs through a known rotation with white noise, 3 % of them a VO's glitches (their rates turned
    20° about one axis): plain Kabsch is pulled off by tenths of a degree, the trimmed fit stays within a
    few hundredths, drops most glitches and keeps nearly every good pair."""
    rng = np.random.default_rng(3)
    R_true = Rotation.from_rotvec(np.deg2rad(0.6) * np.array([0.6, -0.8, 0.0]))
    b = rng.normal(0, 0.4, (3000, 3))
    a = b @ R_true.as_matrix().T + np.array([0.02, -0.01, 0.07]) + rng.normal(0, 0.01, b.shape)
    bad = rng.choice(len(a), 90, replace=False)
    a[bad] = b[bad] @ (R_true * Rotation.from_euler("z", 20, degrees=True)).as_matrix().T + [0.02, -0.01, 0.07]
    err = lambda R: np.degrees((Rotation.from_matrix(R) * R_true.inv()).magnitude())  # noqa: E731
    plain = err(kabsch(a, b)[0])
    R, c, keep = trimmed_kabsch(a, b)
    assert plain > 0.4 and err(R) < 0.1 and err(R) < plain / 5, (plain, err(R))
    assert keep[bad].mean() < 0.2 and keep.sum() > 0.95 * (len(a) - len(bad))
    np.testing.assert_allclose(c, [0.02, -0.01, 0.07], atol=2e-3)
