"""Ground-truth labels: independent numpy oracle, and agreement with the integrated real IMU."""
import numpy as np

import imu_learn as il
from imu_learn.data.synthetic import qconj, qmul, rotate


def rotate_inv(q, v):
    """R(q)ᵀ v, by the sandwich product."""
    return rotate(qconj(q), v)


def test_labels_match_a_direct_numpy_evaluation(shipped):
    seq = il.load_sequence(shipped / "euroc" / "MH_01_easy")[0]
    lab = il.window_labels(seq, window=100, stride=37)
    assert list(lab.horizons) == [20, 40, 60, 80, 100]
    k = lab.starts[:, None]
    j = k + lab.horizons[None, :]
    q = seq.q_wxyz / np.linalg.norm(seq.q_wxyz, axis=1, keepdims=True)
    dt = (seq.t_ns[j] - seq.t_ns[k]) * 1e-9
    g = np.array([0, 0, -9.81])
    qk = np.broadcast_to(q[k], j.shape + (4,))
    dq = qmul(qk * np.array([1, -1, -1, -1]), q[j])
    dv = rotate_inv(qk, seq.v[j] - seq.v[k] - g * dt[..., None])
    dp = rotate_inv(qk, seq.p[j] - seq.p[k] - seq.v[k] * dt[..., None] - 0.5 * g * dt[..., None] ** 2)
    sign = np.sign(np.sum(dq * lab.dq_wxyz, -1, keepdims=True))
    np.testing.assert_allclose(lab.dq_wxyz * sign, dq, atol=1e-12)
    np.testing.assert_allclose(lab.dv, dv, atol=1e-10)
    np.testing.assert_allclose(lab.dp, dp, atol=1e-10)
    np.testing.assert_allclose(lab.dt, dt, atol=1e-15)


def rot_angle(qa, qb):
    d = np.abs(np.sum(qa * qb, -1)).clip(0, 1)
    return 2 * np.arccos(d)


def test_integrated_real_imu_agrees_with_labels_once_bias_is_removed(shared):
    """Real EuRoC V1_01 with its 200 Hz ground-truth state: integrating the IMU minus the
    ground-truth biases must reproduce the GT labels to within sensor noise over 1 s windows, and
    do clearly better than the raw IMU (whose ~0.08 rad/s z bias dominates)."""
    root = shared / "euroc" / "V1_01_easy"
    seq = il.load_sequence(root, groundtruth=root / "groundtruth_pose.tum")[0]
    lab = il.window_labels(seq, window=200, stride=50)
    raw = il.integrate_windows(seq, lab.starts, lab.horizons)
    bias_g = np.array([-0.002, 0.021, 0.077])  # the real data README: V1_0x gyro bias
    corrected = il.Segment("c", seq.t_ns, seq.gyro - bias_g, seq.acc, seq.p, seq.v, seq.q_wxyz)
    cor = il.integrate_windows(corrected, lab.starts, lab.horizons)
    e_raw = rot_angle(raw.dq_wxyz[:, -1], lab.dq_wxyz[:, -1])
    e_cor = rot_angle(cor.dq_wxyz[:, -1], lab.dq_wxyz[:, -1])
    print(f"1 s rotation error RMSE: raw {np.sqrt(np.mean(e_raw**2)):.4f} rad, gyro bias removed {np.sqrt(np.mean(e_cor**2)):.4f} rad")
    assert np.sqrt(np.mean(e_cor ** 2)) < 0.01
    assert np.sqrt(np.mean(e_cor ** 2)) < 0.3 * np.sqrt(np.mean(e_raw ** 2))
