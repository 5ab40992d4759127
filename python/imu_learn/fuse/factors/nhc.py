"""The non-holonomic constraint (NHC) of a wheeled vehicle as a factor: no sideways and no vertical
velocity in the vehicle's body frame.

The body frame is the vehicle frame (x forward; the IMU samples already rotated into it by the
mounting rotation, :func:`imu_learn.data.formats.gnss_imu.mounting_rotation`). For the pose
``X = (R, p)`` and world velocity ``V = v`` of the IMU at a keyframe, the velocity of the
constrained point (``lever`` [m] from the IMU in the body frame, e.g. the rear axle's middle) in
the body frame is ``u = R^T v + omega x lever`` (``omega``: the body rate at that keyframe, taken as
a constant); the factor's residual is ``(u_y, u_z)`` with sigmas ``(sigma_lat, sigma_vert)`` [m/s].

Jacobians, with GTSAM's retractions ``R <- R Exp(dtheta)``, ``p <- p + R dp`` and ``v <- v + dv``:
``d(R^T v)/dtheta = [R^T v]_x`` (since ``Exp(-dtheta) R^T v ~ R^T v + (R^T v) x dtheta``),
``d/dp = 0`` and ``d/dv = R^T``; each restricted to rows y, z (tests/test_gnss_imu.py checks them
against numerical derivatives). It plugs into :class:`imu_learn.fuse.graph.IncrementalFusion` /
:func:`imu_learn.fuse.graph.fuse` through ``extra_factors`` (:func:`nhc_callback`). Both passes hold it
as a native factor linearised at a point (a Python call inside GTSAM's solvers would copy all their
values each time): the causal solver at its keyframe's IMU prediction, the batch smoothing pass at
its estimate, relinearised between Levenberg-Marquardt runs (:mod:`.held`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, List, Optional, Sequence

import numpy as np

from imu_learn.errors import InvalidInputError


@dataclass(frozen=True)
class NhcSettings:
    """Sigmas [m/s] of the body-frame lateral and vertical velocity; ``lever`` [m]: the constrained
    point from the IMU, body frame; ``every_s``: one factor per keyframe at most this often
    (0: every keyframe); ``max_yaw_rate_dps``: [deg/s] no factor while turning faster (skids);
    ``update_every_s``: the NHC factors alone (no aiding at that keyframe) update the causal solver at
    most this often, else they join the next update (an update at every keyframe, with iSAM2 calling
    the Python factor, made the causal pass 2.5-6x the run without NHC: docs/experiments/navigate-nhc.md).
    The one NHC settings type: the navigator's ``--nhc``, an experiment scenario's ``nhc_sigma_mps``
    and the GNSS outage config's ``[nhc]`` table all build one."""

    sigma_lat: float = 0.1
    sigma_vert: float = 0.1
    lever: Sequence[float] = (0.0, 0.0, 0.0)
    every_s: float = 0.0
    max_yaw_rate_dps: float = float("inf")
    update_every_s: float = 0.5

    def __post_init__(self) -> None:
        if not (self.sigma_lat > 0 and self.sigma_vert > 0 and self.every_s >= 0 and self.max_yaw_rate_dps > 0
                and self.update_every_s >= 0):
            raise InvalidInputError(f"NHC: sigmas and max_yaw_rate_dps must be > 0, every_s and update_every_s "
                                    f">= 0: {self}")

    @property
    def max_yaw_rate(self) -> float:
        """``max_yaw_rate_dps`` in rad/s."""
        return math.radians(self.max_yaw_rate_dps)


def skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def nhc_error(R: np.ndarray, v: np.ndarray, omega_cross_lever: np.ndarray) -> np.ndarray:
    """The residual ``(u_y, u_z)`` for attitude ``R`` (3, 3), world velocity ``v`` (3,) and the
    constant ``omega x lever`` (3,) [m/s] (module docstring)."""
    return (R.T @ v + omega_cross_lever)[1:]


def nhc_jacobians(R: np.ndarray, v: np.ndarray) -> tuple:
    """``(H_pose (2, 6), H_vel (2, 3))`` of :func:`nhc_error` in GTSAM's tangent spaces (Pose3:
    rotation then translation)."""
    vb = R.T @ v
    H_pose = np.zeros((2, 6))
    H_pose[:, :3] = skew(vb)[1:]
    return H_pose, R.T[1:]


