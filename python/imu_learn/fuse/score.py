"""Scores of a fused trajectory against ground truth at its keyframes: position RMSE [m], rotation
RMSE [deg], and for each outage the RMSE and maximum of the position error inside it (how far the
estimate coasts without aiding). Unaligned where the aiding fixes the world frame (positions in
ground truth's frame, or a ground-truth first state); after a rigid SE(3) alignment (:func:`umeyama`,
``evo_ape -a``) where it does not (relative aiding started from the data)."""
from __future__ import annotations

from dataclasses import replace
from typing import Dict, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.core.quat import rotation_angle, xyzw_to_wxyz
from imu_learn.score.metrics import rmse

from .aiding.outages import in_windows, outage_mask
from .graph import FusionResult


def rotation_errors_deg(R_est: np.ndarray, q_wxyz_gt: np.ndarray) -> np.ndarray:
    return np.rad2deg(rotation_angle(q_wxyz_gt, xyzw_to_wxyz(Rotation.from_matrix(R_est).as_quat())))


def umeyama(src: np.ndarray, dst: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(R, t) minimising sum |dst - (R src + t)|^2 (rigid, no scale), as evo_ape -a."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    cov = (dst - mu_d).T @ (src - mu_s) / len(src)
    U, _, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1.0
    R = U @ S @ Vt
    return R, mu_d - R @ mu_s


def score(res: FusionResult, t_ns: np.ndarray, p_gt: np.ndarray, q_wxyz_gt: np.ndarray,
          outages: Seq[Tuple[float, float]] = (), align: bool = False) -> Dict[str, object]:
    """``{causal|smoothed: {pos_rmse_m, rot_rmse_deg, outages: [{start_s, duration_s, rmse_m, max_m}]}}``;
    ``align``: each trajectory rigidly aligned to ground truth first (its own alignment)."""
    idx = res.kf_idx
    inside = outage_mask(t_ns, outages)[idx] if outages else np.zeros(len(idx), bool)
    rel_s = (t_ns[idx] - t_ns[0]) * 1e-9
    out: Dict[str, object] = {}
    for name, p, R in (("causal", res.causal_p, res.causal_R), ("smoothed", res.smoothed_p, res.smoothed_R)):
        if align:
            R_al, t_al = umeyama(p, p_gt[idx])
            p, R = p @ R_al.T + t_al, np.einsum("ij,njk->nik", R_al, R)
        e = np.linalg.norm(p - p_gt[idx], axis=1)
        per: List[Dict[str, float]] = []
        for start, dur in outages:
            m = in_windows(rel_s, [(start, dur)])
            per.append({"start_s": float(start), "duration_s": float(dur), "rmse_m": rmse(e[m]),
                        "max_m": float(e[m].max()) if m.any() else float("nan")})
        out[name] = {
            "pos_rmse_m": rmse(e),
            "pos_rmse_aided_m": rmse(e[~inside]),
            "rot_rmse_deg": rmse(rotation_errors_deg(R, q_wxyz_gt[idx])),
            "outages": per,
        }
    return out


def convergence(t_s: np.ndarray, causal_p: np.ndarray, causal_R: np.ndarray, smoothed_p: np.ndarray,
                smoothed_R: np.ndarray, pos_m: float = 0.1, rot_deg: float = 1.0) -> Dict[str, object]:
    """When the causal estimate settles: the first time (seconds from ``t_s[0]``) from which it
    stays within ``pos_m`` and ``rot_deg`` of the smoothed estimate at every later keyframe (None
    when it never does), for position and rotation separately and together."""
    t = np.asarray(t_s, dtype=np.float64) - float(t_s[0])
    dp = np.linalg.norm(causal_p - smoothed_p, axis=1)
    dr = np.rad2deg(np.linalg.norm((Rotation.from_matrix(causal_R).inv()
                                    * Rotation.from_matrix(smoothed_R)).as_rotvec(), axis=1))

    def settled(bad: np.ndarray) -> Optional[float]:
        if bad[-1]:
            return None
        last_bad = np.flatnonzero(bad)
        return float(t[last_bad[-1] + 1]) if len(last_bad) else 0.0

    return {"pos_tol_m": pos_m, "rot_tol_deg": rot_deg, "position_s": settled(dp > pos_m),
            "rotation_s": settled(dr > rot_deg), "converged_s": settled((dp > pos_m) | (dr > rot_deg)),
            "causal_minus_smoothed_pos_rms_m": float(np.sqrt(np.mean(dp ** 2))),
            "causal_minus_smoothed_rot_rms_deg": float(np.sqrt(np.mean(dr ** 2)))}


def crop(res, start: int, first: int):
    """The result of a run fused from sample ``start``, its keyframes counted in the recording's samples,
    from the keyframe at sample ``first`` on (the scored part)."""
    k = res.kf_idx + start >= first
    return replace(res, kf_idx=res.kf_idx[k] + start, causal_p=res.causal_p[k], causal_R=res.causal_R[k],
                   smoothed_p=res.smoothed_p[k], smoothed_R=res.smoothed_R[k], smoothed_v=res.smoothed_v[k],
                   smoothed_bias=res.smoothed_bias[k])
