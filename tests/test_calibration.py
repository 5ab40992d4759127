"""Calibration metrics (imu_learn.eval.calibration) on synthetic data whose noise is known exactly."""
import numpy as np
import pytest
from scipy.stats import chi2

from imu_learn.data.synthetic import G, moving, qconj, qmul, rotate
from imu_learn.data.types import Segment
from imu_learn.eval.calibration import (
    BLOCKS,
    calibrate,
    datasheet_variances,
    expected_fraction,
    nees,
    residuals,
    summarise,
    summarise_nees,
)


def test_nees_of_gaussian_draws_is_chi_square():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(9, 9))
    cov = A @ A.T + 0.1 * np.eye(9)
    r = rng.multivariate_normal(np.zeros(9), cov, size=20000)
    s = summarise(r, np.broadcast_to(cov, (len(r), 9, 9)))
    # 20000 draws: the mean of χ²(9) has standard error sqrt(18/20000) = 0.03; a fraction's is <= 0.0035.
    assert s["all"]["mean_nees"] == pytest.approx(9.0, abs=0.15)
    for m in (1, 2, 3):
        assert s["all"][f"in_{m}sigma"] == pytest.approx(chi2.cdf(m * m, 9), abs=0.015)
        assert s["rot"][f"in_{m}sigma"] == pytest.approx(chi2.cdf(m * m, 3), abs=0.015)


def test_an_overconfident_covariance_shows_as_large_nees():
    rng = np.random.default_rng(1)
    r = rng.normal(size=(5000, 9)) * 2.0  # true sigma 2, claimed 1
    s = summarise(r, np.broadcast_to(np.eye(9), (5000, 9, 9)))
    assert s["all"]["mean_nees"] == pytest.approx(36.0, rel=0.05)
    assert s["all"]["in_3sigma"] < 0.1 < s["all"]["expected_3sigma"]


def test_expected_fractions_are_the_textbook_values():
    assert expected_fraction(1, 1) == pytest.approx(0.6827, abs=1e-4)
    assert expected_fraction(2, 1) == pytest.approx(0.9545, abs=1e-4)
    assert expected_fraction(3, 3) == pytest.approx(0.9707, abs=1e-4)


def test_nees_is_nan_where_the_covariance_is_not_positive_definite():
    cov = np.stack([np.eye(3), -np.eye(3)])
    e = nees(np.ones((2, 3)), cov)
    assert e[0] == pytest.approx(3.0) and np.isnan(e[1])


def _exact_imu(seq: Segment):
    """The trajectory's own IMU by finite differences of its ground truth (exact enough for the
    residual to be dominated by the noise added below)."""
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw
    t = (seq.t_ns - seq.t_ns[0]) * 1e-9
    dt = np.diff(t)
    rel = qmul(qconj(seq.q_wxyz[:-1]), seq.q_wxyz[1:])
    gyro = Rotation.from_quat(wxyz_to_xyzw(rel)).as_rotvec() / dt[:, None]
    gyro = np.vstack([gyro, gyro[-1:]])
    # acc held over [t_k, t_k+1] that reproduces the velocity change: R_k^T ((v_k+1 - v_k)/dt + g)
    a_w = np.diff(seq.v, axis=0) / dt[:, None] + np.array([0.0, 0.0, G])
    acc = rotate(qconj(seq.q_wxyz[:-1]), a_w)
    acc = np.vstack([acc, acc[-1:]])
    return gyro, acc


def test_known_per_sample_noise_is_calibrated():
    """White noise whose variance varies 100x along the recording, integrated over 1 s windows:
    the propagated covariance must describe the residuals (NEES ≈ 9, fractions ≈ χ²(9))."""
    seq = moving(60.0)
    gyro, acc = _exact_imu(seq)
    rng = np.random.default_rng(2)
    n = len(seq)
    scale = 1.0 + 9.0 * (0.5 + 0.5 * np.sin(np.arange(n) / 300.0))  # sigma x1 .. x10
    var = np.concatenate([np.repeat(((2e-3 * scale) ** 2)[:, None], 3, 1),
                          np.repeat(((2e-2 * scale) ** 2)[:, None], 3, 1)], axis=1)
    starts = np.arange(0, n - 201, 25)
    base = residuals(seq, gyro, acc, starts, 200)
    # Noise-free residual (finite-difference IMU) is far below the noise: checked, then many noisy copies.
    assert np.abs(base.r).max() < 1e-4
    rs = []
    for _ in range(8):
        noisy_g = gyro + rng.normal(size=gyro.shape) * np.sqrt(var[:, :3])
        noisy_a = acc + rng.normal(size=acc.shape) * np.sqrt(var[:, 3:])
        rs.append(residuals(seq, noisy_g, noisy_a, starts, 200).r)
    from imu_learn.eval.calibration import window_covariances
    cov = window_covariances(seq, gyro, acc, var, starts, 200)
    s = summarise(np.concatenate(rs), np.concatenate([cov] * len(rs)))
    # 8 x 470 windows (overlapping, so fewer independent ones): 5 % on the mean, 0.03 on fractions.
    assert s["all"]["mean_nees"] == pytest.approx(9.0, rel=0.05)
    for b in BLOCKS:
        for m in (1, 2, 3):
            assert s[b][f"in_{m}sigma"] == pytest.approx(s[b][f"expected_{m}sigma"], abs=0.03), (b, m)
    # The datasheet at the smallest sigma is overconfident on the same residuals.
    ds = datasheet_variances(seq.t_ns, 2e-3 * np.sqrt(0.005), 2e-2 * np.sqrt(0.005))
    noisy = (gyro + rng.normal(size=gyro.shape) * np.sqrt(var[:, :3]),
             acc + rng.normal(size=acc.shape) * np.sqrt(var[:, 3:]))
    s_ds = summarise_nees(calibrate(seq, *noisy, ds, starts, 200))
    assert s_ds["all"]["windows"] == len(starts)
    assert s_ds["all"]["mean_nees"] > 3 * 9.0
