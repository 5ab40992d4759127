"""The core's ``velocity_window_sums`` (the sums the floor's accelerometer fit, baselines/traditional.py
``_VelResiduals``, is built from) against the numpy reference (``core/numpy_reference.py``: the
rotation held over each sample from a doubling scan of exact exponentials, its cumulative sums)."""
from __future__ import annotations

import numpy as np
import pytest

from imu_learn import _imu_core as core
from imu_learn.core import numpy_reference as ref
from imu_learn.errors import InvalidInputError

B, W = 50, 40
HORIZONS = [8, 16, 24, 32, 40]


def windows(seed: int = 0):
    """Random rates up to 3 rad/s (a few windows up to 30 rad/s, steps past the series' switch at
    0.1 rad), specific force around gravity, dt 5 ms with a little jitter: (rates, acc, dt)."""
    rng = np.random.default_rng(seed)
    rates = rng.uniform(-3.0, 3.0, (B, W, 3))
    rates[:5] *= 10.0
    acc = rng.normal(0.0, 2.0, (B, W, 3)) + [0.0, 0.0, 9.81]
    dt = 0.005 * (1.0 + 0.01 * rng.uniform(-1.0, 1.0, (B, W)))
    return rates, acc, dt


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sums_match_numpy(seed):
    rates, acc, dt = windows(seed)
    out = core.velocity_window_sums(rates, acc, dt, np.asarray(HORIZONS, dtype=np.uint64))
    assert out.shape == (B, len(HORIZONS), 9, 8) and out.dtype == np.float64
    assert out.flags.c_contiguous
    np.testing.assert_allclose(out, ref.velocity_window_sums(rates, acc, dt, HORIZONS), rtol=0, atol=1e-12)


def test_zero_rates_are_plain_sums_on_the_identity_rows():
    _, acc, dt = windows(4)
    out = core.velocity_window_sums(np.zeros_like(acc), acc, dt, HORIZONS)
    T = np.cumsum(dt, axis=1)
    s = (T - 0.5 * dt)[..., None]
    f = np.concatenate((acc, np.ones_like(s)), axis=-1)
    cols = np.cumsum(dt[..., None] * np.concatenate((f, s * f), axis=-1), axis=1)[:, [h - 1 for h in HORIZONS]]
    eye = np.eye(3).reshape(9)
    np.testing.assert_allclose(out, eye[None, None, :, None] * cols[:, :, None, :], rtol=0, atol=1e-13)


def test_horizons_in_any_order_land_in_their_own_slots():
    rates, acc, dt = windows(3)
    out = core.velocity_window_sums(rates, acc, dt, HORIZONS)
    order = [4, 0, 2, 0]
    shuffled = core.velocity_window_sums(rates, acc, dt, [HORIZONS[j] for j in order])
    np.testing.assert_array_equal(shuffled, out[:, order])


def test_no_windows_give_an_empty_array():
    out = core.velocity_window_sums(np.zeros((0, W, 3)), np.zeros((0, W, 3)), np.zeros((0, W)), [W])
    assert out.shape == (0, 1, 9, 8)


def _bad() -> dict:
    rates, acc, dt = windows()
    h = np.array([8], np.uint64)
    return {
        "horizon 0": (rates, acc, dt, np.array([0], np.uint64)),
        "horizon past W": (rates, acc, dt, np.array([8, W + 1], np.uint64)),
        "no horizons": (rates, acc, dt, np.array([], np.uint64)),
        "negative horizon": (rates, acc, dt, np.array([-1], np.int64)),
        "negative horizon in a list": (rates, acc, dt, [8, -3]),
        "dt shape": (rates, acc, dt[:, 1:], h),
        "acc shape": (rates, acc[1:], dt, h),
        "acc columns": (rates, acc[..., :2].copy(), dt, h),
        "rates columns": (rates[..., :2].copy(), acc, dt, h),
        "rates not contiguous": (rates[:, ::2], acc[:, ::2], dt[:, ::2], h),
        "rates Fortran order": (np.asfortranarray(rates), acc, dt, h),
        "acc Fortran order": (rates, np.asfortranarray(acc), dt, h),
        "dt Fortran order": (rates, acc, np.asfortranarray(dt), h),
    }


@pytest.mark.parametrize("case", list(_bad()))
def test_bad_inputs_raise_invalid_input(case):
    with pytest.raises(InvalidInputError):
        core.velocity_window_sums(*_bad()[case])
