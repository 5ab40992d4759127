"""The floor's fit in numpy (baselines/traditional.py, what ``imu-learn calibrate`` and evaluate's
``traditional`` / ``traditional+timing`` fit), against oracles it cannot see: a synthetic device
whose ground truth is the zero-order-hold integration of known rates (the core's ``preintegrate``)
and whose raw samples carry a known scale/misalignment, bias and g-sensitivity (the fit must give
them back); its exact Jacobians against central differences of its residuals on real windows; and
calibrate's modules and the fit with torch absent."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.traditional import (
    Traditional,
    TraditionalTiming,
    _Data,
    _gyro_model,
    _huber_weights,
    _RotResiduals,
    _solve,
    _VelResiduals,
    _weighted_normal,
)
from imu_learn.core.integration import preintegrate
from imu_learn.data.types import Segment
from test_layout import BLOCK_TORCH

REPO = Path(__file__).resolve().parents[1]
G = 9.81
SETTINGS = FitSettings(window=100, seed=0, gravity=G)
RNG = np.random.default_rng(7)
M_G = np.eye(3) + 0.01 * RNG.standard_normal((3, 3))
B_G = np.array([0.012, -0.021, 0.017])
G_SENS = 1e-3 * RNG.standard_normal((3, 3))
M_A = np.eye(3) + 0.01 * RNG.standard_normal((3, 3))
B_A = np.array([0.11, -0.07, 0.05])


def device(seconds: float = 40.0, rate: float = 200.0, start: float = 0.0, name: str = "synthetic") -> Segment:
    """True body rates and specific force (smooth, every axis moving), the ground truth their exact
    zero-order-hold integration (q0 = I, v0 = p0 = 0, gravity G along -z), and raw samples that the
    floor's model maps back onto them: gyro = M_g⁻¹ (ω + G a_raw) + b_g, acc = M_a⁻¹ f + b_a."""
    n = int(seconds * rate)
    t_ns = 10**15 + np.round((start + np.arange(n) / rate) * 1e9).astype(np.int64)
    t = start + np.arange(n) / rate
    omega = np.stack([0.6 * np.sin(0.9 * t), 0.5 * np.cos(0.7 * t + 1.0), 0.3 + 0.5 * np.sin(0.5 * t + 0.3)], 1)
    f = np.stack([2.0 * np.sin(0.6 * t), 1.5 * np.cos(0.8 * t + 0.4), G + 1.2 * np.sin(1.1 * t)], 1)
    inc = preintegrate(t_ns, omega, f)
    T = ((t_ns - t_ns[0]) * 1e-9)[:, None]
    gz = np.array([0.0, 0.0, G])
    v = inc.dv - gz * T
    p = inc.dp - 0.5 * gz * T**2
    acc = f @ np.linalg.inv(M_A).T + B_A
    gyro = (omega + acc @ G_SENS.T) @ np.linalg.inv(M_G).T + B_G
    return Segment(name, t_ns, gyro, acc, p, v, inc.dq_wxyz)


def test_the_synthetic_ground_truth_is_the_floors_integration():
    """The oracle's own check: with the true model applied, the floor's residuals vanish."""
    d = _Data([device(10.0)], 100, 50, G)
    w = d.windows(None, None)
    theta_g = np.concatenate([(M_G - np.eye(3)).ravel(), B_G, G_SENS.ravel()])
    assert np.abs(_RotResiduals(w)(theta_g)).max() < 1e-12
    theta_a = np.concatenate([(M_A - np.eye(3)).ravel(), B_A])
    assert np.abs(_VelResiduals(_gyro_model(theta_g, w.gyro, w.acc_g), w)(theta_a)).max() < 1e-9
    assert np.abs(_RotResiduals(w)(np.zeros(21))).max() > 1e-3  # the raw samples are off


def test_recovers_a_known_device():
    """Scale/misalignment, biases and g-sensitivity of both sensors come back (the weak prior on M - I
    and G moves them by less than 1e-7 here); traditional+timing finds no time offset (there is none)."""
    train, val = device(40.0), device(10.0, start=40.0, name="val")
    for m in (Traditional(cutoffs_hz=(None,), max_windows=300), TraditionalTiming(cutoffs_hz=(None, 20.0), max_windows=300)):
        log = m.fit([train], [val], SETTINGS)
        p = m.params
        np.testing.assert_allclose(p.M_g, M_G, atol=1e-7)
        np.testing.assert_allclose(p.b_g, B_G, atol=1e-7)
        np.testing.assert_allclose(p.G, G_SENS, atol=1e-7)
        np.testing.assert_allclose(p.M_a, M_A, atol=1e-7)
        np.testing.assert_allclose(p.b_a, B_A, atol=1e-6)
        assert p.cutoff_gyro is None and p.cutoff_acc is None  # no filter beats the exact samples
        assert log["gyro_loss"][1] < 1e-6 * log["gyro_loss"][0] and log["acc_loss"][1] < 1e-5 * log["acc_loss"][0]
        assert abs(p.time_offset) < 0.01


