"""Quaternions in numpy: order conversions (the one place the project reorders quaternion
components) and the Hamilton algebra on w,x,y,z arrays of shape (..., 4)."""
from __future__ import annotations

import math

import numpy as np


def xyzw_to_wxyz(q_xyzw: np.ndarray) -> np.ndarray:
    """x,y,z,w (TUM, ROS, scipy) -> w,x,y,z (imu_learn, ASL CSV, GTSAM); works on (..., 4)."""
    q = np.asarray(q_xyzw)
    return np.concatenate([q[..., 3:4], q[..., 0:3]], axis=-1)


def wxyz_to_xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    """w,x,y,z -> x,y,z,w; works on (..., 4)."""
    q = np.asarray(q_wxyz)
    return np.concatenate([q[..., 1:4], q[..., 0:1]], axis=-1)


def quat_conj(q_wxyz: np.ndarray) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion); (..., 4)."""
    return q_wxyz * np.array([1.0, -1.0, -1.0, -1.0])


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b of w,x,y,z quaternions; broadcasts over leading axes."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v (..., 3) rotated by the unit quaternion q (..., 4), w,x,y,z."""
    u, w = q[..., 1:], q[..., :1]
    uv = np.cross(u, v)
    return v + 2.0 * (w * uv + np.cross(u, uv))


def rotation_angle(q_gt: np.ndarray, q_hat: np.ndarray) -> np.ndarray:
    """Angle [rad] of q_gt⁻¹ q_hat (unit quaternions, w x y z)."""
    e = quat_mul(quat_conj(q_gt), q_hat)
    return 2.0 * np.arctan2(np.linalg.norm(e[..., 1:], axis=-1), np.abs(e[..., 0]))


def quat_log(q_wxyz: np.ndarray) -> np.ndarray:
    """Unit quaternion (..., 4) -> rotation vector (..., 3), angle in [0, pi] (the same branches as
    :func:`imu_learn.nn.so3.so3_log`, in numpy)."""
    q = np.where(q_wxyz[..., :1] < 0, -q_wxyz, q_wxyz)
    w, u = q[..., :1], q[..., 1:]
    n2 = (u * u).sum(-1, keepdims=True)
    small = n2 < 1e-12
    n = np.sqrt(np.where(small, 1.0, n2))
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(small, (2.0 / w) * (1.0 - n2 / (3.0 * w * w)), 2.0 * np.arctan2(n, w) / n)
    return scale * u


def so3_right_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """The inverse right Jacobian of SO(3) (Exp(φ + δ) ≈ Exp(φ) Exp(J_r δ)), (..., 3, 3): J_r⁻¹ = I + ½ [φ]× +
    c2 [φ]×², c2 = 1/θ² − (1 + cos θ)/(2θ sin θ) (1/12 at θ → 0); [φ]×² = φφᵀ − θ² I. Written out entry by entry."""
    x, y, z = np.moveaxis(phi, -1, 0)
    t2 = x * x + y * y + z * z
    small = t2 < 1e-8
    t2s = np.where(small, 1.0, t2)
    t = np.sqrt(t2s)
    c1 = np.full_like(t2, -0.5)
    c2 = np.where(small, 1.0 / 12.0, 1.0 / t2s - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t)))
    a = 1.0 - c2 * t2
    cx, cy, cz = c1 * x, c1 * y, c1 * z
    xy, xz, yz = c2 * x * y, c2 * x * z, c2 * y * z
    return np.stack((a + c2 * x * x, xy + cz, xz - cy, xy - cz, a + c2 * y * y, yz + cx, xz + cy, yz - cx,
                     a + c2 * z * z), axis=-1).reshape(*phi.shape[:-1], 3, 3)


def quat_from_matrix(r: np.ndarray) -> np.ndarray:
    """w,x,y,z (w >= 0) of one rotation matrix (3, 3) (Shepperd's method)."""
    t = np.trace(r)
    if t > 0:
        w = math.sqrt(1 + t) / 2
        return np.array([w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w)])
    i = int(np.argmax(np.diag(r)))
    j, k = (i + 1) % 3, (i + 2) % 3
    x = math.sqrt(max(1 + r[i, i] - r[j, j] - r[k, k], 0.0)) / 2
    q = np.zeros(4)
    q[1 + i] = x
    q[0] = (r[k, j] - r[j, k]) / (4 * x)
    q[1 + j] = (r[j, i] + r[i, j]) / (4 * x)
    q[1 + k] = (r[k, i] + r[i, k]) / (4 * x)
    return q if q[0] >= 0 else -q
