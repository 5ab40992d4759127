"""Differentiable Δq/Δβ/Δγ in torch, batched over windows.

The same zero-order-hold scheme as imu_core (and GTSAM's manifold preintegration): sample i is held
over dt_i; R_0 = I, R_{i+1} = R_i Exp(w_i dt_i); Δβ_{i+1} = Δβ_i + R_i a_i dt_i;
Δγ_{i+1} = Δγ_i + Δβ_i dt_i + ½ R_i a_i dt_i².

The rotation products R_i are an (exclusive) prefix product, computed by a Hillis–Steele scan in
ceil(log2 W) batched quaternion multiplications instead of a Python loop over W samples; the
velocity and position sums are cumsums. Works in float32 and float64 on any device; the dtype and
device of ``gyro`` decide those of the result.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Union

import torch

from imu_learn.nn.so3 import quat_mul, quat_rotate, so3_exp

Tensor = torch.Tensor
Horizons = Union[Iterable[int], Tensor]


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


def _shift_right(x: Tensor, first: Tensor) -> Tensor:
    """Exclusive version of an inclusive scan along dim 1: (first, x[0], ..., x[W-2])."""
    return torch.cat((first, x[:, :-1]), dim=1)


def horizon_index(horizons: Horizons, W: int, device: torch.device) -> Tensor:
    """Horizons (sample counts 1..W) as 0-based indices into the inclusive scans."""
    if isinstance(horizons, Tensor):
        hs = [int(h) for h in horizons.reshape(-1).tolist()]
    else:
        hs = [int(h) for h in horizons]
    if not hs or min(hs) < 1 or max(hs) > W:
        raise ValueError(f"horizons must be sample counts in 1..{W}, got {hs}")
    return torch.as_tensor([h - 1 for h in hs], dtype=torch.long, device=device)


@dataclass
class TorchScan:
    """Per-sample states of the integration, (B, W, ...): ``R_excl`` the rotation in force while sample
    i is held (R_0 .. R_{W-1}) and ``R_incl`` after it (R_1 .. R_W), as quaternions (w,x,y,z);
    ``dv``/``dp`` after sample i (Δβ_{1..W}, Δγ_{1..W})."""

    R_excl: Tensor
    R_incl: Tensor
    dv: Tensor
    dp: Tensor


def scan(gyro: Tensor, acc: Tensor, dt: Tensor) -> TorchScan:
    """Every sample's state: gyro, acc (B, W, 3); dt (B, W) hold time of each sample [s]."""
    dt3 = dt.to(gyro.dtype).unsqueeze(-1)
    step = so3_exp(gyro * dt3)  # (B, W, 4)
    incl = prefix_quat_product(step)  # R_1 .. R_W
    ident = torch.zeros_like(step[:, :1])
    ident[..., 0] = 1.0
    R = _shift_right(incl, ident)  # R_0 .. R_{W-1}: rotation in force for sample i
    ra_dt = quat_rotate(R, acc) * dt3  # R_i a_i dt_i
    dv_incl = torch.cumsum(ra_dt, dim=1)  # Δβ_{1..W}
    dv_excl = _shift_right(dv_incl, torch.zeros_like(ra_dt[:, :1]))  # Δβ_{0..W-1}, exact
    dp_incl = torch.cumsum(dv_excl * dt3 + 0.5 * ra_dt * dt3, dim=1)
    return TorchScan(R_excl=R, R_incl=incl, dv=dv_incl, dp=dp_incl)


def integrate(gyro: Tensor, acc: Tensor, dt: Tensor, horizons: Horizons) -> TorchIncrements:
    """Increments after the first n samples of each window, for n in ``horizons``.

    gyro, acc: (B, W, 3); dt: (B, W) hold time of each sample [s]; horizons: ints in 1..W.
    """
    idx = horizon_index(horizons, gyro.shape[1], gyro.device)
    s = scan(gyro, acc, dt)
    return TorchIncrements(dq_wxyz=s.R_incl[:, idx], dv=s.dv[:, idx], dp=s.dp[:, idx])
