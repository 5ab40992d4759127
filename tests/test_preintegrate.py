"""Preintegration against independent oracles: GTSAM's exact (manifold) preintegration and
closed-form motions."""
import numpy as np
import pytest

import imu_learn as il

gtsam = pytest.importorskip("gtsam")


def gtsam_manifold(t_ns, gyro, acc):
    """Cumulative deltas from gtsam.PreintegratedImuMeasurementsManifold, zero bias."""
    params = gtsam.PreintegrationParams.MakeSharedU(9.81)
    params.setAccelerometerCovariance(np.eye(3) * 1e-6)
    params.setGyroscopeCovariance(np.eye(3) * 1e-6)
    params.setIntegrationCovariance(np.eye(3) * 1e-8)
    pim = gtsam.PreintegratedImuMeasurementsManifold(params, gtsam.imuBias.ConstantBias())
    n = len(t_ns)
    R = np.zeros((n, 3, 3))
    dv = np.zeros((n, 3))
    dp = np.zeros((n, 3))
    R[0] = np.eye(3)
    dts = np.diff(t_ns) * 1e-9
    for i in range(n - 1):
        pim.integrateMeasurement(acc[i], gyro[i], dts[i])
        R[i + 1] = pim.deltaRij().matrix()
        dv[i + 1] = pim.deltaVij()
        dp[i + 1] = pim.deltaPij()
    return R, dv, dp


def quat_wxyz_to_matrix(q):
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def check_against_gtsam(t_ns, gyro, acc, tol=1e-9):
    inc = il.preintegrate(t_ns, gyro, acc)
    R, dv, dp = gtsam_manifold(t_ns, gyro, acc)
    np.testing.assert_allclose(quat_wxyz_to_matrix(inc.dq_wxyz), R, atol=tol, rtol=0)
    np.testing.assert_allclose(inc.dv, dv, atol=tol, rtol=0)
    np.testing.assert_allclose(inc.dp, dp, atol=tol, rtol=0)
    np.testing.assert_allclose(inc.dt, (t_ns - t_ns[0]) * 1e-9, atol=1e-15)


def test_matches_gtsam_manifold_on_random_input():
    rng = np.random.default_rng(7)
    n = 2000
    t_ns = np.cumsum(rng.integers(4_000_000, 6_000_000, n)).astype(np.int64)
    gyro = rng.normal(0, 1.5, (n, 3))
    acc = rng.normal(0, 5.0, (n, 3)) + [0, 0, 9.81]
    check_against_gtsam(t_ns, gyro, acc)


def test_matches_gtsam_manifold_on_10s_of_real_euroc(shipped):
    imu = il.read_imu(shipped / "euroc" / "V1_01_easy")
    n = 2001  # 10 s at 200 Hz
    check_against_gtsam(imu.t_ns[:n], imu.gyro[:n], imu.acc[:n])


def test_gtsam_tangent_preintegration_is_the_wrong_oracle(shipped):
    """GTSAM's default (tangent-space) class is first order: on 10 s of real data it is off by far
    more than 1e-9, which is why the tests above use the manifold class."""
    imu = il.read_imu(shipped / "euroc" / "V1_01_easy")
    n = 2001
    params = gtsam.PreintegrationParams.MakeSharedU(9.81)
    params.setAccelerometerCovariance(np.eye(3) * 1e-6)
    params.setGyroscopeCovariance(np.eye(3) * 1e-6)
    params.setIntegrationCovariance(np.eye(3) * 1e-8)
    pim = gtsam.PreintegratedImuMeasurementsTangent(params, gtsam.imuBias.ConstantBias())
    dts = np.diff(imu.t_ns[:n]) * 1e-9
    for i in range(n - 1):
        pim.integrateMeasurement(imu.acc[i], imu.gyro[i], dts[i])
    inc = il.preintegrate(imu.t_ns[:n], imu.gyro[:n], imu.acc[:n])
    assert np.abs(pim.deltaPij() - inc.dp[-1]).max() > 1e-6


def test_constant_rate_is_exact_rotation():
    n, dt = 1001, 0.005
    t_ns = (np.arange(n) * 5_000_000).astype(np.int64)
    w = np.array([0.3, -0.2, 0.9])
    inc = il.preintegrate(t_ns, np.tile(w, (n, 1)), np.zeros((n, 3)))
    T = (n - 1) * dt
    ang = np.linalg.norm(w) * T
    q = np.concatenate([[np.cos(ang / 2)], np.sin(ang / 2) * w / np.linalg.norm(w)])
    np.testing.assert_allclose(inc.dq_wxyz[-1], q, atol=1e-12)
    np.testing.assert_allclose(inc.dv[-1], 0, atol=0)


def test_constant_specific_force_without_rotation():
    n = 401
    t_ns = (np.arange(n) * 5_000_000).astype(np.int64)
    a = np.array([1.0, -2.0, 9.81])
    inc = il.preintegrate(t_ns, np.zeros((n, 3)), np.tile(a, (n, 1)))
    T = (n - 1) * 0.005
    np.testing.assert_allclose(inc.dv[-1], a * T, rtol=1e-12)
    np.testing.assert_allclose(inc.dp[-1], 0.5 * a * T * T, rtol=1e-12)


def test_row_zero_is_identity_and_empty_input_is_empty():
    t = np.array([0, 5_000_000], dtype=np.int64)
    inc = il.preintegrate(t, np.ones((2, 3)), np.ones((2, 3)))
    np.testing.assert_array_equal(inc.dq_wxyz[0], [1, 0, 0, 0])
    np.testing.assert_array_equal(inc.dp[0], 0)
    e = il.preintegrate(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    assert e.dq_wxyz.shape == (0, 4)
