"""Aiding rows paired with the gyro over the same IMU samples: the one rule the aiding frame check
(:mod:`.frame`) and the pose noise estimate (:mod:`.noise`) compare rotation increments by.

* **Which rows pair.** Consecutive rows are linked when their IMU samples lie ``0 < Δt ≤ max_gap_s``
  apart (``--max-relative-gap-s``, the rule the relative poses are chained by); a run is a stretch of
  linked rows, and rows ``k`` apart pair (or make a triple, ``2k``) only inside one run.
* **The gyro's rotation over a pair** is the full SO(3) chain of its samples between them,
  ``C_aᵀ C_b`` with ``C`` the gyro's orientation (:func:`gyro_orientation`: each sample's rate held
  until the next), against the aiding's ``R_aᵀ R_b``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from scipy.spatial.transform import Rotation


def gyro_orientation(t_ns: np.ndarray, gyro: np.ndarray) -> np.ndarray:
    """(N, 3, 3): the IMU's orientation at each sample in the frame of the first, from the gyro
    alone (each sample's rate held until the next)."""
    dt = np.diff(np.asarray(t_ns, dtype=np.int64)) * 1e-9
    steps = Rotation.from_rotvec(gyro[:-1] * dt[:, None]).as_matrix()
    C = np.empty((len(t_ns), 3, 3))
    C[0] = np.eye(3)
    for k in range(len(steps)):
        C[k + 1] = C[k] @ steps[k]
    return C


def run_numbers(dt_s: np.ndarray, max_gap_s: float) -> np.ndarray:
    """The aiding's one break rule: (M,) each row's run number from the M − 1 times between consecutive
    rows ``dt_s``; two rows share a run when they are more than zero and at most ``max_gap_s`` apart."""
    dt = np.asarray(dt_s, dtype=np.float64)
    return np.r_[0, np.cumsum(~((dt > 0) & (dt <= max_gap_s)))]


def runs(imu_t_ns: np.ndarray, sample: np.ndarray, max_gap_s: float) -> np.ndarray:
    """(M,) each row's run number (:func:`run_numbers`), the rows at IMU samples ``sample``."""
    return run_numbers(np.diff(np.asarray(imu_t_ns, dtype=np.int64)[np.asarray(sample, dtype=np.int64)]) * 1e-9,
                       max_gap_s)


def within(run: np.ndarray, span: int) -> np.ndarray:
    """The rows ``a`` whose row ``a + span`` lies in the same run (:func:`runs`)."""
    a = np.arange(max(len(run) - span, 0))
    return a[run[a] == run[a + span]]


@dataclass(frozen=True)
class RotationPairs:
    """Rows ``a`` and ``b`` paired (P,), the IMU time between them ``dt_s`` [s], and the relative
    rotations over each pair (P, 3, 3): the aiding's ``R_aᵀ R_b`` and the gyro's ``C_aᵀ C_b``."""

    a: np.ndarray
    b: np.ndarray
    dt_s: np.ndarray
    aiding: np.ndarray
    gyro: np.ndarray

    def __len__(self) -> int:
        return len(self.a)


def rotation_pairs(imu_t_ns: np.ndarray, sample: np.ndarray, R: np.ndarray, max_gap_s: float, stride: int = 1,
                   C: Optional[np.ndarray] = None, gyro: Optional[np.ndarray] = None) -> RotationPairs:
    """The rows ``stride`` apart inside one run (module docstring) with the aiding's (``R`` (M, 3, 3),
    body to world) and the gyro's relative rotations; ``C``: :func:`gyro_orientation`, computed from
    ``gyro`` when not given."""
    sample = np.asarray(sample, dtype=np.int64)
    t = np.asarray(imu_t_ns, dtype=np.int64)
    if C is None:
        C = gyro_orientation(t, gyro)
    a = within(runs(t, sample, max_gap_s), stride)
    b = a + stride
    R = np.asarray(R)
    return RotationPairs(a, b, (t[sample[b]] - t[sample[a]]) * 1e-9, np.einsum("nki,nkj->nij", R[a], R[b]),
                         np.einsum("nki,nkj->nij", C[sample[a]], C[sample[b]]))