def nhc_factor(pose_key: int, vel_key: int, settings: NhcSettings, omega: Optional[np.ndarray] = None):
    """A ``gtsam.CustomFactor`` on ``pose_key`` (Pose3) and ``vel_key`` (Vector3): the body-frame
    lateral and vertical velocity of the constrained point about zero. ``omega`` (3,) [rad/s]: the
    body rate for the lever term (ignored when None or a zero lever)."""
    import gtsam

    lever = np.asarray(settings.lever, dtype=np.float64).reshape(3)
    wxl = np.zeros(3) if omega is None else np.cross(np.asarray(omega, dtype=np.float64), lever)
    model = gtsam.noiseModel.Diagonal.Sigmas(np.array([settings.sigma_lat, settings.sigma_vert]))

    def error(this, values, jacobians: Optional[List[np.ndarray]]) -> np.ndarray:
        R = values.atPose3(this.keys()[0]).rotation().matrix()
        v = values.atVector(this.keys()[1])
        if jacobians is not None:
            jacobians[0], jacobians[1] = nhc_jacobians(R, v)
        return nhc_error(R, v, wxl)

    return gtsam.CustomFactor(model, [pose_key, vel_key], error)


def nhc_callback(settings: NhcSettings, gyro: Optional[np.ndarray] = None,
                 active: Optional[np.ndarray] = None) -> Callable:
    """An ``extra_factors`` callback for :class:`imu_learn.fuse.graph.IncrementalFusion`: an NHC factor
    at keyframe ``k`` (IMU sample ``s``), at most every ``settings.every_s`` seconds, skipped while
    the gyro's |z| rate exceeds ``max_yaw_rate`` or where ``active[s]`` is False (e.g. outside the
    stretch where the platform is a wheeled vehicle). ``gyro`` (N, 3): the body rates for the lever
    term and the turn test (the same samples the graph integrates)."""
    from gtsam.symbol_shorthand import V, X

    max_yaw_rate = settings.max_yaw_rate
    state = {"last_ns": None}
    period_ns = int(round(settings.every_s * 1e9))

    def extra(inc, k: int, s: int) -> list:
        if active is not None and not active[s]:
            return []
        w = None if gyro is None else gyro[s]
        if w is not None and abs(w[2]) > max_yaw_rate:
            return []
        t = int(inc.t_ns[s])
        if period_ns and state["last_ns"] is not None and t - state["last_ns"] < period_ns:
            return []
        state["last_ns"] = t
        return [nhc_factor(X(k), V(k), settings, w)]

    extra.update_every_s = settings.update_every_s  # read by IncrementalFusion (when to update)
    return extra


def calibrate_lever(R: np.ndarray, v: np.ndarray, omega: np.ndarray, min_speed: float = 2.0,
                    min_rate: float = 0.01) -> tuple:
    """The constrained point's lever ``(r_x, 0, r_z)`` [m] from an unconstrained (no NHC) estimate:
    attitudes ``R`` (K, 3, 3), world velocities ``v`` (K, 3) and body rates ``omega`` (K, 3) at
    keyframes. A point with no sideways velocity satisfies ``(R^T v)_y = -omega_z r_x + omega_x r_z``
    (the y row of ``omega x r``), fitted by least squares over the keyframes faster than
    ``min_speed`` [m/s]. Returns ``(lever (3,), residual std [m/s], keyframes used)``: the residual
    is what the NHC's lateral sigma must allow. Without enough turning and rolling to tell the two
    apart (the regressors' smaller singular value below ``min_rate`` [rad/s] RMS, e.g. a straight
    drive) it raises :class:`InvalidInputError` rather than return a lever fitted to noise."""
    vb = np.einsum("kji,kj->ki", np.asarray(R), np.asarray(v))
    m = np.linalg.norm(vb, axis=1) > min_speed
    if m.sum() < 10:
        raise InvalidInputError(f"NHC lever: {int(m.sum())} keyframes faster than {min_speed} m/s; at least 10 needed")
    A = np.stack([-omega[m, 2], omega[m, 0]], axis=1)
    sv = np.linalg.svd(A / np.sqrt(len(A)), compute_uv=False)
    if sv.min() < min_rate:
        raise InvalidInputError(f"NHC lever: too little yaw/roll rate to fit it (RMS excitation {sv.min():.4f} < "
                                f"{min_rate} rad/s)")
    x, *_ = np.linalg.lstsq(A, vb[m, 1], rcond=None)
    resid = vb[m, 1] - A @ x
    return np.array([x[0], 0.0, x[1]]), float(resid.std()), int(m.sum())
