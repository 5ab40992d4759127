"""The pose aiding's noise, from the data: its increments against the IMU's prediction over the same
short spans, per body axis, robust to jumps and loop closures (a median absolute deviation), with a
floor. No ground truth is read.

* **Rotation.** For rows ``a, b`` (``stride`` rows apart, no gap longer than ``max_gap_s`` between
  them: paired as the frame check pairs them, :mod:`.pairs`) the aiding's relative rotation
  ``R_a^T R_b`` against the gyro's over the same samples (its SO(3) chain): the residual's rotation
  vector, less its running median (the gyro bias over the span), per axis.
  Its robust spread is the relative rotation's sigma; each pose's own is that over sqrt(2).
* **Translation.** For rows ``a, b, c`` (one run, :func:`.pairs.runs`) the change of mean velocity, ``(p_c - p_b)/Δ2 - (p_b -
  p_a)/Δ1``, needs no velocity: the IMU predicts it from the specific force rotated into the aiding's
  world (the aiding's rotation at ``b``, carried by the gyro inside the span) as
  ``1/Δ2 ∫_b^c (t_c - s) a ds + 1/Δ1 ∫_a^b (s - a) a ds``; gravity and the accelerometer bias add a
  slowly changing term (``g (Δ1 + Δ2)/2``), removed by a running median. The residual in the body
  frame at ``b`` has, for white position noise ``σ_p`` per pose, the spread
  ``σ_p sqrt(1/Δ1² + (1/Δ1 + 1/Δ2)² + 1/Δ2²)``, which gives ``σ_p`` per axis.

The spread is 1.4826 × the median absolute deviation: a jump or loop closure moves a handful of
increments and leaves it where the rest put it. Increments with fewer than ``MIN_INCREMENTS`` are
not enough: the estimate is then None.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import numpy as np
from scipy.ndimage import median_filter
from scipy.spatial.transform import Rotation

from .pairs import RotationPairs, gyro_orientation, rotation_pairs, runs, within

MAD_TO_SIGMA = 1.4826
MIN_INCREMENTS = 20
TREND_S = 5.0  # the running median removing the gyro bias / gravity and acc bias [s]
FLOOR_ROT_RAD = float(np.deg2rad(0.005))  # a pose's rotation sigma is never taken below this
FLOOR_TRANS_M = 0.0005  # nor its position sigma below this


@dataclass(frozen=True)
class PoseNoise:
    """Each aiding pose's own noise, per body axis: rotation [rad] and position [m] sigmas (the
    relative pose between two rows has sqrt(2) times them), and how many increments each came from;
    ``span_s``: the median time between the rows compared."""

    rot_rad: np.ndarray
    trans_m: np.ndarray
    n_rot: int
    n_trans: int
    span_s: float

    def to_dict(self) -> Dict[str, object]:
        return {"rot_deg_per_axis": [round(float(np.rad2deg(x)), 5) for x in self.rot_rad],
                "trans_m_per_axis": [round(float(x), 5) for x in self.trans_m],
                "increments": {"rotation": self.n_rot, "translation": self.n_trans},
                "span_s": round(self.span_s, 4), "floor": {"rot_deg": float(np.rad2deg(FLOOR_ROT_RAD)),
                                                           "trans_m": FLOOR_TRANS_M},
                "method": "per-pose sigma: 1.4826 MAD of the aiding's increments against the IMU's prediction, "
                          "per body axis"}


def robust_sigma(r: np.ndarray) -> np.ndarray:
    """(3,) 1.4826 × the median absolute deviation of ``r`` (M, 3), per column."""
    return MAD_TO_SIGMA * np.median(np.abs(r - np.median(r, axis=0)), axis=0)


def detrend(r: np.ndarray, rows: int) -> np.ndarray:
    """``r`` (M, 3) less its running median over ``rows`` rows, per column."""
    size = max(1, min(len(r), rows) | 1)
    return r - median_filter(r, size=(size, 1), mode="nearest")


def pose_noise(imu_t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, rows: Tuple[np.ndarray, np.ndarray, np.ndarray],
               stride: int = 1, max_gap_s: float = 0.5, C: Optional[np.ndarray] = None) -> Optional[PoseNoise]:
    """Each pose's noise per body axis from ``rows`` = (IMU samples (M,), body poses R (M, 3, 3), p (M, 3)
    in the aiding's world), compared ``stride`` rows apart (module docstring); ``C``:
    :func:`gyro_orientation` when already computed. None with too few increments."""
    sample, R, p = rows
    t = (np.asarray(imu_t_ns, dtype=np.int64) - int(imu_t_ns[0])) * 1e-9
    C = gyro_orientation(imu_t_ns, gyro) if C is None else C
    ts = t[sample]
    pairs = rotation_pairs(imu_t_ns, sample, R, max_gap_s, stride, C=C)
    rot = _rotation_residuals(pairs, ts, stride)
    trans = _translation_sigma(t, C, acc, sample, R, p, within(runs(imu_t_ns, sample, max_gap_s), 2 * stride), stride)
    if len(rot) < MIN_INCREMENTS or trans is None:
        return None
    rot_rad = np.maximum(robust_sigma(rot) / np.sqrt(2), FLOOR_ROT_RAD)
    span = float(np.median(pairs.dt_s))
    return PoseNoise(rot_rad, np.maximum(trans[0], FLOOR_TRANS_M), int(len(rot)), trans[1], span)


def _rotation_residuals(pairs: RotationPairs, ts: np.ndarray, stride: int) -> np.ndarray:
    """(M, 3) the aiding's relative rotations against the gyro's (:func:`.pairs.rotation_pairs`), less
    their running median."""
    r = Rotation.from_matrix(np.einsum("nki,nkj->nij", pairs.gyro, pairs.aiding)).as_rotvec()
    per_s = max(1, int(round(TREND_S / max(float(np.median(np.diff(ts))), 1e-3) / stride)))
    return detrend(r, per_s) if len(r) else r


def _translation_sigma(t, C, acc, sample, R, p, a, stride):
    """((3,) each pose's position sigma per body axis, the number of increments) or None (too few)."""
    if len(a) < MIN_INCREMENTS:
        return None
    b, c = a + stride, a + 2 * stride
    sa, sb, sc = sample[a], sample[b], sample[c]
    d1, d2 = t[sb] - t[sa], t[sc] - t[sb]
    d_vo = (p[c] - p[b]) / d2[:, None] - (p[b] - p[a]) / d1[:, None]
    # the specific force in the gyro's frame of the first sample, and its weighted running sums
    dt = np.r_[np.diff(t), 0.0]
    F = np.einsum("nij,nj->ni", C, acc) * dt[:, None]
    S0 = np.r_[np.zeros((1, 3)), np.cumsum(F, axis=0)]
    S1 = np.r_[np.zeros((1, 3)), np.cumsum(F * t[:, None], axis=0)]
    late = (t[sc][:, None] * (S0[sc] - S0[sb]) - (S1[sc] - S1[sb])) / d2[:, None]
    early = ((S1[sb] - S1[sa]) - t[sa][:, None] * (S0[sb] - S0[sa])) / d1[:, None]
    to_A = np.einsum("nij,nkj->nik", R[b], C[sb])  # R_A_b C_b^T
    d_imu = np.einsum("nij,nj->ni", to_A, late + early)
    w = 0.5 * (d1 + d2)
    e = (d_vo - d_imu) / w[:, None]  # gravity (and the acc bias) per second: slowly changing
    per_s = max(1, int(round(TREND_S / max(float(np.median(w)), 1e-3))))
    r = detrend(e, per_s) * w[:, None]
    r_body = np.einsum("nki,nk->ni", R[b], r)
    gain = np.median(np.sqrt(1 / d1 ** 2 + (1 / d1 + 1 / d2) ** 2 + 1 / d2 ** 2))
    return robust_sigma(r_body) / gain, int(len(a))
