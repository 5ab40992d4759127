"""The pose aiding's noise and time offset, estimated from the data against the IMU (synthetic: a
known noise level and offset recovered; a jump or loop closure does not inflate the estimate), and
the relative poses over several spans that keep a trajectory's global consistency."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_learn.fuse.aiding.estimate import one_line_text, shift_trajectory, summary_entry
from imu_learn.fuse.aiding.noise import gyro_orientation, pose_noise
from imu_learn.fuse.aiding.offset import estimate_offset
from imu_learn.fuse.aiding.spans import given_noise, pair_sigmas, relative_poses, span_pairs, unbroken
from imu_learn.fuse.aiding.tum import Trajectory
from imu_learn.fuse.aiding.types import AidingRows

RATE = 200.0
G = np.array([0.0, 0.0, -9.81])


def flight(seconds: float = 60.0, seed: int = 0):
    """(t_ns, gyro, acc, R (N, 3, 3), p (N, 3)): a smooth 6-DoF motion whose IMU is exact (the gyro's
    rate held over each sample interval is the orientation's step; the specific force from the
    analytic acceleration)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    t = np.arange(n) / RATE
    freq, phase = rng.uniform(0.3, 12.0, (4, 3)), rng.uniform(0, 2 * np.pi, (4, 3))
    gyro = 0.4 * np.sin(freq[None] * t[:, None, None] + phase[None]).sum(axis=1)
    R = gyro_orientation((t * 1e9).astype(np.int64), gyro)
    w = np.array([0.5, 0.3, 0.7])
    amp = np.array([2.0, 1.5, 0.4])
    p = amp * np.sin(w * t[:, None])
    a = -amp * w ** 2 * np.sin(w * t[:, None])
    acc = np.einsum("nki,nk->ni", R, a - G)
    return (t * 1e9).astype(np.int64), gyro, acc, R, p


def noisy_rows(R, p, sigma_rot_rad: float, sigma_m: float, every: int = 10, seed: int = 1):
    """Aiding rows every ``every`` IMU samples (20 Hz), each pose with white noise of the given sigmas."""
    rng = np.random.default_rng(seed)
    sample = np.arange(0, len(p), every)
    Rn = R[sample] @ Rotation.from_rotvec(rng.normal(0, sigma_rot_rad, (len(sample), 3))).as_matrix()
    pn = p[sample] + rng.normal(0, sigma_m, (len(sample), 3))
    return sample, Rn, pn


@pytest.fixture(scope="module")
def synthetic():
    t_ns, gyro, acc, R, p = flight()
    return t_ns, gyro, acc, R, p, gyro_orientation(t_ns, gyro)


def test_a_known_noise_level_is_recovered_per_axis(synthetic):
    t_ns, gyro, acc, R, p, C = synthetic
    sig_rot, sig_m = np.deg2rad(0.05), 0.003
    sample, Rn, pn = noisy_rows(R, p, sig_rot, sig_m)
    est = pose_noise(t_ns, gyro, acc, (sample, Rn, pn), C=C)
    assert est is not None and est.n_rot > 500 and est.n_trans > 500
    np.testing.assert_allclose(est.trans_m, sig_m, rtol=0.15)
    np.testing.assert_allclose(est.rot_rad, sig_rot, rtol=0.15)
    # three times the noise reads three times as large
    sample, Rn, pn = noisy_rows(R, p, 3 * sig_rot, 3 * sig_m)
    est3 = pose_noise(t_ns, gyro, acc, (sample, Rn, pn), C=C)
    np.testing.assert_allclose(est3.trans_m / est.trans_m, 3.0, rtol=0.15)
    np.testing.assert_allclose(est3.rot_rad / est.rot_rad, 3.0, rtol=0.15)