def test_refit_from_a_fit_recovers_the_device_on_a_part():
    """refit (calibrate's per-recording uncertainty): from another fit's parameters on a part of the
    data, the same device (no time offset here: on these raw samples the offset search is pulled by
    the device's large bias, the reason the timing baseline's windows are short)."""
    start = Traditional(cutoffs_hz=(None,), max_windows=300)
    start.fit([device(40.0)], [], SETTINGS)
    start.params.b_g = start.params.b_g + 0.01  # a start the part must move away from
    start.params.M_a = start.params.M_a + 0.005
    m = Traditional(max_windows=200)
    m.refit([device(15.0, start=40.0)], [], start.params, SETTINGS)
    np.testing.assert_allclose(m.params.M_g, M_G, atol=1e-6)  # the weak prior weighs more on 15 s: 2.5e-7
    np.testing.assert_allclose(m.params.b_g, B_G, atol=1e-6)
    np.testing.assert_allclose(m.params.M_a, M_A, atol=1e-6)
    np.testing.assert_allclose(m.params.b_a, B_A, atol=1e-5)


def test_refit_on_the_fits_own_data_is_the_fit(crop_split):
    """A refit on the same data from the fit's parameters and cutoffs: its time offset from the
    bracketed search is the full grid search's, and the affine parameters are the fit's."""
    tr, _ = crop_split
    fit = TraditionalTiming(cutoffs_hz=(None,), max_windows=150)
    fit.fit([tr], [], SETTINGS)
    m = TraditionalTiming(max_windows=150)
    m.refit([tr], [], fit.params, SETTINGS)
    assert abs(m.params.time_offset - fit.params.time_offset) < 2e-3
    np.testing.assert_allclose(m.params.b_g, fit.params.b_g, atol=2e-5)
    np.testing.assert_allclose(m.params.M_g, fit.params.M_g, atol=2e-4)
    np.testing.assert_allclose(m.params.b_a, fit.params.b_a, atol=2e-3)


def central(res, theta: np.ndarray, h: float) -> np.ndarray:
    cols = []
    for i in range(len(theta)):
        e = np.zeros_like(theta)
        e[i] = h
        cols.append((res(theta + e) - res(theta - e)) / (2 * h))
    return np.stack(cols, 1)


def test_jacobians_match_central_differences(crop_split):
    """Both stages' analytic Jacobians on real windows (filtered, at a θ away from the identity)."""
    d = _Data([crop_split[0]], 100, 40, G)
    w = d.windows(20.0, 10.0)
    rng = np.random.default_rng(3)
    theta_g = np.concatenate([0.01 * rng.standard_normal(9), 0.02 * rng.standard_normal(3), 1e-3 * rng.standard_normal(9)])
    rot = _RotResiduals(w)
    r = rot(theta_g)
    J, Jn = rot.jacobian(theta_g, r), central(rot, theta_g, 1e-6)
    assert np.abs(J - Jn).max() < 1e-7 * np.abs(Jn).max()
    vel = _VelResiduals(_gyro_model(theta_g, w.gyro, w.acc_g), w)
    theta_a = np.concatenate([0.01 * rng.standard_normal(9), 0.1 * rng.standard_normal(3)])
    J, Jn = vel.jacobian(theta_a, vel(theta_a)), central(vel, theta_a, 1e-5)
    assert np.abs(J - Jn).max() < 1e-8 * np.abs(Jn).max()




