"""The Rust covariance (imu_learn.core.covariance) against the torch closed form on real EuRoC IMU data,
against GTSAM, and its typed errors."""
import numpy as np
import pytest
import torch

import imu_learn as il
from imu_learn import _imu_core as core
from imu_learn.core.covariance import increment_covariance, interval_covariances
from imu_learn.nn.covariance import increment_covariance as torch_increment_covariance
from imu_learn.nn.covariance import to_gtsam_manifold
from imu_learn.nn.integration import integrate

torch.set_num_threads(1)

N = 2001  # 10 s at 200 Hz


def rel_err(a, b):
    """max |a − b| scaled entry by entry by sqrt(b_ii b_jj) (a correlation-sized error)."""
    d = np.sqrt(np.clip(np.einsum("...ii->...i", b), 1e-300, None))
    return float((np.abs(a - b) / (d[..., :, None] * d[..., None, :])).max())


@pytest.fixture(scope="module")
def euroc(shipped):
    """10 s of the shipped EuRoC V1_01_easy crop, with per-sample variances that follow the motion
    (EuRoC's noise densities, larger when rotating or accelerating hard, times a random factor):
    they vary by more than 100× over the recording."""
    imu = il.read_imu(shipped / "euroc" / "V1_01_easy")
    t, g, a = imu.t_ns[:N], imu.gyro[:N], imu.acc[:N]
    rng = np.random.default_rng(1)
    rate = np.linalg.norm(g, axis=1, keepdims=True)
    force = np.abs(np.linalg.norm(a, axis=1, keepdims=True) - 9.81)
    var = np.concatenate((
        1.7e-4 ** 2 * 200 * (1 + 30 * rate ** 2) * rng.uniform(0.3, 3.0, (N, 3)),
        2.0e-3 ** 2 * 200 * (1 + 10 * force ** 2) * rng.uniform(0.3, 3.0, (N, 3)),
    ), axis=1)
    return t, g, a, var


def torch_cov(t, g, a, var, horizons):
    dt = np.diff(t) * 1e-9
    args = [torch.from_numpy(np.ascontiguousarray(x[:len(dt)]))[None] for x in (g, a)]
    return torch_increment_covariance(args[0], args[1], torch.from_numpy(dt)[None],
                                      torch.from_numpy(np.ascontiguousarray(var[:len(dt)]))[None], horizons)[0].numpy()


def test_increment_covariance_matches_torch_on_euroc(euroc):
    """Rust vs torch, float64, on 10 s of real EuRoC data at five horizons (5 ms to 10 s): at most
    1e-9 relative (entry / sqrt(Σ_ii Σ_jj); measured ~1e-13)."""
    t, g, a, var = euroc
    hs = [1, 10, 200, 1000, N - 1]
    got = increment_covariance(t, g, a, var, hs)
    assert got.shape == (len(hs), 9, 9) and got.dtype == np.float64 and got.flags.c_contiguous
    np.testing.assert_array_equal(got, got.transpose(0, 2, 1))
    assert rel_err(got, torch_cov(t, g, a, var, hs)) <= 1e-9
    assert np.all(increment_covariance(t, g, a, var, [0]) == 0)


def test_interval_covariances_match_torch_from_each_start(euroc):
    """Each keyframe interval equals the torch covariance of the samples from its own start (at most
    1e-9 relative), and one interval from sample 0 equals increment_covariance exactly."""
    t, g, a, var = euroc
    bounds = [0, 137, 400, 401, 1500, N - 1]
    got = interval_covariances(t, g, a, var, bounds)
    assert got.shape == (len(bounds) - 1, 9, 9)
    worst = 0.0
    for i, (b0, b1) in enumerate(zip(bounds[:-1], bounds[1:])):
        want = torch_cov(t[b0:b1 + 1], g[b0:b1 + 1], a[b0:b1 + 1], var[b0:b1 + 1], [b1 - b0])[0]
        worst = max(worst, rel_err(got[i], want))
    assert worst <= 1e-9, worst
    np.testing.assert_array_equal(interval_covariances(t, g, a, var, [0, 1000]),
                                  increment_covariance(t, g, a, var, [1000]))
    assert interval_covariances(t, g, a, var, [5]).shape == (0, 9, 9)


