"""Overlapping Allan deviation of IMU rate samples and the standard slope fits of their noise,
computed in Rust (:mod:`imu_learn._imu_core`; ``crates/imu_core/src/allan.rs`` has the formulas).

* :func:`allan_deviation`: σ(τ) per axis at log-spaced cluster sizes m = 1 … N/2 (20 per decade
  by default), with the number of clusters N // m and the approximate relative error
  1 / sqrt(2 (N/m − 1)) of each point. O(N) per τ (cumulative sums), the GIL released.
* :func:`fit_noise`: per axis, the white noise density N (the −1/2 slope line at τ = 1 s; for a
  gyro the angle random walk in rad/s/√Hz, for an accelerometer the velocity random walk in
  m/s²/√Hz), the rate random walk K (the +1/2 line at τ = 3 s; rad/s²/√Hz, m/s³/√Hz) and the bias
  instability B (the minimum / 0.664). Each line is fitted over the longest run of points whose
  local log-log slope (least squares over ±0.1 decade) is within ±0.1 of the nominal one, among
  points with a relative error of at most 0.3; its uncertainty is the smallest relative error of a
  point in the run. A line with no such run is NaN.

Samples must be evenly spaced (the period is one number); a recording with gaps should be cut at
them first. Errors: inconsistent inputs raise :class:`imu_learn.errors.InvalidInputError`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.core.integration import ImuArrays
from imu_learn.core.stamps import median_period_ns

DEFAULT_PER_DECADE = 20
BIAS_INSTABILITY_FACTOR = 0.6642829925998278  # sqrt(2 ln 2 / pi)


@dataclass(frozen=True)
class AllanDeviation:
    """σ(τ) of k axes at T cluster sizes; ``adev`` is (T, k)."""

    tau_s: np.ndarray  # (T,) float64 [s]
    m: np.ndarray  # (T,) uint64 samples per cluster
    n_clusters: np.ndarray  # (T,) uint64, N // m
    rel_err: np.ndarray  # (T,) float64, 1/sqrt(2 (N/m - 1))
    adev: np.ndarray  # (T, k) float64, in the samples' unit
    period_s: float
    n_samples: int


@dataclass(frozen=True)
class LineFit:
    """One coefficient per axis read off a line of fixed slope (NaN where the curve has no region)."""

    value: np.ndarray  # (k,) the line at its reference τ
    rel_err: np.ndarray  # (k,)
    tau_lo: np.ndarray  # (k,) [s] the region fitted
    tau_hi: np.ndarray  # (k,)
    points: np.ndarray  # (k,) uint64

    @property
    def found(self) -> np.ndarray:
        return self.points > 0


@dataclass(frozen=True)
class NoiseFit:
    """The noise of each axis from its Allan deviation."""

    white: LineFit  # white noise density N [unit sqrt(s)] = [unit/sqrt(Hz)], at tau = 1 s
    random_walk: LineFit  # rate random walk K [unit/sqrt(s)], at tau = 3 s
    bias_instability: np.ndarray  # (k,) B [unit] = min adev / 0.664
    tau_bias: np.ndarray  # (k,) [s] where the minimum is
    bias_rel_err: np.ndarray  # (k,)
    bias_observed: np.ndarray  # (k,) bool: False when the minimum is the last usable point (B an upper bound)


def allan_deviation(
    samples: np.ndarray, period_s: float, per_decade: int = DEFAULT_PER_DECADE, m: Optional[np.ndarray] = None
) -> AllanDeviation:
    """Overlapping Allan deviation of ``samples`` (N,) or (N, k) of period ``period_s``, at ``m``
    (increasing cluster sizes in 1..N/2) or ``per_decade`` log-spaced ones."""
    x = np.asarray(samples, dtype=np.float64)
    x = np.ascontiguousarray(x.reshape(len(x), -1) if x.ndim == 1 else x)
    mm = None if m is None else np.ascontiguousarray(m, dtype=np.uint64)
    d = core.allan_deviation(x, float(period_s), int(per_decade), mm)
    return AllanDeviation(d["tau_s"], d["m"], d["n_clusters"], d["rel_err"], d["adev"], float(period_s), len(x))


def imu_allan_deviation(imu: ImuArrays, per_decade: int = DEFAULT_PER_DECADE) -> AllanDeviation:
    """Allan deviation of an IMU's six axes (gyro x, y, z [rad/s], then acc x, y, z [m/s^2]) at the
    median sample period."""
    period_s = median_period_ns(imu.t_ns) * 1e-9
    return allan_deviation(np.hstack([imu.gyro, imu.acc]), period_s, per_decade)


def _line(d: dict) -> LineFit:
    return LineFit(d["value"], d["rel_err"], d["tau_lo"], d["tau_hi"], d["points"])


def fit_noise(dev: AllanDeviation) -> NoiseFit:
    """The standard slope fits (N, K, B) of each axis of ``dev``."""
    f = core.allan_fit(dev.tau_s, np.ascontiguousarray(dev.adev), dev.rel_err)
    return NoiseFit(
        _line(f["white"]),
        _line(f["random_walk"]),
        f["bias_instability"],
        f["tau_bias"],
        f["bias_rel_err"],
        f["bias_observed"],
    )