def test_a_gyro_bias_and_gravity_do_not_enter_the_estimate(synthetic):
    t_ns, gyro, acc, R, p, C = synthetic
    sample, Rn, pn = noisy_rows(R, p, np.deg2rad(0.05), 0.003)
    clean = pose_noise(t_ns, gyro, acc, (sample, Rn, pn), C=C)
    biased = pose_noise(t_ns, gyro + [0.01, -0.02, 0.015], acc + [0.1, 0.0, -0.2], (sample, Rn, pn))
    np.testing.assert_allclose(biased.rot_rad, clean.rot_rad, rtol=0.1)
    np.testing.assert_allclose(biased.trans_m, clean.trans_m, rtol=0.1)


def test_jumps_and_a_loop_closure_do_not_inflate_the_estimate(synthetic):
    t_ns, gyro, acc, R, p, C = synthetic
    sample, Rn, pn = noisy_rows(R, p, np.deg2rad(0.05), 0.003)
    clean = pose_noise(t_ns, gyro, acc, (sample, Rn, pn), C=C)
    pj, Rj = pn.copy(), Rn.copy()
    pj[600:] += [0.4, -0.3, 0.1]  # a loop closure: the rest of the trajectory moved at once
    Rj[600:] = Rotation.from_euler("z", 3, degrees=True).as_matrix() @ Rj[600:]
    for k in (100, 250, 900):  # single outliers
        pj[k] += 0.2
        Rj[k] = Rj[k] @ Rotation.from_rotvec([0.05, 0, 0]).as_matrix()
    jumped = pose_noise(t_ns, gyro, acc, (sample, Rj, pj), C=C)
    np.testing.assert_allclose(jumped.trans_m, clean.trans_m, rtol=0.1)
    np.testing.assert_allclose(jumped.rot_rad, clean.rot_rad, rtol=0.1)
    # a plain standard deviation of the same residuals would not have been robust: the jump is 130 sigmas
    assert np.linalg.norm([0.4, -0.3, 0.1]) > 100 * clean.trans_m.max()


def test_the_floor_holds_for_a_noiseless_aiding(synthetic):
    t_ns, gyro, acc, R, p, C = synthetic
    sample, Rn, pn = noisy_rows(R, p, 0.0, 0.0)
    est = pose_noise(t_ns, gyro, acc, (sample, Rn, pn), C=C)
    assert np.all(est.trans_m >= 0.0005) and np.all(est.rot_rad >= np.deg2rad(0.005))
    assert np.all(est.trans_m < 0.001)


def test_too_few_rows_give_no_estimate(synthetic):
    t_ns, gyro, acc, R, p, C = synthetic
    sample, Rn, pn = noisy_rows(R[:100], p[:100], 0.001, 0.003)
    assert pose_noise(t_ns, gyro, acc, (sample, Rn, pn), C=C) is None


@pytest.mark.parametrize("lag_s", [0.012, -0.0237, 0.0, 0.2])  # 0.2 s: a late clock (the edge of the search it had)
def test_a_known_time_offset_is_recovered(synthetic, lag_s):
    t_ns, gyro, acc, R, p, C = synthetic
    sample = np.arange(0, len(t_ns), 10)
    q = Rotation.from_matrix(R[sample]).as_quat()
    # the aiding stamped late by lag_s: its stamp t is the motion the IMU saw at t - lag_s
    off = estimate_offset(t_ns, gyro, t_ns[sample] + int(round(lag_s * 1e9)), q)
    assert off.applied and off.correlation > 0.9
    # each synthetic gyro sample is the rate held over the interval after it: the motion it reads is
    # half a sample later than its stamp, which the estimate sees as that much more lag
    assert abs(off.lag_s - (lag_s + 0.5 / RATE)) < 0.001


def test_an_unrelated_aiding_is_not_shifted(synthetic):
    t_ns, gyro, acc, R, p, C = synthetic
    other = flight(seed=5)
    sample = np.arange(0, len(t_ns), 10)
    off = estimate_offset(t_ns, gyro, t_ns[sample], Rotation.from_matrix(other[3][sample]).as_quat())
    assert not off.applied and "not applied" in off.why


