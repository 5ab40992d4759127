"""The numpy reference of the core (imu_learn.core.numpy_reference: bench_core.py times the core
against it) against GTSAM and a plain loop.

GTSAM's ``PreintegratedImuMeasurementsManifold`` with zero bias is the definition of the scheme
(sample i held over [t_i, t_{i+1}); per sample dp += dv*dt + 1/2 R a dt^2, dv += R a dt,
R <- R Exp(w dt)); the reference has to agree with it to 1e-9 for the benchmark to be fair.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imu_learn.core import numpy_reference as nr

REPO = Path(__file__).resolve().parent.parent

gtsam = pytest.importorskip("gtsam")

EUROC_IMU = REPO / "datasets" / "euroc" / "V1_01_easy" / "mav0" / "imu0" / "data.csv"
TOL = 1e-9


def _gtsam_rows(t_ns, gyro, acc, gravity):
    """Run GTSAM sample by sample; rows 1..N-1 as (R (N-1,3,3), q xyzw->wxyz (N-1,4), dv, dp, dT)."""
    params = gtsam.PreintegrationParams.MakeSharedU(gravity)
    params.setGyroscopeCovariance(np.eye(3) * 1e-6)
    params.setAccelerometerCovariance(np.eye(3) * 1e-4)
    params.setIntegrationCovariance(np.eye(3) * 1e-8)
    pim = gtsam.PreintegratedImuMeasurementsManifold(params, gtsam.imuBias.ConstantBias())
    hold = np.diff(t_ns) * 1e-9
    rs, qs, vs, ps, ts = [], [], [], [], []
    for i in range(len(t_ns) - 1):
        pim.integrateMeasurement(acc[i], gyro[i], float(hold[i]))
        r = pim.deltaRij()
        rq = r.toQuaternion()
        rs.append(r.matrix())
        qs.append([rq.w(), rq.x(), rq.y(), rq.z()])
        vs.append(pim.deltaVij())
        ps.append(pim.deltaPij())
        ts.append(pim.deltaTij())
    return np.array(rs), np.array(qs), np.array(vs), np.array(ps), np.array(ts)


def _same_sign(q, ref):
    """q and -q are one rotation; flip q onto ref's hemisphere row by row."""
    s = np.sign(np.einsum("...i,...i->...", q, ref))
    return q * np.where(s == 0, 1.0, s)[..., None]


def _random_imu(n, seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.integers(2_000_000, 8_000_000, n)).astype(np.int64) + 1_403_715_274_302_142_976
    gyro = rng.normal(scale=1.5, size=(n, 3))
    acc = rng.normal(scale=4.0, size=(n, 3)) + [0.0, 0.0, 9.81]
    return t, gyro, acc


def _euroc(n):
    if not EUROC_IMU.exists():
        pytest.skip(f"{EUROC_IMU} not shipped")
    t = np.loadtxt(EUROC_IMU, delimiter=",", skiprows=1, usecols=0, dtype=np.int64, max_rows=n)
    x = np.loadtxt(EUROC_IMU, delimiter=",", skiprows=1, usecols=range(1, 7), max_rows=n)
    assert len(t) == n
    return t, np.ascontiguousarray(x[:, :3]), np.ascontiguousarray(x[:, 3:])


def _check_against_gtsam(t, gyro, acc, gravity, scan="doubling"):
    dq, dv, dp, dt = nr.preintegrate(t, gyro, acc, scan)
    r_g, q_g, v_g, p_g, t_g = _gtsam_rows(t, gyro, acc, gravity)
    np.testing.assert_array_equal(dq[0], [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(dv[0], 0.0)
    np.testing.assert_array_equal(dp[0], 0.0)
    np.testing.assert_allclose(nr.quat_to_matrix(dq[1:]), r_g, rtol=0, atol=TOL)
    np.testing.assert_allclose(_same_sign(dq[1:], q_g), q_g, rtol=0, atol=TOL)
    np.testing.assert_allclose(dv[1:], v_g, rtol=0, atol=TOL)
    np.testing.assert_allclose(dp[1:], p_g, rtol=0, atol=TOL)
    # GTSAM sums the hold times; the reference takes dt from the integer stamps.
    np.testing.assert_allclose(dt[1:], t_g, rtol=0, atol=TOL)


@pytest.mark.parametrize("scan", ["doubling", "blocked"])
@pytest.mark.parametrize("gravity", [9.81, 0.0])
@pytest.mark.parametrize("seed", [0, 1])
def test_preintegrate_matches_gtsam_random(seed, gravity, scan):
    _check_against_gtsam(*_random_imu(1500, seed), gravity, scan)


@pytest.mark.parametrize("scan", ["doubling", "blocked"])
def test_preintegrate_matches_gtsam_euroc(scan):
    _check_against_gtsam(*_euroc(2000), 9.81, scan)


def test_gtsam_order_of_updates():
    """GTSAM uses the rotation from before the sample for both dv and dp, and dp uses the old dv:
    moving the rotation update first, or updating dv before dp, is visibly different."""
    t, gyro, acc = _random_imu(300, 7)
    _, _, v_g, p_g, _ = _gtsam_rows(t, gyro, acc, 9.81)
    hold = np.diff(t) * 1e-9

    def run(rot_first, v_first):
        q, v, p = np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3)
        vs, ps = [], []
        for i, h in enumerate(hold):
            if rot_first:
                q = nr.quat_mul(q, nr.so3_exp(gyro[i] * h))
            a = nr.quat_rotate(q, acc[i])
            if v_first:
                v = v + a * h
                p = p + v * h + 0.5 * a * h * h
            else:
                p = p + v * h + 0.5 * a * h * h
                v = v + a * h
            if not rot_first:
                q = nr.quat_mul(q, nr.so3_exp(gyro[i] * h))
            vs.append(v)
            ps.append(p)
        return np.abs(np.array(vs) - v_g).max(), np.abs(np.array(ps) - p_g).max()

    ev, ep = run(False, False)
    assert ev < TOL and ep < TOL
    assert max(run(True, False)) > 1e-3
    assert run(False, True)[1] > 1e-3


@pytest.mark.parametrize("scan", ["doubling", "blocked"])
@pytest.mark.parametrize("n", [1, 2, 3, 16, 17, 33, 1024, 1025])
def test_scan_matches_loop(n, scan):
    t, gyro, acc = _random_imu(n, n)
    for a, b in zip(nr.preintegrate(t, gyro, acc, scan), nr.preintegrate_loop(t, gyro, acc)):
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-11)


