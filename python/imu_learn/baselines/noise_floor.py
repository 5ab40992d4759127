"""Noise floor: an IMU synthesised from the ground truth itself.

Evaluation scores a method's dead reckoning against ground-truth poses, and those labels are not
perfect (motion-capture noise, interpolation onto the IMU stamps, and for pose-only sources a
velocity *derived* from the positions). To show how much of an error is label noise, the report
adds a row "ground truth (noise floor)": the same metrics for the IMU that the ground truth itself
implies under the evaluation's integration.

The integration (the core's ``integrate_windows``, GTSAM-style zero-order hold) holds sample i over
[t_i, t_{i+1}) with dt_i = t_{i+1} − t_i and g = [0, 0, −gravity]::

    R_{i+1} = R_i Exp(ω_i dt_i)
    v_{i+1} = v_i + g dt_i + R_i a_i dt_i
    p_{i+1} = p_i + v_i dt_i + ½ g dt_i² + ½ R_i a_i dt_i²

so the IMU that reproduces consecutive ground-truth states exactly is::

    ω_i = Log(R_iᵀ R_{i+1}) / dt_i                   body rate from consecutive quaternions
    a_i = R_iᵀ ((v_{i+1} − v_i) / dt_i − g)          specific force from velocity differences

(the last sample, never integrated by a window, repeats the one before). With it, rotation and
velocity telescope exactly onto the ground truth: their floors are zero up to rounding *by
construction*. Position then follows p_{i+1} = p_i + ½ (v_i + v_{i+1}) dt_i (the trapezoid of the
ground-truth velocity), so the position floor is exactly the disagreement between the ground-truth
positions and the ground-truth velocities: for a perfect (self-consistent) label it is ~0, for
pose-only ground truth it shows the error that the velocity derivation (a local fit over a few
poses) and the position noise leave in the labels. No method that integrates IMU samples from the
ground-truth start state can be expected to score below it on position.
"""
from __future__ import annotations

from typing import Tuple

import numpy as np

from imu_learn.baselines.base import Method
from imu_learn.core.quat import quat_conj, quat_mul, quat_rotate
from imu_learn.data.types import Segment
from imu_learn.errors import InvalidInputError

NOISE_FLOOR_NAME = "ground truth (noise floor)"


def quat_log(q_wxyz: np.ndarray) -> np.ndarray:
    """Rotation vector (…, 3) of unit quaternions (shortest arc: q and −q give the same)."""
    q = np.asarray(q_wxyz, dtype=np.float64)
    q = np.where(q[..., :1] < 0, -q, q)
    xyz = q[..., 1:]
    s = np.linalg.norm(xyz, axis=-1)
    angle = 2.0 * np.arctan2(s, q[..., 0])
    # angle / s -> 2 / w as s -> 0
    scale = np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 2.0 / np.maximum(q[..., 0], 1e-300))
    return xyz * scale[..., None]


def synthesize_imu(seq: Segment, gravity: float = 9.81) -> Tuple[np.ndarray, np.ndarray]:
    """(gyro, acc), each (N, 3) float64: the IMU that the ground truth of ``seq`` implies under the
    zero-order-hold integration (see the module doc)."""
    n = len(seq)
    if n < 2:
        raise InvalidInputError(f"{seq.name}: need at least 2 samples to synthesise an IMU, got {n}")
    dt = np.diff(np.asarray(seq.t_ns, dtype=np.int64)).astype(np.float64) * 1e-9
    if np.any(dt <= 0):
        raise InvalidInputError(f"{seq.name}: timestamps must increase strictly")
    q = np.asarray(seq.q_wxyz, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    dq = quat_mul(quat_conj(q[:-1]), q[1:])
    gyro = np.empty((n, 3))
    gyro[:-1] = quat_log(dq) / dt[:, None]
    gyro[-1] = gyro[-2]
    g = np.array([0.0, 0.0, -gravity])
    world = (seq.v[1:] - seq.v[:-1]) / dt[:, None] - g[None]
    acc = np.empty((n, 3))
    acc[:-1] = quat_rotate(quat_conj(q[:-1]), world)
    acc[-1] = acc[-2]
    return gyro, acc


class GroundTruthImu(Method):
    """Not a method: the noise-floor reference row. ``refine`` returns the IMU synthesised from the
    sequence's own ground truth (:func:`synthesize_imu`), so evaluation integrates it exactly like a
    refined IMU. It uses the test ground truth, which no real method may; it is reported only as
    the floor that label noise sets."""

    name = NOISE_FLOOR_NAME
    rotation_only = False

    def __init__(self, gravity: float = 9.81) -> None:
        self.gravity = gravity

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        return synthesize_imu(seq, self.gravity)