def test_matches_gtsam_with_per_sample_noise(euroc):
    """Rust straight against GTSAM's manifold preintMeasCov with per-sample noise on 2 s of EuRoC:
    at most 1e-9 relative."""
    gtsam = pytest.importorskip("gtsam")
    t, g, a, var = euroc
    n = 400
    dt = np.diff(t[:n + 1]) * 1e-9
    params = gtsam.PreintegrationParams.MakeSharedU(9.81)
    params.setIntegrationCovariance(np.zeros((3, 3)))
    pim = gtsam.PreintegratedImuMeasurementsManifold(params, gtsam.imuBias.ConstantBias())
    for k in range(n):
        params.setGyroscopeCovariance(np.diag(var[k, :3] * dt[k]))
        params.setAccelerometerCovariance(np.diag(var[k, 3:] * dt[k]))
        pim.integrateMeasurement(a[k], g[k], dt[k])
    ours = torch.from_numpy(increment_covariance(t, g, a, var, [n]))
    dq = integrate(torch.from_numpy(g[None, :n]), torch.from_numpy(a[None, :n]), torch.from_numpy(dt[None]), [n]).dq_wxyz[0]
    assert rel_err(to_gtsam_manifold(ours, dq)[0].numpy(), pim.preintMeasCov()) <= 1e-9


def test_bad_inputs_raise_invalid_input_error():
    n = 6
    t = np.arange(n, dtype=np.int64) * 5_000_000
    z = np.zeros((n, 3))
    var = np.full((n, 6), 1e-4)
    for bad in (-1e-12, np.nan, np.inf):
        v = var.copy()
        v[3, 4] = bad
        with pytest.raises(il.InvalidInputError, match=r"var\[3\]\[4\]"):
            increment_covariance(t, z, z, v, [2])
        with pytest.raises(il.InvalidInputError, match=r"var\[3\]\[4\]"):
            interval_covariances(t, z, z, v, [0, 2])
    # Shapes: through the wrapper and straight into the binding (the Rust-side check).
    with pytest.raises(il.InvalidInputError, match=r"\(N, 6\)"):
        increment_covariance(t, z, z, var[:, :5], [2])
    with pytest.raises(il.InvalidInputError, match=r"\(N, 6\)"):
        core.increment_covariance(t, z, z, np.ascontiguousarray(var[:, :5]), np.array([2], dtype=np.uint64))
    with pytest.raises(il.InvalidInputError):
        increment_covariance(t, z, z, var.ravel(), [2])
    with pytest.raises(il.InvalidInputError, match="var has 5 rows"):
        increment_covariance(t, z, z, var[:5], [2])
    with pytest.raises(il.InvalidInputError, match="gyro has 5"):
        interval_covariances(t, z[:5], z, var, [0, 2])
    # Horizons and boundaries.
    with pytest.raises(il.InvalidInputError, match="horizon 6 is past the last stamp"):
        increment_covariance(t, z, z, var, [1, 6])
    with pytest.raises(il.InvalidInputError, match="non-negative"):
        increment_covariance(t, z, z, var, [-1])
    with pytest.raises(il.InvalidInputError, match="strictly increasing"):
        interval_covariances(t, z, z, var, [0, 3, 3])
    with pytest.raises(il.InvalidInputError, match="boundary 6"):
        interval_covariances(t, z, z, var, [0, 6])
    with pytest.raises(il.InvalidInputError, match="strictly increasing"):
        increment_covariance(t[::-1].copy(), z, z, var, [2])
    assert isinstance(il.InvalidInputError("x"), ValueError)