@pytest.mark.parametrize("scan", ["doubling", "blocked"])
def test_scan_matches_loop_euroc(scan):
    t, gyro, acc = _euroc(2000)
    for a, b in zip(nr.preintegrate(t, gyro, acc, scan), nr.preintegrate_loop(t, gyro, acc)):
        np.testing.assert_allclose(a, b, rtol=0, atol=TOL)


def test_scans_batched_over_leading_axes():
    rng = np.random.default_rng(11)
    q = nr.so3_exp(rng.normal(size=(3, 5, 70, 3)))
    d, b = nr.quat_prefix_scan(q, "doubling"), nr.quat_prefix_scan(q, "blocked", block=8)
    np.testing.assert_allclose(d, b, rtol=0, atol=1e-13)
    np.testing.assert_allclose(d[1, 2], nr.quat_prefix_scan(q[1, 2]), rtol=0, atol=0)


def test_so3_exp_small_and_large_angles():
    rng = np.random.default_rng(3)
    axis = rng.normal(size=(50, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    for th in (0.0, 1e-9, 1e-5, 9.99e-5, 1e-4, 0.3, 3.0):
        phi = axis * th
        q = nr.so3_exp(phi)
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
        for i in range(5):
            r = gtsam.Rot3.Expmap(phi[i]).matrix()
            np.testing.assert_allclose(nr.quat_to_matrix(q[i]), r, atol=1e-14)


def _toy_sequence(n, seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.integers(4_000_000, 6_000_000, n)).astype(np.int64)
    q = nr.quat_prefix_scan(nr.so3_exp(rng.normal(scale=0.02, size=(n, 3))))
    p = np.cumsum(rng.normal(scale=0.01, size=(n, 3)), axis=0)
    v = rng.normal(size=(n, 3))
    gyro, acc = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    return t, gyro, acc, p, v, q


def test_window_labels_match_definition():
    t, _, _, p, v, q = _toy_sequence(260, 0)
    d = nr.window_labels(t, p, v, q, window=50, stride=3, fractions=(0.2, 0.5, 1.0), gravity=9.81)
    np.testing.assert_array_equal(d["horizons"], [10, 25, 50])
    np.testing.assert_array_equal(d["starts"], np.arange(0, 210, 3))
    g = np.array([0.0, 0.0, -9.81])
    for w, k in enumerate(d["starts"].astype(int)):
        rk_t = nr.quat_to_matrix(q[k]).T
        for h, n in enumerate(d["horizons"].astype(int)):
            j = k + n
            dt = (t[j] - t[k]) * 1e-9
            assert d["dt"][w, h] == dt
            np.testing.assert_allclose(d["dv"][w, h], rk_t @ (v[j] - v[k] - g * dt), atol=1e-12)
            np.testing.assert_allclose(d["dp"][w, h], rk_t @ (p[j] - p[k] - v[k] * dt - 0.5 * g * dt * dt), atol=1e-12)
            np.testing.assert_allclose(
                nr.quat_to_matrix(d["dq_wxyz"][w, h]), rk_t @ nr.quat_to_matrix(q[j]), atol=1e-12
            )


def test_make_batch_windows_and_augmentation():
    seqs = [_toy_sequence(400, 1), _toy_sequence(90, 2), _toy_sequence(300, 3)]
    ss = nr.SequenceSet(seqs)
    plain = ss.make_batch(80, 64, seed=5)
    assert plain["imu"].shape == (64, 80, 6) and plain["dq_wxyz"].shape == (64, 5, 4)
    assert set(plain["seq_index"].tolist()) <= {0, 1, 2}
    np.testing.assert_array_equal(plain["bias"], 0.0)
    for b in range(64):
        t, gyro, acc, p, v, q = seqs[plain["seq_index"][b]]
        k = int(plain["start"][b])
        assert k + 80 < len(t)
        np.testing.assert_array_equal(plain["imu"][b], np.hstack([gyro, acc])[k : k + 80])
        np.testing.assert_array_equal(plain["dt"][b], np.diff(t[k : k + 81]) * 1e-9)
        lab = nr.labels_at(t, p, v, q, np.array([k]), plain["horizons"].astype(np.int64), 9.81)
        np.testing.assert_array_equal(plain["dv"][b], lab["dv"][0])
    aug = ss.make_batch(80, 64, seed=5, gyro_noise_density=0.0, acc_noise_density=0.0, gyro_bias_max=0.1, acc_bias_max=0.5)
    np.testing.assert_array_equal(aug["start"], plain["start"])  # same stream for the starts
    np.testing.assert_allclose(aug["imu"] - plain["imu"], aug["bias"], atol=1e-12)
    assert np.all(np.abs(aug["bias"][..., :3]) <= 0.1) and np.all(np.abs(aug["bias"][..., 3:]) <= 0.5)
    assert np.all(aug["bias"] == aug["bias"][:, :1])  # constant per window without a walk