def test_span_pairs_keep_inside_runs_and_reach_far():
    t = np.r_[np.arange(0, 30, 0.05), np.arange(40, 60, 0.05)]  # a 10 s gap at 30 s
    i, j, which = span_pairs(t, (0.0, 1.0, 4.0, 16.0), max_gap_s=0.5)
    assert not np.any((t[i] < 30) & (t[j] >= 40))  # never across the gap
    assert np.all(i < j) and len(set(zip(i, j))) == len(i)
    assert np.sum(which == 0) == len(t) - 2  # every consecutive pair but the gap's
    assert (t[j] - t[i]).max() >= 16.0
    consecutive = span_pairs(t, (0.0,), max_gap_s=0.5)
    assert len(consecutive[0]) == len(t) - 2


def test_pair_sigmas_grow_with_the_lever_of_the_rotation():
    noise = given_noise(np.deg2rad(0.1), 0.004)
    sig = pair_sigmas(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 10.0]]), noise)
    np.testing.assert_allclose(sig[0, 3:], 0.004)
    np.testing.assert_allclose(sig[:, :3], np.deg2rad(0.1))
    assert sig[1, 3] > 3 * sig[0, 3] and sig[1, 5] == pytest.approx(0.004)


def test_relative_poses_and_the_summary_line(synthetic):
    t_ns, gyro, acc, R, p, C = synthetic
    sample, Rn, pn = noisy_rows(R, p, np.deg2rad(0.05), 0.003)
    est = pose_noise(t_ns, gyro, acc, (sample, Rn, pn), C=C)
    a, counts = relative_poses(sample, t_ns[sample], Rn, pn, est, (0.0, 1.0, 16.0), 0.5, "vo")
    assert a.sigmas.shape == (len(a), 6) and counts["relative_poses"] == len(a)
    assert counts["relative_poses_per_span"][0] == len(sample) - 1
    k = np.flatnonzero(a.j - a.i > 10)[0]  # a long span: its relative pose is the rows' own
    np.testing.assert_allclose(a.t_ij[k], Rn[np.searchsorted(sample, a.i[k])].T
                               @ (pn[np.searchsorted(sample, a.j[k])] - pn[np.searchsorted(sample, a.i[k])]))
    rows = AidingRows(sample, t_ns[sample], t_ns[sample], pn, Rn)
    rows.noise = est
    rows.offset = estimate_offset(t_ns, gyro, t_ns[sample], Rotation.from_matrix(Rn).as_quat())
    line = one_line_text(summary_entry(rows, est, "estimated"))
    assert line.startswith("aiding noise 0.0") and "mm per pose (estimated)" in line and "offset" in line
    assert one_line_text(None) == ""


def test_the_navigator_shifts_the_stamps_only_by_a_lag_of_a_sample_or_more(synthetic):
    t_ns, gyro, acc, R, p, C = synthetic
    sample = np.arange(0, len(t_ns), 10)
    q = Rotation.from_matrix(R[sample]).as_quat()
    for lag_s, applied in ((0.0, False), (0.015, True)):
        stamps = t_ns[sample] + int(round(lag_s * 1e9))
        traj = Trajectory(stamps, p[sample], q, "vo.tum", np.arange(len(sample)) + 1)
        moved, off = shift_trajectory(traj, t_ns, gyro)
        assert off.applied is applied and off.to_dict()["applied"] is applied
        if applied:  # back on the IMU's clock to within a sample
            assert np.all(np.abs(moved.t_ns - t_ns[sample]) < 5e6)
        else:
            assert moved is traj and "within one IMU sample" in off.why


def test_only_an_unbroken_aiding_is_tied_over_long_spans():
    t = (np.arange(0, 30, 0.05) * 1e9).astype(np.int64)
    assert unbroken(t, 0.5)
    assert not unbroken(np.r_[t, t[-1] + np.int64(10e9)], 0.5)
