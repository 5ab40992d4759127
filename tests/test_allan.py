"""Overlapping Allan deviation (imu_learn.core.allan, in Rust) against the overlapping formula
written out in numpy, against allantools where it is installed, and its slope fits against noise
of known strength: white noise of density sigma has adev = sigma / sqrt(tau), a rate random walk
of strength K has adev = K sqrt(tau / 3)."""
from __future__ import annotations

import numpy as np
import pytest

from imu_learn.core.allan import (
    BIAS_INSTABILITY_FACTOR,
    allan_deviation,
    fit_noise,
    imu_allan_deviation,
)
from imu_learn.data.types import ImuData
from imu_learn.errors import InvalidInputError

PERIOD = 0.01  # 100 Hz


def direct_oadev(y: np.ndarray, m: int) -> float:
    """The overlapping Allan deviation by its definition: half the mean squared difference of
    adjacent cluster means, over every start (N - 2m + 1 of them)."""
    means = np.convolve(y, np.ones(m) / m, mode="valid")  # means[k] = mean(y[k:k+m])
    d = means[m:] - means[:-m]
    return float(np.sqrt(0.5 * np.mean(d**2)))


def noise(n: int, sigma: float, k: float, seed: int) -> np.ndarray:
    """White noise of density sigma [unit sqrt(s)] plus a rate random walk of strength k [unit/sqrt(s)]
    plus an offset (which the deviation ignores)."""
    rng = np.random.default_rng(seed)
    white = sigma / np.sqrt(PERIOD) * rng.standard_normal(n)
    walk = np.cumsum(k * np.sqrt(PERIOD) * rng.standard_normal(n))
    return white + walk + 9.81


def test_matches_the_overlapping_formula_written_out():
    rng = np.random.default_rng(3)
    y = rng.standard_normal((3001, 3)) * [1.0, 0.01, 5.0] + [0.0, 0.3, -9.8]
    y[:, 2] += np.cumsum(rng.standard_normal(3001)) * 0.05
    dev = allan_deviation(y, PERIOD, m=np.arange(1, 1501))
    assert dev.adev.shape == (1500, 3)
    for j, m in enumerate(dev.m):
        for axis in range(3):
            want = direct_oadev(y[:, axis], int(m))
            assert dev.adev[j, axis] == pytest.approx(want, rel=1e-9), (m, axis)
    np.testing.assert_array_equal(dev.n_clusters, 3001 // dev.m)
    np.testing.assert_allclose(dev.tau_s, dev.m * PERIOD)
    np.testing.assert_allclose(dev.rel_err, 1 / np.sqrt(2 * (3001 / dev.m - 1)))


def test_default_cluster_sizes_are_log_spaced_from_one_to_half():
    dev = allan_deviation(np.random.default_rng(0).standard_normal(10_000), PERIOD)
    m = dev.m.astype(int)
    assert m[0] == 1 and m[-1] == 5000 and np.all(np.diff(m) > 0)
    # 20 per decade where the integers allow it.
    assert 20 * np.log10(5000) - 10 <= len(m) <= 20 * np.log10(5000) + 2


def test_matches_allantools():
    allantools = pytest.importorskip("allantools")
    y = noise(20_000, 1e-3, 1e-4, seed=5)
    dev = allan_deviation(y, PERIOD)
    taus, adev, _, _ = allantools.oadev(y, rate=1 / PERIOD, data_type="freq", taus=dev.tau_s)
    # allantools stops one short of m = N/2 (a single difference); every other tau is the same.
    n = len(taus)
    assert n >= len(dev.tau_s) - 1
    np.testing.assert_allclose(taus, dev.tau_s[:n])
    np.testing.assert_allclose(dev.adev[:n, 0], adev, rtol=1e-9)


def test_white_noise_density_is_read_at_one_second():
    sigma = 2e-3
    dev = allan_deviation(noise(500_000, sigma, 0.0, seed=1), PERIOD)
    good = dev.rel_err < 0.1
    ratio = dev.adev[good, 0] / (sigma / np.sqrt(dev.tau_s[good]))
    assert np.all(np.abs(ratio - 1) < 3 * dev.rel_err[good])
    fit = fit_noise(dev)
    assert fit.white.value[0] == pytest.approx(sigma, rel=0.03)
    assert fit.white.tau_lo[0] == pytest.approx(PERIOD)
    assert not fit.random_walk.found[0]
    assert not fit.bias_observed[0]  # still falling at the longest usable tau


def test_random_walk_is_read_at_three_seconds():
    k = 1e-4
    dev = allan_deviation(noise(1_000_000, 0.0, k, seed=2), PERIOD)
    fit = fit_noise(dev)
    assert fit.random_walk.value[0] == pytest.approx(k, rel=0.25)
    assert not fit.white.found[0]


@pytest.mark.parametrize("seed", [7, 8, 9])
def test_white_noise_plus_random_walk_recovers_both(seed):
    sigma, k = 1e-3, 1e-4  # crossover sqrt(3) sigma / K = 17 s
    y = noise(2_000_000, sigma, k, seed)
    dev = allan_deviation(np.column_stack([y, 3 * y]), PERIOD)
    fit = fit_noise(dev)
    np.testing.assert_allclose(fit.white.value, [sigma, 3 * sigma], rtol=0.05)
    np.testing.assert_allclose(fit.random_walk.value, [k, 3 * k], rtol=0.25)
    assert np.all(fit.white.tau_hi < 10) and np.all(fit.random_walk.tau_lo > 30)
    # B from the minimum near the crossover, where the two lines add in quadrature.
    assert np.all(fit.bias_observed) and np.all((fit.tau_bias > 3) & (fit.tau_bias < 100))
    j = np.argmin(dev.adev[:, 0])
    assert fit.bias_instability[0] == pytest.approx(dev.adev[j, 0] / BIAS_INSTABILITY_FACTOR)


def test_imu_samples_give_six_axes_at_the_median_period():
    rng = np.random.default_rng(4)
    n = 5000
    t = np.arange(n, dtype=np.int64) * 5_000_000  # 200 Hz
    imu = ImuData(t, rng.standard_normal((n, 3)), rng.standard_normal((n, 3)))
    dev = imu_allan_deviation(imu)
    assert dev.adev.shape[1] == 6 and dev.period_s == pytest.approx(0.005)
    fit = fit_noise(dev)
    assert fit.white.value.shape == (6,)
    # Unit white noise of period 5 ms: density sqrt(0.005).
    np.testing.assert_allclose(fit.white.value, np.sqrt(0.005), rtol=0.1)


@pytest.mark.parametrize(
    "samples, period, m",
    [
        (np.zeros(100), 0.0, None),
        (np.zeros(100), 0.01, np.array([0], dtype=np.uint64)),
        (np.zeros(100), 0.01, np.array([51], dtype=np.uint64)),
        (np.zeros(100), 0.01, np.array([3, 2], dtype=np.uint64)),
        (np.array([0.0, np.nan, 1.0, 2.0]), 0.01, None),
        (np.zeros(1), 0.01, None),
    ],
)
def test_bad_inputs_are_invalid_input(samples, period, m):
    with pytest.raises(InvalidInputError):
        allan_deviation(samples, period, m=m)
