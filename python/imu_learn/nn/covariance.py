"""Covariance of the integrated increments under per-sample IMU noise, in torch (batched, differentiable).

Noise model: sample i's error is zero-mean white noise with the *discrete-time* per-axis variances
``var[i] = (σ²_gx, σ²_gy, σ²_gz, σ²_ax, σ²_ay, σ²_az)`` in (rad/s)² and (m/s²)², i.e. the variance of
one sample as the model predicts it. A filter that wants a continuous-time noise density takes
``σ_c = σ · sqrt(dt)`` (rad/s/√Hz, m/s²/√Hz); GTSAM's ``PreintegrationParams`` takes ``σ_c²`` as its
covariance and divides by dt itself (:func:`continuous_covariance`).

Error state (δθ, δβ, δγ), 9 components, all in the window's start frame: the true rotation increment is
``Exp(δθ) Δq̂`` (a left perturbation, the frame of the rotation residual ``Log(Δq_s Δq̂⁻¹)`` the losses
use), ``Δβ = Δβ̂ + δβ``, ``Δγ = Δγ̂ + δγ``. GTSAM's manifold ``preintMeasCov`` is the same covariance in
its own coordinates (δθ right-perturbed, position before velocity, both in the frame at the end of the
interval): :func:`to_gtsam_manifold` converts.

Closed form instead of a recursion over samples (the linearised propagation
``Σ_{i+1} = A_i Σ_i A_iᵀ + B_i Q_i B_iᵀ`` unrolled): to first order, sample k's noise moves the state
after sample h by ``E_h F_k n_k`` where ``F_k`` depends on sample k alone and ``E_h`` on the state at h:

    F_k (gyro)  = [M_k; [v_{k+1}]× M_k; [p_{k+1} − T_{k+1} v_{k+1}]× M_k],   M_k = R_{k+1} J_r(ω_k dt_k) dt_k
    F_k (acc)   = [0;   R_k dt_k;       (dt_k/2 − T_{k+1}) R_k dt_k]
    E_h         = [[I, 0, 0], [−[v_h]×, I, 0], [−[p_h]×, T_h I, I]]

so ``Σ_h = E_h (Σ_{k<h} F_k Q_k F_kᵀ) E_hᵀ``: one cumulative sum of 9×9 matrices gives every horizon
(T_k is the time since the window's start). It equals the recursion exactly (same Jacobians, no
further approximation); tests/test_torch_covariance.py checks it against GTSAM.
"""
from __future__ import annotations

from typing import Optional

import torch

from imu_learn.nn.integration import Horizons, horizon_index, scan

Tensor = torch.Tensor


def quat_to_matrix(q: Tensor) -> Tensor:
    """Unit quaternion (..., 4) w,x,y,z -> rotation matrix (..., 3, 3)."""
    w, x, y, z = q.unbind(-1)
    rows = (
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    )
    return torch.stack(rows, dim=-1).reshape(q.shape[:-1] + (3, 3))


def skew(v: Tensor) -> Tensor:
    """(..., 3) -> (..., 3, 3) with skew(v) u = v × u."""
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack((o, -z, y, z, o, -x, -y, x, o), dim=-1).reshape(v.shape[:-1] + (3, 3))


def so3_right_jacobian(phi: Tensor) -> Tensor:
    """J_r(φ) = I − (1 − cos θ)/θ² [φ]× + (θ − sin θ)/θ³ [φ]×², Taylor terms near θ = 0."""
    theta2 = (phi * phi).sum(-1)[..., None, None]
    small = theta2 < 1e-6
    t2 = torch.where(small, torch.ones_like(theta2), theta2)
    t = torch.sqrt(t2)
    a = torch.where(small, 0.5 - theta2 / 24.0, (1.0 - torch.cos(t)) / t2)
    b = torch.where(small, 1.0 / 6.0 - theta2 / 120.0, (t - torch.sin(t)) / (t2 * t))
    K = skew(phi)
    eye = torch.eye(3, dtype=phi.dtype, device=phi.device).expand_as(K)
    return eye - a * K + b * (K @ K)


