"""Differentiable Δq/Δβ/Δγ in torch, batched over windows.

The same zero-order-hold scheme as imu_core (and GTSAM's manifold preintegration): sample i is held
over dt_i; R_0 = I, R_{i+1} = R_i Exp(w_i dt_i); Δβ_{i+1} = Δβ_i + R_i a_i dt_i;
Δγ_{i+1} = Δγ_i + Δβ_i dt_i + ½ R_i a_i dt_i².

The rotation products R_i are an (exclusive) prefix product, computed by a Hillis–Steele scan in
ceil(log2 W) batched quaternion multiplications instead of a Python loop over W samples; the
velocity and position sums are cumsums.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import torch

from imu_learn.torch_so3 import quat_mul, quat_rotate, so3_exp

Tensor = torch.Tensor


@dataclass
class TorchIncrements:
    dq_wxyz: Tensor  # (B, H, 4)
    dv: Tensor  # (B, H, 3)
    dp: Tensor  # (B, H, 3)


def prefix_quat_product(q: Tensor) -> Tensor:
    """Inclusive prefix product along dim -2: out[i] = q[0] q[1] ... q[i] (Hillis–Steele scan)."""
    out = q
    n = q.shape[-2]
    shift = 1
    while shift < n:
        left = out[..., : n - shift, :]
        right = out[..., shift:, :]
        out = torch.cat((out[..., :shift, :], quat_mul(left, right)), dim=-2)
        shift *= 2
    return out


def integrate(gyro: Tensor, acc: Tensor, dt: Tensor, horizons: Sequence[int]) -> TorchIncrements:
    """Increments after the first n samples of each window, for n in ``horizons``.

    gyro, acc: (B, W, 3); dt: (B, W) hold time of each sample [s]; horizons: ints in 1..W.
    """
    B, W, _ = gyro.shape
    dt3 = dt.unsqueeze(-1)
    step = so3_exp(gyro * dt3)  # (B, W, 4)
    incl = prefix_quat_product(step)  # R_1 .. R_W
    ident = torch.zeros_like(step[:, :1])
    ident[..., 0] = 1.0
    R = torch.cat((ident, incl[:, :-1]), dim=1)  # R_0 .. R_{W-1}: rotation in force for sample i
    ra_dt = quat_rotate(R, acc) * dt3  # R_i a_i dt_i
    dv_incl = torch.cumsum(ra_dt, dim=1)  # Δβ_{1..W}
    dv_excl = dv_incl - ra_dt  # Δβ_{0..W-1}
    dp_incl = torch.cumsum(dv_excl * dt3 + 0.5 * ra_dt * dt3, dim=1)
    idx = torch.as_tensor([int(h) - 1 for h in horizons], device=gyro.device)
    return TorchIncrements(dq_wxyz=incl[:, idx], dv=dv_incl[:, idx], dp=dp_incl[:, idx])
