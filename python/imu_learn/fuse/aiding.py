"""Aiding measurements for the factor graph, each tied to IMU sample indices.

Real: EuRoC's Leica MS50 laser tracker (a prism's position, 20 Hz; lever arm from its
``sensor.yaml``), snapped to the nearest IMU sample. Simulated from ground truth (seeded, and
labelled as simulated in every table): a GNSS-like position fix and a VO-like relative pose.
Outages drop every measurement inside configured time windows.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Optional, Tuple
from typing import Sequence as Seq

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.errors import InvalidInputError
from imu_learn.quat import wxyz_to_xyzw


@dataclass(frozen=True)
class PositionFixes:
    """Positions of a point ``lever`` [m] (body frame) in the world frame at IMU samples ``idx``."""

    idx: np.ndarray
    p: np.ndarray
    sigma_m: float
    lever: np.ndarray
    label: str

    def __len__(self) -> int:
        return len(self.idx)


@dataclass(frozen=True)
class RelativePoses:
    """Body pose at sample ``j`` relative to sample ``i``: rotation ``R_ij`` and translation
    ``t_ij`` (in frame i), with isotropic rotation [rad] and translation [m] sigmas."""

    i: np.ndarray
    j: np.ndarray
    R_ij: np.ndarray
    t_ij: np.ndarray
    sigma_rot_rad: float
    sigma_trans_m: float
    label: str

    def __len__(self) -> int:
        return len(self.i)


def epochs(t_ns: np.ndarray, rate_hz: float) -> np.ndarray:
    """Sample indices nearest to a ``rate_hz`` grid starting at the first sample."""
    if not rate_hz > 0:
        raise InvalidInputError(f"aiding rate must be > 0 Hz, got {rate_hz!r}")
    period_ns = int(round(1e9 / rate_hz))
    grid = np.arange(int(t_ns[0]), int(t_ns[-1]) + 1, period_ns, dtype=np.int64)
    idx = np.clip(np.searchsorted(t_ns, grid), 0, len(t_ns) - 1)
    return np.unique(idx)


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


def leica_fixes(leica_t_ns, leica_p, lever, imu_t_ns, rate_hz: Optional[float], sigma_m: float) -> PositionFixes:
    """Real laser-tracker fixes on the IMU's clock: each snapped to the nearest IMU sample (kept when
    within half a sample period of it), then thinned to at most one per ``1/rate_hz`` s (all when
    ``rate_hz`` is None)."""
    imu_t_ns = np.asarray(imu_t_ns)
    half = int(np.median(np.diff(imu_t_ns))) // 2
    k = np.clip(np.searchsorted(imu_t_ns, leica_t_ns), 1, len(imu_t_ns) - 1)
    nearer = np.where(np.abs(imu_t_ns[k - 1] - leica_t_ns) <= np.abs(imu_t_ns[k] - leica_t_ns), k - 1, k)
    keep = np.abs(imu_t_ns[nearer] - leica_t_ns) <= half
    idx, p = nearer[keep], np.asarray(leica_p)[keep]
    if rate_hz is not None:
        bins = (imu_t_ns[idx] - imu_t_ns[0]) // int(round(1e9 / rate_hz))
        _u, first = np.unique(bins, return_index=True)
        idx, p = idx[first], p[first]
    idx, uniq = np.unique(idx, return_index=True)
    rate = "20 Hz" if rate_hz is None else f"{rate_hz:g} Hz"
    return PositionFixes(idx, p[uniq], float(sigma_m), np.asarray(lever, dtype=np.float64),
                         f"Leica MS50 (real) {rate}, sigma {sigma_m:g} m")


def outage_mask(t_ns: np.ndarray, outages: Seq[Tuple[float, float]]) -> np.ndarray:
    """True for samples inside an outage ``(start_s, duration_s)`` (seconds from the first sample)."""
    rel = (np.asarray(t_ns) - t_ns[0]) * 1e-9
    inside = np.zeros(len(t_ns), dtype=bool)
    for start, dur in outages:
        inside |= (rel >= start) & (rel < start + dur)
    return inside


def apply_outages(aiding, t_ns: np.ndarray, outages: Seq[Tuple[float, float]]):
    """``aiding`` without the measurements inside any outage (a relative pose is dropped when
    either end is inside)."""
    if not outages:
        return aiding
    inside = outage_mask(t_ns, outages)
    if isinstance(aiding, PositionFixes):
        keep = ~inside[aiding.idx]
        return replace(aiding, idx=aiding.idx[keep], p=aiding.p[keep])
    keep = ~(inside[aiding.i] | inside[aiding.j])
    return replace(aiding, i=aiding.i[keep], j=aiding.j[keep], R_ij=aiding.R_ij[keep], t_ij=aiding.t_ij[keep])
