"""The IMU's time offset against GNSS fixes, from the data alone (no attitude, no truth).

A GNSS position track's second difference at epoch ``e`` (neighbours ``h`` apart) is the
triangle-weighted mean of the acceleration over ``[t_e - h, t_e + h]``; the accelerometer measures
the specific force ``f = a - g``, whose norm needs no attitude. So ``|a_e + g_up|`` (from the fixes)
is compared with the same triangle-weighted mean of ``|f|`` over the IMU samples, their stamps
shifted by a trial delay (the value added to every IMU stamp, rtklibexplorer/GNSS_IMU's
``imu_t_off``); the delay with the least RMS difference (median removed: an accelerometer scale or
bias error shifts the norm) over the moving fixed epochs is the estimate, refined by a parabola
through its neighbours on the grid. The triangle means are exact for a piecewise-linear ``|f|``:
``(F(c + h) - 2 F(c) + F(c - h)) / h^2`` with ``F`` the twice-integrated ``|f|``.

On the car drive (its fixed epochs outside the outages) this finds -0.20 s, where the peer's config
sets -0.125 s (too little, as the fusion's own fit residual outside the outages agrees); on the walk
-0.01 s (its config: 0; weakly determined there): docs/experiments/fusion_gnss.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from imu_learn.errors import InvalidInputError

MIN_EPOCHS = 50  # the least moving fixed epochs (with both neighbours) the estimate uses
GRID_S = (-0.5, 0.5, 0.005)  # trial delays [s]: first, last, step


@dataclass(frozen=True)
class DelayEstimate:
    """The delay [s] to add to the IMU's stamps, the RMS specific-force-norm residual there and at
    zero delay [m/s^2], the epochs used, the grid searched ``(first, last, step)`` [s] and the residual
    at each of its delays (NaN: too few epochs there)."""

    delay_s: float
    rms_mps2: float
    rms_at_zero_mps2: float
    epochs: int
    grid_s: tuple
    grid_rms: tuple = ()

    def rms_at(self, delay_s: float) -> float:
        """The residual [m/s^2] at the grid's delay nearest ``delay_s`` (NaN outside the grid)."""
        first, last, step = self.grid_s
        k = int(round((delay_s - first) / step))
        return float(self.grid_rms[k]) if 0 <= k < len(self.grid_rms) else math.nan


def double_integral(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``F(t_i) = int_0^t_i int_0^s y``, ``y`` piecewise linear between the samples (exact)."""
    dt = np.diff(t)
    f1 = np.r_[0.0, np.cumsum(0.5 * (y[1:] + y[:-1]) * dt)]
    # F2 over a step: F1(t0) dt + y0 dt^2 / 2 + (y1 - y0) dt^2 / 6
    return np.r_[0.0, np.cumsum(f1[:-1] * dt + y[:-1] * dt * dt / 2 + (y[1:] - y[:-1]) * dt * dt / 6)]


def imu_delay(imu_t_ns: np.ndarray, acc: np.ndarray, sol, gravity: float, use: Optional[np.ndarray] = None,
              min_speed_mps: float = 1.0, grid_s: tuple = GRID_S) -> DelayEstimate:
    """The delay to add to the IMU stamps ``imu_t_ns`` (as read, no delay) that best matches the
    accelerometer's specific-force norm (``acc`` (N, 3) [m/s^2], any frame) with the RTKLIB solution
    ``sol``'s fixed (Q = 1) positions, at epochs faster than ``min_speed_mps`` whose neighbours are
    fixed and evenly spaced (and, with ``use``, all three used)."""
    t0 = int(sol.t_ns[0])
    ti = (np.asarray(imu_t_ns, dtype=np.int64) - t0) * 1e-9
    fn = np.linalg.norm(np.asarray(acc, dtype=np.float64), axis=1) - gravity
    F = double_integral(ti, fn)
    t = (np.asarray(sol.t_ns, dtype=np.int64) - t0) * 1e-9
    ok = sol.q == 1
    if use is not None:
        ok &= np.asarray(use, dtype=bool)
    i = np.arange(1, len(t) - 1)
    h = t[i] - t[i - 1]
    keep = ok[i - 1] & ok[i] & ok[i + 1] & (h > 0) & (np.abs(t[i + 1] - t[i] - h) <= 1e-3 * h)
    if sol.vel_enu is not None:
        keep &= np.linalg.norm(sol.vel_enu[i, :2], axis=1) > min_speed_mps
    i, h = i[keep], h[keep]
    p = sol.enu
    a = (p[i + 1] - 2 * p[i] + p[i - 1]) / (h * h)[:, None]
    fn_gnss = np.linalg.norm(a + np.array([0.0, 0.0, gravity]), axis=1) - gravity
    first, last, step = grid_s
    grid = np.arange(first, last + step / 2, step)
    rms = np.full(len(grid), np.nan)
    n_used = 0
    for g, d in enumerate(grid):
        c = t[i] - d  # the IMU stamp (as read) of each epoch's instant
        inside = (c - h > ti[0]) & (c + h < ti[-1])
        if inside.sum() < MIN_EPOCHS:
            continue
        cc, hh = c[inside], h[inside]
        f_imu = (np.interp(cc + hh, ti, F) - 2 * np.interp(cc, ti, F) + np.interp(cc - hh, ti, F)) / (hh * hh)
        r = f_imu - fn_gnss[inside]
        r = r - np.median(r)
        rms[g] = float(np.sqrt(np.mean(r * r)))
        n_used = max(n_used, int(inside.sum()))
    if n_used < MIN_EPOCHS or not np.isfinite(rms).any():
        raise InvalidInputError(f"{getattr(sol, 'path', 'solution')}: {n_used} moving fixed epochs inside the IMU's span: too "
                                f"few (< {MIN_EPOCHS}) to measure the IMU's time offset")
    k = int(np.nanargmin(rms))
    if k == 0 or k == len(grid) - 1 or not np.isfinite(rms[k - 1]) or not np.isfinite(rms[k + 1]):
        raise InvalidInputError(f"the IMU's time offset: the best match lies at the edge of the searched "
                                f"{first:+.3f}..{last:+.3f} s ({grid[k]:+.3f} s)")
    y0, y1, y2 = rms[k - 1], rms[k], rms[k + 1]
    curv = y0 - 2 * y1 + y2
    off = 0.5 * (y0 - y2) / curv if curv > 0 else 0.0
    zero = int(np.argmin(np.abs(grid)))
    return DelayEstimate(float(grid[k] + off * step), float(y1), float(rms[zero]), n_used, (first, last, step),
                         tuple(float(x) for x in rms))