def _noise_jacobians(gyro: Tensor, acc: Tensor, dt: Tensor, Rx: Tensor, Ri: Tensor, v: Tensor, p: Tensor,
                     T: Tensor) -> tuple:
    """F_k for the gyro (B, W, 9, 3) and accelerometer (B, W, 9, 3) noise of every sample."""
    dt_ = dt[..., None, None]
    M = Ri @ so3_right_jacobian(gyro * dt[..., None]) * dt_
    Tn = T[..., None]
    Fg = torch.cat((M, skew(v) @ M, skew(p - Tn * v) @ M), dim=-2)
    A = Rx * dt_
    c = (0.5 * dt - T)[..., None, None]
    Fa = torch.cat((torch.zeros_like(A), A, c * A), dim=-2)
    return Fg, Fa


def increment_covariance(gyro: Tensor, acc: Tensor, dt: Tensor, var: Tensor,
                         horizons: Optional[Horizons] = None) -> Tensor:
    """Covariance of (δθ, δβ, δγ) after the first n samples of each window.

    gyro, acc: (B, W, 3) the measurements integrated; dt: (B, W) hold times [s]; var: (B, W, 6) per-sample
    discrete-time variances (gyro then acc). Returns (B, H, 9, 9) for ``horizons`` (sample counts in
    1..W), or (B, W, 9, 9) for every horizon 1..W when ``horizons`` is None.
    """
    dt = dt.to(gyro.dtype)
    s = scan(gyro, acc, dt)
    Ri = quat_to_matrix(s.R_incl)  # R_{k+1}
    Rx = quat_to_matrix(s.R_excl)  # R_k
    T = torch.cumsum(dt, dim=1)  # T_{k+1}: time at the end of sample k
    Fg, Fa = _noise_jacobians(gyro, acc, dt, Rx, Ri, s.dv, s.dp, T)
    F = torch.cat((Fg, Fa), dim=-1)  # (B, W, 9, 6)
    # F Q Fᵀ as (F Q) Fᵀ, not (F √Q)(F √Q)ᵀ: sqrt has an infinite derivative at 0, which made the
    # gradient NaN wherever a variance was exactly zero.
    FQ = F * var.to(gyro.dtype)[..., None, :]
    C = torch.cumsum(FQ @ F.transpose(-1, -2), dim=1)  # Σ_{k<h} F Q Fᵀ for h = 1..W
    v, p = s.dv, s.dp
    if horizons is not None:
        idx = horizon_index(horizons, gyro.shape[1], gyro.device)
        C, v, p, T = C[:, idx], v[:, idx], p[:, idx], T[:, idx]
    eye = torch.eye(3, dtype=gyro.dtype, device=gyro.device).expand(v.shape[:-1] + (3, 3))
    zero = torch.zeros_like(eye)
    E = torch.cat((
        torch.cat((eye, zero, zero), dim=-1),
        torch.cat((-skew(v), eye, zero), dim=-1),
        torch.cat((-skew(p), T[..., None, None] * eye, eye), dim=-1),
    ), dim=-2)
    return E @ C @ E.transpose(-1, -2)


def to_gtsam_manifold(cov: Tensor, dq_wxyz: Tensor) -> Tensor:
    """Our (δθ, δβ, δγ) start-frame covariance (..., 9, 9) -> GTSAM ``preintMeasCov`` coordinates of the
    manifold preintegration (δθ right-perturbed, then position, then velocity, both rotated into the
    frame at the end of the interval): every block is rotated by ΔRᵀ and position goes before velocity."""
    Rt = quat_to_matrix(dq_wxyz).transpose(-1, -2)
    zero = torch.zeros_like(Rt)
    Tm = torch.cat((
        torch.cat((Rt, zero, zero), dim=-1),
        torch.cat((zero, zero, Rt), dim=-1),
        torch.cat((zero, Rt, zero), dim=-1),
    ), dim=-2)
    return Tm @ cov @ Tm.transpose(-1, -2)


def continuous_covariance(var: Tensor, dt: Tensor) -> Tensor:
    """Per-sample discrete variances (..., 6) and hold times (...) -> the continuous-time covariance
    densities (σ² dt) a filter or GTSAM's ``PreintegrationParams`` expects."""
    return var * dt[..., None]
