import numpy as np

from imu_learn import wxyz_to_xyzw, xyzw_to_wxyz


def test_order_conversion_moves_w_and_round_trips():
    q_xyzw = np.array([[0.1, 0.2, 0.3, 0.9], [0.0, 0.0, 0.0, 1.0]])
    q_wxyz = xyzw_to_wxyz(q_xyzw)
    np.testing.assert_array_equal(q_wxyz[0], [0.9, 0.1, 0.2, 0.3])
    np.testing.assert_array_equal(wxyz_to_xyzw(q_wxyz), q_xyzw)


def test_sequence_q_xyzw_matches_tum_file(shipped):
    import imu_learn as il

    seq = il.load_sequence(shipped / "euroc" / "MH_01_easy")[0]
    rows = np.loadtxt(shipped / "euroc" / "MH_01_easy" / "groundtruth_pose.tum")
    t_ns = np.round(rows[:, 0] * 1e9).astype(np.int64)
    common, i_seq, i_gt = np.intersect1d(seq.t_ns, t_ns, return_indices=True)
    assert len(common) > 100
    q_file = rows[i_gt, 4:8] / np.linalg.norm(rows[i_gt, 4:8], axis=1, keepdims=True)
    q_seq = seq.q_xyzw[i_seq]
    sign = np.sign(np.sum(q_file * q_seq, axis=1, keepdims=True))
    np.testing.assert_allclose(q_seq * sign, q_file, atol=1e-12)
