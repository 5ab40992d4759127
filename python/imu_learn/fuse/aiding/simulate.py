"""Aiding simulated from ground truth (seeded, and labelled as simulated in every table): a GNSS-like
position fix and a VO-like relative pose, on the :func:`~imu_learn.fuse.aiding.sampling.epochs` grid."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.core.quat import wxyz_to_xyzw

from .sampling import epochs
from .types import PositionFixes, RelativePoses


def simulate_position(t_ns, p_gt, rate_hz: float, sigma_m: float, rng: np.random.Generator) -> PositionFixes:
    """GNSS-like fixes: ground-truth position plus white Gaussian noise, every ``1/rate_hz`` s."""
    idx = epochs(t_ns, rate_hz)
    p = p_gt[idx] + rng.normal(0.0, sigma_m, size=(len(idx), 3))
    return PositionFixes(idx, p, float(sigma_m), np.zeros(3),
                         f"simulated position {rate_hz:g} Hz, sigma {sigma_m:g} m")


def simulate_relative_pose(t_ns, p_gt, q_wxyz_gt, rate_hz: float, sigma_rot_deg: float, sigma_trans_m: float,
                           rng: np.random.Generator) -> RelativePoses:
    """VO-like relative poses between consecutive ``rate_hz`` epochs: ground truth perturbed by a
    random rotation (axis-angle, sigma per axis) and a translation error (sigma per axis)."""
    idx = epochs(t_ns, rate_hz)
    i, j = idx[:-1], idx[1:]
    R = Rotation.from_quat(wxyz_to_xyzw(q_wxyz_gt))
    Ri, Rj = R[i], R[j]
    R_ij = (Ri.inv() * Rj)
    t_ij = Ri.inv().apply(p_gt[j] - p_gt[i])
    sig_r = np.deg2rad(sigma_rot_deg)
    R_noisy = R_ij * Rotation.from_rotvec(rng.normal(0.0, sig_r, size=(len(i), 3)))
    t_noisy = t_ij + rng.normal(0.0, sigma_trans_m, size=(len(i), 3))
    return RelativePoses(i, j, R_noisy.as_matrix(), t_noisy, float(sig_r), float(sigma_trans_m),
                         f"simulated relative pose {rate_hz:g} Hz, sigma {sigma_rot_deg:g} deg / {sigma_trans_m:g} m")
