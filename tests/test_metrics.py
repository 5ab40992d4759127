"""Relative pose error and start-up bias fitting (imu_learn.score.metrics)."""
import math

import numpy as np
import pytest

import imu_learn as il
from imu_learn.core.quat import quat_conj, quat_log, quat_mul
from imu_learn.score.metrics import (
    fit_startup_bias,
    relative_pose_errors,
    relative_pose_rmse,
    relative_pose_rmse_many,
    remove_bias,
    rmse,
    simulate_sequence,
    with_imu,
)

G = 9.81


def _motion(seconds=30.0, rate=200.0, seed=0):
    """Smooth, exciting synthetic IMU signal (rotation about all axes, varying specific force)."""
    n = int(seconds * rate) + 1
    t_ns = 10**18 + np.arange(n, dtype=np.int64) * int(round(1e9 / rate))
    t = (t_ns - t_ns[0]) * 1e-9
    rng = np.random.default_rng(seed)
    f = rng.uniform(0.2, 1.5, size=(2, 3))
    ph = rng.uniform(0, 2 * np.pi, size=(2, 3))
    gyro = 0.4 * np.sin(f[0] * t[:, None] + ph[0])
    acc = 0.6 * np.sin(f[1] * t[:, None] + ph[1]) + np.array([0.0, 0.0, G])
    return t_ns, gyro, acc


def _synthetic(**kw):
    t_ns, gyro, acc = _motion(**kw)
    q0 = np.array([0.9, 0.1, -0.3, 0.2])
    return simulate_sequence(t_ns, gyro, acc, q0 / np.linalg.norm(q0), v0=(1.0, -0.5, 0.2), p0=(3.0, 2.0, 1.0), gravity=G)


def test_rmse_arithmetic():
    assert rmse(np.array([3.0, 4.0])) == pytest.approx(math.sqrt(12.5))
    assert rmse(np.array([-2.0])) == 2.0
    assert rmse(np.zeros(5)) == 0.0
    assert rmse([1.0, 1.0, 1.0, 5.0]) == pytest.approx(math.sqrt(7.0), rel=1e-15)  # a list too
    assert math.isnan(rmse(np.zeros(0)))


def test_rmse_matches_per_window_errors():
    seq = _synthetic()
    biased = with_imu(seq, seq.gyro + 0.01, seq.acc - 0.05)
    e = relative_pose_errors(biased, 50, stride=13)
    r = relative_pose_rmse(biased, 50, stride=13)
    assert r["windows"] == len(e["starts"]) > 0
    assert r["rot_rad"] == pytest.approx(np.sqrt(np.mean(e["rot_rad"] ** 2)))
    assert r["rot_deg"] == pytest.approx(math.degrees(r["rot_rad"]))
    assert r["trans_m"] == pytest.approx(np.sqrt(np.mean(e["trans_m"] ** 2)))
    # windows: starts first, first+stride, ... with start + n <= last sample
    assert e["starts"][0] == 0 and np.all(np.diff(e["starts"].astype(np.int64)) == 13)
    assert int(e["starts"][-1]) + 50 <= len(seq) - 1 < int(e["starts"][-1]) + 13 + 50
    pooled = relative_pose_rmse_many([biased, biased], 50, 13)
    assert pooled["windows"] == 2 * r["windows"]
    assert pooled["rot_rad"] == pytest.approx(r["rot_rad"])


