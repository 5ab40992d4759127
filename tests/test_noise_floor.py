"""Noise floor (imu_learn.baselines.noise_floor): the IMU synthesised from ground truth integrates back onto it."""
import numpy as np
import pytest
import torch

from imu_learn.baselines.base import poses_from_imu
from imu_learn.baselines.noise_floor import NOISE_FLOOR_NAME, GroundTruthImu, quat_log, synthesize_imu
from imu_learn.data.synthetic import AXIS, DT, G, axis_angle, moving, qconj, qmul, spin
from imu_learn.data.types import Segment
from imu_learn.errors import InvalidInputError
from imu_learn.eval.run import evaluate_sequence, pose_errors, window_starts

torch.set_num_threads(1)



def spinning_in_place(seconds: float = 20.0, rate: float = 0.7):
    """``synthetic.spin`` and its closed-form IMU."""
    seq = spin(seconds, rate)
    return seq, seq.gyro, seq.acc


def integrate_from_start(seq: Segment, gyro: np.ndarray, acc: np.ndarray):
    """End states of one window over the whole sequence from the ground-truth start."""
    pred = poses_from_imu(seq, gyro, acc, np.array([0], dtype=np.uint64), len(seq) - 1, G)
    return pred


def angle_between(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    e = qmul(qconj(q_a), q_b)
    return 2.0 * np.arctan2(np.linalg.norm(e[..., 1:], axis=-1), np.abs(e[..., 0]))


# ---------------------------------------------------------------------------------------------


def test_quat_log_known_values():
    for angle in (0.0, 1e-9, 0.3, 2.0, np.pi - 1e-6):
        q = axis_angle(AXIS, angle)
        np.testing.assert_allclose(quat_log(q), angle * AXIS, atol=1e-12)
        np.testing.assert_allclose(quat_log(-q), angle * AXIS, atol=1e-12)  # q and −q: the same rotation
    # a rotation by more than π is the shorter one the other way round
    np.testing.assert_allclose(quat_log(axis_angle(AXIS, 1.5 * np.pi)), -0.5 * np.pi * AXIS, atol=1e-12)
    assert quat_log(np.zeros((0, 4))).shape == (0, 3)


def test_closed_form_imu_is_reproduced():
    """Constant rate about a tilted axis at rest: synthesize_imu returns exactly gyro = ω·axis,
    acc = Rᵀ[0, 0, g] (all but the last sample, which repeats the one before)."""
    seq, gyro, acc = spinning_in_place()
    g2, a2 = synthesize_imu(seq, G)
    assert g2.shape == a2.shape == (len(seq), 3) and g2.dtype == a2.dtype == np.float64
    np.testing.assert_allclose(g2[:-1], gyro[:-1], atol=1e-11)
    np.testing.assert_allclose(a2[:-1], acc[:-1], atol=1e-11)
    np.testing.assert_array_equal(g2[-1], g2[-2])
    np.testing.assert_array_equal(a2[-1], a2[-2])
    # the specific force of an IMU at rest has magnitude g whatever its orientation
    np.testing.assert_allclose(np.linalg.norm(a2, axis=1), G, rtol=1e-12)


def test_synthesized_imu_integrates_to_ground_truth():
    """Rotation and velocity telescope exactly; a quadratic position is trapezoid-consistent, so
    the position is reproduced too (over the whole 20 s from the start state)."""
    seq = moving()
    gyro, acc = synthesize_imu(seq, G)
    pred = integrate_from_start(seq, gyro, acc)
    assert angle_between(seq.q_wxyz[-1:], pred.q_wxyz)[0] < 1e-10
    np.testing.assert_allclose(pred.v[0], seq.v[-1], atol=1e-10)
    np.testing.assert_allclose(pred.p[0], seq.p[-1], atol=1e-9)
    # and every window of the evaluation is exact
    starts = window_starts(seq, 37, 11, 0)
    e = pose_errors(seq, starts, 37, poses_from_imu(seq, gyro, acc, starts.astype(np.uint64), 37, G))
    assert e["rot_rad"].max() < 1e-12 and e["vel_mps"].max() < 1e-12 and e["trans_m"].max() < 1e-12


def test_position_floor_is_the_trapezoid_error_closed_form():
    """A cubic position p = c t³ (velocity 3 c t²) is not trapezoid-consistent: per step the
    trapezoid of the velocity overshoots by ½ c dt³, so the floor over n samples is ½|c| n dt³,
    while rotation and velocity stay exact."""
    c = np.array([0.2, -0.1, 0.05])
    seq = moving(cubic=c)
    m = GroundTruthImu(G)
    assert m.name == NOISE_FLOOR_NAME
    for n in (10, 200):
        starts = window_starts(seq, n, 25, 0)
        g, a = m.refine(seq)
        e = pose_errors(seq, starts, n, poses_from_imu(seq, g, a, starts.astype(np.uint64), n, G))
        np.testing.assert_allclose(e["trans_m"], 0.5 * np.linalg.norm(c) * n * DT**3, rtol=1e-5)
        assert e["rot_rad"].max() < 1e-12 and e["vel_mps"].max() < 1e-10


def test_noise_floor_row_through_evaluation_is_zero_for_perfect_labels():
    seq = moving()
    out, bias = evaluate_sequence(GroundTruthImu(G), seq, [10, 200], 10, 2.0, G)
    assert set(out) == {(v, n) for v in ("open_loop", "bias_removed") for n in (10, 200)}
    for e in out.values():
        assert e["rot_rad"].max() < 1e-12 and e["trans_m"].max() < 1e-9 and e["vel_mps"].max() < 1e-10
    assert np.abs(bias["gyro"]).max() < 1e-9 and np.abs(bias["acc"]).max() < 1e-8


def test_quaternion_sign_and_scale_do_not_matter():
    """Ground truth may flip the quaternion sign between samples, or store it slightly unnormalised."""
    seq = moving(seconds=5.0)
    g, a = synthesize_imu(seq, G)
    q = seq.q_wxyz.copy()
    q[1::2] *= -1.0
    q *= 1.0 + 1e-7 * np.arange(len(q))[:, None] / len(q)
    g2, a2 = synthesize_imu(Segment(seq.name, seq.t_ns, seq.gyro, seq.acc, seq.p, seq.v, q), G)
    np.testing.assert_allclose(g2, g, atol=1e-9)
    np.testing.assert_allclose(a2, a, atol=1e-9)


def test_gravity_is_a_parameter():
    seq, _, _ = spinning_in_place(seconds=2.0)
    _, a = synthesize_imu(seq, 9.0)
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 9.0, rtol=1e-12)


