"""Differentiable SO(3) on quaternions (w,x,y,z, Hamilton) in torch, float32 or float64.

exp and log are written with the "double where" pattern so that gradients stay finite at the
identity, where |phi| has no derivative.
"""
from __future__ import annotations

import torch

Tensor = torch.Tensor


def quat_mul(a: Tensor, b: Tensor) -> Tensor:
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        dim=-1,
    )


def quat_conj(q: Tensor) -> Tensor:
    return q * q.new_tensor([1.0, -1.0, -1.0, -1.0])


def quat_rotate(q: Tensor, v: Tensor) -> Tensor:
    """R(q) v for unit q: v + 2w (u x v) + 2 u x (u x v), u the vector part."""
    w = q[..., :1]
    u = q[..., 1:]
    uv = torch.cross(u, v, dim=-1)
    return v + 2.0 * (w * uv + torch.cross(u, uv, dim=-1))


def so3_exp(phi: Tensor) -> Tensor:
    """Rotation vector (..., 3) -> unit quaternion (..., 4)."""
    theta2 = (phi * phi).sum(-1, keepdim=True)
    small = theta2 < 1e-8
    theta_safe = torch.sqrt(torch.where(small, torch.ones_like(theta2), theta2))
    half = 0.5 * theta_safe
    s_big = torch.sin(half) / theta_safe
    c_big = torch.cos(half)
    # Taylor: sin(t/2)/t = 1/2 - t^2/48 + ..., cos(t/2) = 1 - t^2/8 + ...
    s_small = 0.5 - theta2 / 48.0
    c_small = 1.0 - theta2 / 8.0
    s = torch.where(small, s_small, s_big)
    c = torch.where(small, c_small, c_big)
    return torch.cat((c, s * phi), dim=-1)


def so3_log(q: Tensor) -> Tensor:
    """Unit quaternion (..., 4) -> rotation vector (..., 3) with angle in [0, pi]."""
    sign = torch.where(q[..., :1] < 0, -torch.ones_like(q[..., :1]), torch.ones_like(q[..., :1]))
    q = q * sign
    w = q[..., :1]
    u = q[..., 1:]
    n2 = (u * u).sum(-1, keepdim=True)
    small = n2 < 1e-12
    n_safe = torch.sqrt(torch.where(small, torch.ones_like(n2), n2))
    scale_big = 2.0 * torch.atan2(n_safe, w) / n_safe
    # 2 atan2(n, w)/n = (2/w)(1 - n^2/(3 w^2)) + O(n^4)
    scale_small = (2.0 / w) * (1.0 - n2 / (3.0 * w * w))
    return torch.where(small, scale_small, scale_big) * u
