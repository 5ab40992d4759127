"""imu_learn.fuse.variance: the per-sample variances calibrated over keyframe intervals, on synthetic data
whose truth is known (a still body, the IMU's exact readings plus noise of known statistics)."""
from __future__ import annotations

import numpy as np
import pytest

from imu_learn.data.types import Segment
from imu_learn.errors import InvalidInputError
from imu_learn.fuse.variance import interval_residuals, remove_bias, scale_from_residuals, sequence_residuals

G = 9.81
N = 40_001  # 200 s at 200 Hz: 2000 intervals of 20 samples
SG, SA = 0.01, 0.2  # per-sample sigmas [rad/s], [m/s^2]


def still(gyro_noise: np.ndarray, acc_noise: np.ndarray) -> Segment:
    """A body at rest, level, for N samples at 200 Hz: ground truth exact, the IMU reads 0 and +g plus noise."""
    t = np.arange(N, dtype=np.int64) * 5_000_000
    z = np.zeros((N, 3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (N, 1))
    return Segment("still", t, gyro_noise, np.array([0.0, 0.0, G]) + acc_noise, z, z.copy(), q)


def per_sample_var() -> np.ndarray:
    return np.tile([SG ** 2] * 3 + [SA ** 2] * 3, (N, 1))


def test_white_noise_of_the_predicted_variance_gives_k_one():
    rng = np.random.default_rng(1)
    seq = still(rng.normal(0, SG, (N, 3)) + [1e-3, -2e-3, 5e-4], rng.normal(0, SA, (N, 3)) + [0.05, 0.0, -0.1])
    res = sequence_residuals(seq, per_sample_var(), K=20, gravity=G)
    assert len(res) == 2000
    np.testing.assert_allclose(res.rot.mean(0), 0, atol=1e-15)  # the constant bias is removed
    k = scale_from_residuals([res])
    assert k.n == 2000
    for v in (k.k_gyro, k.k_acc, k.k_gyro_mean, k.k_acc_mean):
        assert 0.85 < v < 1.15, k
    # twice the variance the head predicts: k = 2
    k2 = scale_from_residuals([sequence_residuals(seq, per_sample_var() / 2, K=20, gravity=G)])
    assert 1.7 < k2.k_gyro < 2.3 and 1.7 < k2.k_acc < 2.3, k2


def test_noise_that_cancels_over_the_interval_gives_k_far_below_one():
    """Differenced white noise e_i - e_(i-1) (per-sample variance 2 s^2) sums over K samples to
    e_end - e_start: variance 2 s^2 instead of the 2 K s^2 white noise would give, k = 1 / K."""
    rng = np.random.default_rng(2)
    eg, ea = rng.normal(0, SG, (N + 1, 3)), rng.normal(0, SA, (N + 1, 3))
    seq = still(np.diff(eg, axis=0), np.diff(ea, axis=0))
    k = scale_from_residuals([sequence_residuals(seq, 2 * per_sample_var(), K=20, gravity=G)])
    for v in (k.k_gyro, k.k_acc, k.k_gyro_mean, k.k_acc_mean):
        assert 0.04 < v < 0.06, k  # 1 / K = 0.05


def test_inputs_are_checked_and_short_sequences_give_no_interval():
    rng = np.random.default_rng(3)
    seq = still(rng.normal(0, SG, (N, 3)), rng.normal(0, SA, (N, 3)))
    with pytest.raises(InvalidInputError, match="var must be"):
        interval_residuals(seq, np.ones((N, 5)))
    with pytest.raises(InvalidInputError, match="K must be"):
        interval_residuals(seq, per_sample_var(), K=0)
    short = Segment("s", seq.t_ns[:10], seq.gyro[:10], seq.acc[:10], seq.p[:10], seq.v[:10], seq.q_wxyz[:10])
    assert len(remove_bias(interval_residuals(short, per_sample_var()[:10], K=20))) == 0
    with pytest.raises(InvalidInputError, match="no interval"):
        scale_from_residuals([interval_residuals(short, per_sample_var()[:10], K=20)])
