"""GNSS velocities as factors: the epoch's ENU velocity from an RTKLIB solution, as
rtklibexplorer/GNSS_IMU's EKF uses them; the antenna's rotation-induced velocity (omega x lever,
~cm/s with car lever arms) is neglected.

A receiver's velocity need not belong to its epoch's instant: the rtklibexplorer/GNSS_IMU solutions
(``gnss_*_sf.pos``) give the mean velocity over the 0.25 s before each epoch, 0.12 s behind the
positions (:func:`velocity_lag` measures it from the file alone, against the fixed positions' own
central differences: docs/experiments/fusion_gnss.md). With ``lag_s`` the velocity constrains the
state at ``t_epoch - lag_s``: the two keyframes around that instant, linearly interpolated
(:func:`interpolated_velocity_factor`, an exact linear factor); without it, the fix's own keyframe
(its epoch's instant, as before)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from imu_learn.errors import InvalidInputError

from ..aiding.rtklib import RtkSolution
from ..aiding.types import GnssFixes

MIN_LAG_EPOCHS = 20  # the least fixed epochs with both neighbours fixed that :func:`velocity_lag` fits on
MIN_ACC_RMS = 0.01  # [m/s^2] the least horizontal RMS acceleration (second differences) that tells a lag


@dataclass(frozen=True)
class VelocityLag:
    """:func:`velocity_lag`'s answer: the lag [s] (the velocity belongs to ``t_epoch - lag_s``), the
    horizontal RMS of velocity minus the positions' central difference before and after the
    lag [m/s], and the epochs it used."""

    lag_s: float
    rms_before_mps: float
    rms_after_mps: float
    epochs: int


def velocity_lag(sol: RtkSolution, qualities=(1,), use: Optional[np.ndarray] = None) -> VelocityLag:
    """How far the solution's velocities lag its positions, from the file alone: at each epoch whose
    two neighbours are equally spaced and of ``qualities`` (and, with ``use`` (bool per epoch), all
    three used), the central difference of the positions
    ``c`` (the velocity at the epoch, to second order) and the second difference ``a`` (the
    acceleration); a velocity of ``t - lag`` reads ``c - lag a``, so the lag is the least-squares
    ``-sum((v - c) . a) / sum(a . a)`` over the horizontal axes. No IMU and no truth involved."""
    if sol.vel_enu is None:
        raise InvalidInputError(f"{sol.path}: no velocity columns: no velocity lag to measure")
    t = (np.asarray(sol.t_ns, dtype=np.int64) - int(sol.t_ns[0])) * 1e-9
    ok_q = np.isin(sol.q, np.asarray(qualities))
    if use is not None:
        ok_q &= np.asarray(use, dtype=bool)
    i = np.arange(1, len(t) - 1)
    h1, h2 = t[i] - t[i - 1], t[i + 1] - t[i]
    keep = ok_q[i - 1] & ok_q[i] & ok_q[i + 1] & (h1 > 0) & (np.abs(h2 - h1) <= 1e-3 * h1)
    i, h = i[keep], h1[keep]
    if len(i) < MIN_LAG_EPOCHS:
        raise InvalidInputError(f"{sol.path}: {len(i)} evenly spaced epochs of quality {list(qualities)} with both "
                                f"neighbours: too few (< {MIN_LAG_EPOCHS}) to measure the velocity lag")
    p = sol.enu
    c = ((p[i + 1] - p[i - 1]) / (2 * h)[:, None])[:, :2]
    a = ((p[i + 1] - 2 * p[i] + p[i - 1]) / (h * h)[:, None])[:, :2]
    r = sol.vel_enu[i][:, :2] - c
    aa = float(np.sum(a * a))
    if not aa > MIN_ACC_RMS ** 2 * len(a):
        raise InvalidInputError(f"{sol.path}: the track never accelerates: the velocity lag is not observable")
    lag = -float(np.sum(r * a)) / aa
    rms = lambda x: float(np.sqrt(np.mean(np.sum(x * x, axis=1))))  # noqa: E731
    return VelocityLag(lag, rms(r), rms(r + lag * a), int(len(i)))


def interpolated_velocity_factor(k0: int, k1: int, alpha: float, v: np.ndarray, sigma: float):
    """The factor ``(1 - alpha) V(k0) + alpha V(k1) = v`` (isotropic ``sigma``): the velocity at an
    instant between keyframes ``k0`` and ``k1``, linear in both, as GTSAM's exact linear factor
    held at zero (a vector space: its error is the Jacobian factor's at any values)."""
    import gtsam
    from gtsam.symbol_shorthand import V

    if k0 == k1 or alpha <= 0.0:
        return gtsam.PriorFactorVector(V(k0), np.asarray(v, dtype=np.float64), gtsam.noiseModel.Isotropic.Sigma(3, sigma))
    if alpha >= 1.0:
        return gtsam.PriorFactorVector(V(k1), np.asarray(v, dtype=np.float64), gtsam.noiseModel.Isotropic.Sigma(3, sigma))
    eye = np.eye(3)
    jf = gtsam.JacobianFactor(V(k0), (1.0 - alpha) * eye, V(k1), alpha * eye, np.asarray(v, dtype=np.float64),
                              gtsam.noiseModel.Isotropic.Sigma(3, sigma))
    at = gtsam.Values()
    at.insert(V(k0), np.zeros(3))
    at.insert(V(k1), np.zeros(3))
    return gtsam.LinearContainerFactor(jf, at)


def velocity_callback(fixes: GnssFixes, sol: RtkSolution, sigma: float, float_gain: float,
                      lag_s: float = 0.0) -> Callable:
    """An ``extra_factors`` callback adding each fix's epoch velocity when the fix arrives (sigma times
    ``float_gain`` for float epochs): on the fix's keyframe (``lag_s = 0``), or at ``t_epoch -
    lag_s`` between the two keyframes around it (:func:`interpolated_velocity_factor`; an instant
    before the first keyframe is skipped)."""
    import gtsam
    from gtsam.symbol_shorthand import V

    if sol.vel_enu is None:
        raise InvalidInputError(f"{sol.path}: velocity_sigma_mps > 0 but the file has no velocity columns")
    if not (np.isfinite(lag_s) and lag_s >= 0.0):
        raise InvalidInputError(f"velocity lag: a time >= 0 s, got {lag_s!r}")
    at = {int(s): (sol.vel_enu[e], sigma * (1.0 if q == 1 else float_gain), int(sol.t_ns[e]) - int(round(lag_s * 1e9)))
          for s, e, q in zip(fixes.idx, fixes.epoch, fixes.q)}

    def extra(inc, k: int, s: int) -> list:
        if s not in at:
            return []
        v, sg, t_v = at[s]
        if lag_s == 0.0:
            return [gtsam.PriorFactorVector(V(k), v, gtsam.noiseModel.Isotropic.Sigma(3, sg))]
        kt = inc.t_ns[inc.kf_idx[:k + 1]]
        if t_v < kt[0]:
            return []
        j = min(int(np.searchsorted(kt, t_v, side="right")) - 1, k)
        if j == k:
            return [interpolated_velocity_factor(k, k, 0.0, v, sg)]
        alpha = (t_v - int(kt[j])) / (int(kt[j + 1]) - int(kt[j]))
        return [interpolated_velocity_factor(j, j + 1, alpha, v, sg)]

    return extra