@pytest.mark.parametrize("n", [0, 1])
def test_too_short_is_a_typed_error(n):
    seq, _, _ = spinning_in_place(seconds=1.0)
    short = Segment("short", seq.t_ns[:n], seq.gyro[:n], seq.acc[:n], seq.p[:n], seq.v[:n], seq.q_wxyz[:n])
    with pytest.raises(InvalidInputError, match="at least 2 samples"):
        synthesize_imu(short)
    with pytest.raises(InvalidInputError):
        GroundTruthImu().refine(short)


def test_two_samples_suffice():
    seq, gyro, acc = spinning_in_place(seconds=1.0)
    two = Segment("two", seq.t_ns[:2], seq.gyro[:2], seq.acc[:2], seq.p[:2], seq.v[:2], seq.q_wxyz[:2])
    g, a = synthesize_imu(two, G)
    np.testing.assert_allclose(g, gyro[:2], atol=1e-11)
    np.testing.assert_allclose(a, np.tile(acc[0], (2, 1)), atol=1e-11)


def test_non_increasing_stamps_are_a_typed_error():
    seq, _, _ = spinning_in_place(seconds=1.0)
    t = seq.t_ns.copy()
    t[5] = t[4]
    with pytest.raises(InvalidInputError, match="increase"):
        synthesize_imu(Segment("dup", t, seq.gyro, seq.acc, seq.p, seq.v, seq.q_wxyz))
