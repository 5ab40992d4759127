"""Covariance of the preintegrated increments under per-sample IMU noise, computed in Rust (float64,
for inference: a keyframe factor graph, a filter). :mod:`imu_learn.nn.covariance` is the same
closed form in torch (batched, differentiable, for training); its docstring has the derivation.

Convention (that of :mod:`imu_learn.nn.covariance`):

* Noise: sample i's error is zero-mean white noise with the *discrete-time* per-axis variances
  ``var[i] = (σ²_gx, σ²_gy, σ²_gz, σ²_ax, σ²_ay, σ²_az)`` in (rad/s)² and (m/s²)², the variance of one
  sample. The continuous-time density a filter or GTSAM's ``PreintegrationParams`` expects is
  ``σ² dt`` (:func:`imu_learn.nn.covariance.continuous_covariance`).
* Error state (δθ, δβ, δγ), rows and columns in that order, all in the frame at the start of the
  integration: the true rotation increment is ``Exp(δθ) Δq̂`` (left perturbation, the frame of the
  residual ``Log(Δq_s Δq̂⁻¹)``), ``Δβ = Δβ̂ + δβ``, ``Δγ = Δγ̂ + δγ``. GTSAM's manifold
  ``preintMeasCov`` is the same covariance in its own coordinates
  (:func:`imu_learn.nn.covariance.to_gtsam_manifold` converts).
* Time: as :func:`imu_learn.core.integration.preintegrate`: stamps ``t_ns`` (int64 ns), sample i held
  over [t_i, t_{i+1}), so horizon n covers [t_0, t_n] with samples 0..n-1; the last sample is not
  held (its values and variances are still checked).

Errors: inconsistent inputs (lengths, shapes, non-finite or negative variances, horizons past the
end, boundaries out of range or not strictly increasing, bad stamps) raise
:class:`imu_learn.errors.InvalidInputError`.
"""
from __future__ import annotations

from typing import Sequence, Union

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.errors import InvalidInputError

Indices = Union[Sequence[int], np.ndarray]


def _rows(a: np.ndarray, name: str, k: int) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != k:
        raise InvalidInputError(f"{name} must have shape (N, {k}), got {a.shape}")
    return a


def _indices(x: Indices, name: str) -> np.ndarray:
    a = np.asarray(x)
    if a.ndim != 1 or (a.size and not np.issubdtype(a.dtype, np.integer)):
        raise InvalidInputError(f"{name} must be a 1-d sequence of integers, got {a.dtype} {a.shape}")
    if a.size and a.min() < 0:
        raise InvalidInputError(f"{name} must be non-negative, got {int(a.min())}")
    return np.ascontiguousarray(a, dtype=np.uint64)


def _inputs(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, var: np.ndarray) -> tuple:
    t = np.ascontiguousarray(t_ns, dtype=np.int64)
    if t.ndim != 1:
        raise InvalidInputError(f"t_ns must be 1-d, got shape {t.shape}")
    return t, _rows(gyro, "gyro", 3), _rows(acc, "acc", 3), _rows(var, "var", 6)


def increment_covariance(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, var: np.ndarray,
                         horizons: Indices) -> np.ndarray:
    """(H, 9, 9) covariance of (δθ, δβ, δγ) after integrating from sample 0 over each of ``horizons``
    intervals (the rows of :func:`imu_learn.core.integration.preintegrate`; horizon 0 gives zeros).

    t_ns (N,); gyro, acc (N, 3); var (N, 6) per-sample discrete-time variances, gyro then acc;
    horizons: integers in 0..N-1, any order, repeats allowed.
    """
    return core.increment_covariance(*_inputs(t_ns, gyro, acc, var), _indices(horizons, "horizons"))


def interval_covariances(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, var: np.ndarray,
                         boundaries: Indices) -> np.ndarray:
    """(M - 1, 9, 9): for strictly increasing sample indices ``boundaries`` b_0 < ... < b_{M-1}
    (each below N), the covariance of each interval [t_{b_i}, t_{b_{i+1}}] integrated from its own
    start (samples b_i..b_{i+1}-1, frame of b_i): what the preintegrated factor between keyframes
    b_i and b_{i+1} carries. Fewer than two boundaries give an empty (0, 9, 9) array.
    """
    return core.interval_covariances(*_inputs(t_ns, gyro, acc, var), _indices(boundaries, "boundaries"))
