"""The core's ``rotation_window_sums`` (what the floor's gyro fit, baselines/traditional.py
``_RotResiduals``, runs on) against the numpy reference (``core/numpy_reference.py``: exact
exponentials, a doubling scan of the products, J_r in closed form): the rotation products at each
horizon, and the sums Σ_{k<h} A_k ⊗ f_k its exact Jacobian is built from."""
from __future__ import annotations

import numpy as np
import pytest

from imu_learn import _imu_core as core
from imu_learn.baselines.traditional import _Windows
from imu_learn.core import numpy_reference as ref
from imu_learn.errors import InvalidInputError

B, W = 50, 40
HORIZONS = [8, 16, 24, 32, 40]


def windows(seed: int = 0) -> _Windows:
    """Random rates up to 3 rad/s (a few windows up to 30 rad/s, steps past the series' switch at
    0.1 rad), specific force around gravity, dt 5 ms with a little jitter."""
    rng = np.random.default_rng(seed)
    gyro = rng.uniform(-3.0, 3.0, (B, W, 3))
    gyro[:5] *= 10.0
    acc_g = rng.normal(0.0, 2.0, (B, W, 3)) + [0.0, 0.0, 9.81]
    dt = 0.005 * (1.0 + 0.01 * rng.uniform(-1.0, 1.0, (B, W)))
    H = len(HORIZONS)
    dq = np.zeros((B, H, 4))
    dq[..., 0] = 1.0
    zero = np.zeros((B, H, 3))
    return _Windows(gyro=gyro, acc_g=acc_g, acc=acc_g.copy(), dt=dt, dq=dq, dv=zero, dp=zero, horizons=HORIZONS)


def some_theta(seed: int) -> np.ndarray:
    """A small θ with every part nonzero: M_g − I, b_g, G."""
    rng = np.random.default_rng(100 + seed)
    return np.concatenate((0.01 * rng.standard_normal(9), 0.02 * rng.standard_normal(3),
                           1e-3 * rng.standard_normal(9)))


def call(w: _Windows, theta: np.ndarray, jacobian: bool, horizons=None) -> dict:
    hs = np.asarray(w.horizons if horizons is None else horizons, dtype=np.uint64)
    return core.rotation_window_sums(w.gyro, w.acc_g, w.dt, theta, hs, jacobian)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rotations_and_sums_match_numpy(seed):
    w = windows(seed)
    theta = np.zeros(21) if seed == 0 else some_theta(seed)
    q_np, s_np = ref.rotation_window_sums(w.gyro, w.acc_g, w.dt, theta, HORIZONS)
    out = call(w, theta, True)
    assert out["q_wxyz"].shape == (B, len(HORIZONS), 4)
    assert out["sums"].shape == (B, len(HORIZONS), 9, 7)
    np.testing.assert_allclose(out["q_wxyz"], q_np, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["sums"], s_np, rtol=0, atol=1e-12)
    plain = call(w, theta, False)
    assert plain["sums"] is None
    np.testing.assert_array_equal(plain["q_wxyz"], out["q_wxyz"])


def test_horizons_in_any_order_land_in_their_own_slots():
    w, theta = windows(3), some_theta(3)
    out = call(w, theta, True)
    order = [4, 0, 2, 0]
    shuffled = call(w, theta, True, [HORIZONS[j] for j in order])
    np.testing.assert_array_equal(shuffled["q_wxyz"], out["q_wxyz"][:, order])
    np.testing.assert_array_equal(shuffled["sums"], out["sums"][:, order])


def _bad(w: _Windows) -> dict:
    theta = some_theta(0)
    nan = theta.copy()
    nan[4] = np.nan
    return {
        "horizon 0": (w.gyro, w.acc_g, w.dt, theta, np.array([0], np.uint64)),
        "horizon past W": (w.gyro, w.acc_g, w.dt, theta, np.array([8, W + 1], np.uint64)),
        "no horizons": (w.gyro, w.acc_g, w.dt, theta, np.array([], np.uint64)),
        "negative horizon": (w.gyro, w.acc_g, w.dt, theta, np.array([-1], np.int64)),
        "NaN theta": (w.gyro, w.acc_g, w.dt, nan, np.array([8], np.uint64)),
        "short theta": (w.gyro, w.acc_g, w.dt, theta[:20], np.array([8], np.uint64)),
        "dt shape": (w.gyro, w.acc_g, w.dt[:, 1:], theta, np.array([8], np.uint64)),
        "acc_g shape": (w.gyro, w.acc_g[1:], w.dt, theta, np.array([8], np.uint64)),
        "gyro columns": (w.gyro[..., :2].copy(), w.acc_g, w.dt, theta, np.array([8], np.uint64)),
        "gyro not contiguous": (w.gyro[:, ::2], w.acc_g[:, ::2], w.dt[:, ::2], theta, np.array([8], np.uint64)),
        "gyro Fortran order": (np.asfortranarray(w.gyro), w.acc_g, w.dt, theta, np.array([8], np.uint64)),
        "dt Fortran order": (w.gyro, w.acc_g, np.asfortranarray(w.dt), theta, np.array([8], np.uint64)),
    }


@pytest.mark.parametrize("case", list(_bad(windows())))
def test_bad_inputs_raise_invalid_input(case):
    args = _bad(windows())[case]
    with pytest.raises(InvalidInputError):
        core.rotation_window_sums(*args, True)