def test_calibrates_modules_and_the_fit_run_without_torch():
    """calibrate's modules import, and the floor fits, with torch blocked."""
    code = BLOCK_TORCH + (
        "import imu_learn.cli.calibrate, imu_learn.calib.run, imu_learn.calib.fit, imu_learn.calib.select\n"
        "sys.path.insert(0, 'tests')\n"
        "from test_floor_numpy import device, SETTINGS, M_G\n"
        "from imu_learn.baselines.traditional import Traditional\n"
        "import numpy as np\n"
        "m = Traditional(cutoffs_hz=(None,), max_windows=300)\n"
        "m.fit([device(40.0)], [], SETTINGS)\n"
        "assert np.abs(m.params.M_g - M_G).max() < 1e-7 and 'torch' not in sys.modules\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=str(REPO))
    assert r.returncode == 0, r.stderr[-2000:]


@pytest.mark.parametrize("fs,fc", [(200.0, 5.0), (200.0, 20.0), (200.0, 40.0), (200.0, 90.0), (30.0, 5.0), (285.7, 20.0),
                                   (1000.0, 5.0)])
def test_the_order_2_lowpass_is_scipys(fs, fc):
    """affine's numpy Butterworth (the floor's order 2) against scipy.signal's butter and sosfiltfilt
    (the oracle), on a drifting noisy signal with a large offset, and on one just longer than the padding."""
    from scipy.signal import butter, sosfiltfilt

    from imu_learn.baselines.affine import butter2, lowpass

    sos = butter(2, fc, btype="low", fs=fs, output="sos")
    np.testing.assert_allclose(butter2(fc, fs), sos, rtol=1e-14, atol=1e-15)
    rng = np.random.default_rng(int(fs + fc))
    x = np.cumsum(rng.normal(size=(20000, 3)), 0) * 0.01 + [0.1, -0.2, 9.81] + rng.normal(size=(20000, 3))
    y = lowpass(x, fs, fc)
    assert np.abs(y - sosfiltfilt(sos, x, axis=0)).max() < 1e-12 * np.abs(x).max()
    short = x[:10]
    assert np.abs(lowpass(short, fs, fc) - sosfiltfilt(sos, short, axis=0)).max() < 1e-12 * np.abs(short).max()
    np.testing.assert_array_equal(lowpass(x[:9], fs, fc), x[:9])  # too short for the padding: unchanged


def test_a_jacobians_columns_alone_are_its_full_columns(crop_split):
    """A level's fit asks for its columns only (the bias: 3 of 21): they equal the full Jacobian's."""
    d = _Data([crop_split[0]], 100, 40, G)
    w = d.windows(None, None)
    rng = np.random.default_rng(4)
    theta = np.concatenate([0.01 * rng.standard_normal(9), 0.02 * rng.standard_normal(3), 1e-3 * rng.standard_normal(9)])
    rot = _RotResiduals(w)
    r = rot(theta)
    full = rot.jacobian(theta, r)
    for cols in ([9, 10, 11], [0, 4, 8, 9, 10, 11], list(range(12)), [12, 15, 20], [3, 13]):
        np.testing.assert_allclose(rot.jacobian(theta, r, np.asarray(cols)), full[:, cols], rtol=1e-12, atol=1e-15)


def test_the_accelerometers_normal_equations_are_its_jacobians(crop_split):
    """The accelerometer stage's Jᵀ W J and Jᵀ W r from Φ's Gram matrix (the rows Huber takes down
    subtracted; or summed directly where many are) equal those of its exact Jacobian, for every
    column subset a level frees."""
    d = _Data([crop_split[0]], 100, 40, G)
    w = d.windows(None, None)
    rng = np.random.default_rng(5)
    res = _VelResiduals(_gyro_model(np.zeros(21), w.gyro, w.acc_g), d.windows(None, 10.0))
    theta = np.concatenate([0.01 * rng.standard_normal(9), 0.05 * rng.standard_normal(3)])
    r = res(theta)
    for delta in (np.inf, float(np.median(np.abs(r))) * 3, float(np.median(np.abs(r))) * 0.5):  # none, few, most down
        wts = _huber_weights(r, delta)
        for cols in (None, np.array([9, 10, 11]), np.array([0, 4, 8, 9, 10, 11]), np.arange(12)):
            A, g = res.normal(theta, r, wts, cols)
            A_j, g_j = _weighted_normal(res.jacobian(theta, r, cols), r, wts)
            np.testing.assert_allclose(A, A_j, rtol=1e-9, atol=1e-12 * np.abs(A_j).max())
            np.testing.assert_allclose(g, g_j, rtol=1e-9, atol=1e-12 * np.abs(g_j).max())


@pytest.mark.parametrize("stage", ["rotation", "velocity"])
def test_a_solve_stops_within_its_tolerance_of_the_minimum(crop_split, stage):
    """The solve's stopping rule (a step not taken where the model predicts a decrease under tol of the
    cost): its cost is within tol of the cost a solve run to 1e-15 reaches."""
    d = _Data([crop_split[0]], 100, 60, G)
    w = d.windows(None, None)
    if stage == "rotation":
        res, x0, prior_idx, delta, tol = _RotResiduals(w), np.zeros(21), np.r_[0:9, 12:21], 0.01, 1e-8
    else:
        res = _VelResiduals(_gyro_model(np.zeros(21), w.gyro, w.acc_g), w)
        x0, prior_idx, delta, tol = np.zeros(12), np.r_[0:9], 0.1, 1e-8

    def cost(x):
        r = res(x).reshape(-1, 3)
        n = np.sqrt((r * r).sum(-1))
        return float(np.where(n <= delta, 0.5 * n * n, delta * (n - 0.5 * delta)).sum()
                     + 0.5 * 1e-6 * (x[prior_idx] ** 2).sum())

    x = _solve(res, x0, prior_idx, 1e-3, delta, 50, tol)
    best = _solve(res, x0, prior_idx, 1e-3, delta, 200, 1e-15)
    assert cost(best) <= cost(x) <= cost(best) * (1 + 10 * tol)
    assert cost(x) < 0.5 * cost(x0)  # it solved something