def test_constant_gyro_bias_rotation_error_closed_form():
    """A constant gyro bias b on a static IMU rotates by |b| n dt over n samples."""
    n_samples, dt_ns = 1001, 5_000_000
    t_ns = np.arange(n_samples, dtype=np.int64) * dt_ns
    seq = il.Segment(
        "static", t_ns, np.zeros((n_samples, 3)), np.tile([0.0, 0.0, G], (n_samples, 1)),
        np.zeros((n_samples, 3)), np.zeros((n_samples, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (n_samples, 1)),
    )
    r0 = relative_pose_rmse(seq, 200, stride=10, gravity=G)
    assert r0["rot_rad"] < 1e-12 and r0["trans_m"] < 1e-12
    b = np.array([0.0, 0.0, 0.05])
    r = relative_pose_rmse(with_imu(seq, seq.gyro + b, seq.acc), 200, stride=10, gravity=G)
    assert r["rot_rad"] == pytest.approx(0.05 * 200 * 0.005, rel=1e-9)
    # yaw about the gravity axis leaves a static IMU's position untouched
    assert r["trans_m"] < 1e-9
    # an accelerometer bias a gives ½ a T² of position error
    r = relative_pose_rmse(with_imu(seq, seq.gyro, seq.acc + [0.1, 0, 0]), 200, stride=10, gravity=G)
    assert r["trans_m"] == pytest.approx(0.5 * 0.1 * 1.0**2, rel=1e-9)


@pytest.mark.parametrize("n", [1, 10, 200])
def test_exact_imu_gives_zero_error(n):
    seq = _synthetic()
    r = relative_pose_rmse(seq, n, stride=7, gravity=G)
    assert r["windows"] > 100
    assert r["rot_rad"] < 1e-12
    assert r["trans_m"] < 1e-9


def test_zero_error_on_real_stamps():
    """Ground truth rebuilt from a real IMU record (irregular real stamps) with the core."""
    real = il.load_sequence("datasets/euroc/V1_01_easy")[0]
    m = 3000
    seq = simulate_sequence(real.t_ns[:m], real.gyro[:m], real.acc[:m], real.q_wxyz[0], real.v[0], real.p[0], gravity=G)
    for n in (10, 200):
        r = relative_pose_rmse(seq, n, stride=5, gravity=G)
        assert r["rot_rad"] < 1e-12 and r["trans_m"] < 1e-9
    # and the error of a wrong gravity sign shows up (the check is not vacuous)
    assert relative_pose_rmse(seq, 200, stride=5, gravity=-G)["trans_m"] > 1.0


def test_fit_startup_bias_recovers_injected_bias():
    seq = _synthetic(seconds=30.0)
    bg = np.array([0.012, -0.021, 0.077])
    ba = np.array([0.15, -0.08, 0.22])
    biased = with_imu(seq, seq.gyro + bg, seq.acc + ba)
    g_hat, a_hat = fit_startup_bias(biased, seconds=10.0, gravity=G)
    np.testing.assert_allclose(g_hat, bg, atol=1e-7)
    np.testing.assert_allclose(a_hat, ba, atol=1e-6)
    fixed = remove_bias(biased, g_hat, a_hat)
    r = relative_pose_rmse(fixed, 200, stride=20, gravity=G)
    assert r["rot_rad"] < 1e-6 and r["trans_m"] < 1e-6
    assert relative_pose_rmse(biased, 200, stride=20, gravity=G)["trans_m"] > 0.05


def test_fit_startup_bias_with_noise_is_close():
    seq = _synthetic(seconds=20.0, seed=3)
    rng = np.random.default_rng(1)
    bg, ba = np.array([-0.01, 0.02, 0.005]), np.array([0.1, 0.0, -0.2])
    noisy = with_imu(seq, seq.gyro + bg + rng.normal(0, 2e-3, seq.gyro.shape),
                     seq.acc + ba + rng.normal(0, 2e-2, seq.acc.shape))
    g_hat, a_hat = fit_startup_bias(noisy, seconds=10.0, gravity=G)
    np.testing.assert_allclose(g_hat, bg, atol=2e-4)
    np.testing.assert_allclose(a_hat, ba, atol=5e-3)


def test_fit_startup_bias_on_euroc_matches_known_gyro_bias():
    """EuRoC V1_01's gyro bias is about [-0.002, 0.021, 0.077] rad/s (nearly constant)."""
    seq = il.load_sequence("datasets/euroc/V1_01_easy")[0]
    g_hat, _ = fit_startup_bias(seq, seconds=10.0)
    np.testing.assert_allclose(g_hat, [-0.002, 0.021, 0.077], atol=0.006)
    raw = relative_pose_rmse(seq, 200, 10)
    fixed = relative_pose_rmse(remove_bias(seq, *fit_startup_bias(seq)), 200, 10)
    assert fixed["rot_rad"] < 0.3 * raw["rot_rad"]


def test_fit_startup_bias_gyro_is_the_least_squares_minimum_of_the_metrics_integration():
    """Oracle independent of the core's rotation sums: with noise (so the residuals at the minimum are
    not zero), the gradient of Σ|r|² through integrate_windows, by central differences, vanishes at the
    fitted gyro bias, and a step of 1e-4 rad/s along any axis raises the cost."""
    seq = _synthetic(seconds=12.0, seed=5)
    rng = np.random.default_rng(2)
    noisy = with_imu(seq, seq.gyro + np.array([0.03, -0.01, 0.02]) + rng.normal(0, 5e-3, seq.gyro.shape), seq.acc)
    g_hat, _ = fit_startup_bias(noisy, seconds=10.0, gravity=G)
    m = int(np.searchsorted(noisy.t_ns, noisy.t_ns[0] + 10 * 10**9)) + 1
    sub = il.Segment(noisy.name, noisy.t_ns[:m], noisy.gyro[:m], noisy.acc[:m], noisy.p[:m], noisy.v[:m], noisy.q_wxyz[:m])
    n = 200
    labels = il.window_labels(sub, n, n // 4, fractions=(1.0,), gravity=G)
    starts = np.asarray(labels.starts, dtype=np.uint64)

    def cost(b):
        inc = il.integrate_windows(with_imu(sub, sub.gyro - b, sub.acc), starts, np.array([n], dtype=np.uint64))
        r = quat_log(quat_mul(quat_conj(inc.dq_wxyz[:, 0]), labels.dq_wxyz[:, 0]))
        return float((r * r).sum())

    c0 = cost(g_hat)
    grad = np.array([(cost(g_hat + e) - cost(g_hat - e)) / 2e-7 for e in 1e-7 * np.eye(3)])
    scale = np.array([(cost(g_hat + e) - c0) / 1e-8 for e in 1e-4 * np.eye(3)])  # the curvature's size
    assert np.all(np.abs(grad) < 1e-5 * scale), (grad, scale)
    assert all(cost(g_hat + s * e) > c0 for e in 1e-4 * np.eye(3) for s in (-1, 1))


def test_window_increments_are_the_cores_window_by_window_integration():
    """relative_pose_errors composes each window from the recording's cumulative increments
    (score.metrics.window_increments); the core's integrate_windows runs the same sums window by window:
    they agree to round-off, on irregular stamps and a long recording (its cumulative γ reaches ~4 km)."""
    from imu_learn.core.integration import integrate_windows, preintegrate
    from imu_learn.score.metrics import window_increments

    t_ns, gyro, acc = _motion(seconds=30.0)
    rng = np.random.default_rng(3)
    t_ns = t_ns + rng.integers(-400_000, 400_000, size=len(t_ns))  # jittered stamps (±0.4 ms of 5 ms)
    seq = simulate_sequence(t_ns, gyro, acc, np.array([1.0, 0, 0, 0]), gravity=G)
    k = np.arange(7, len(seq) - 401, 37)
    for n in (1, 10, 400):
        want = integrate_windows(seq, k.astype(np.uint64), np.array([n], dtype=np.uint64))
        dq, dp, dt = window_increments(preintegrate(seq.t_ns, seq.gyro, seq.acc), k, k + n)
        assert np.allclose(dt, want.dt[:, 0], rtol=0, atol=1e-12)
        ang = 2 * np.arcsin(np.clip(np.linalg.norm(quat_mul(quat_conj(want.dq_wxyz[:, 0]), dq)[:, 1:], axis=1), 0, 1))
        assert ang.max() < 1e-10
        assert np.abs(dp - want.dp[:, 0]).max() < 1e-8 * max(1.0, np.abs(want.dp[:, 0]).max())
