"""Scoring, in one place. Scores of a fused trajectory against ground truth at its keyframes: position RMSE [m], rotation
RMSE [deg], and for each outage the RMSE and maximum of the position error inside it (how far the
estimate coasts without aiding). Unaligned where the aiding fixes the world frame (positions in
ground truth's frame, or a ground-truth first state); after a rigid SE(3) alignment (:func:`umeyama`,
``evo_ape -a``) where it does not (relative aiding started from the data)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Dict, Optional, Sequence, Tuple
from typing import Sequence as Seq

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from imu_learn.core.quat import rotation_angle, xyzw_to_wxyz
from imu_learn.data.formats import fetch
from imu_learn.data.formats.groundtruth import read_groundtruth
from imu_learn.errors import AidingError
from imu_learn.score.metrics import rmse

from .aiding.outages import in_windows, outage_mask
from .geo import enu_to_llh, llh_to_enu
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


def window_errors(e: np.ndarray, rel_s: np.ndarray, start: float, dur: float, missing: Optional[float] = float("nan")
                  ) -> Dict[str, Optional[float]]:
    """The errors ``e`` [m] at the keyframes (``rel_s``: seconds from the first IMU sample) inside one
    outage or gap: its RMS, maximum and the last one inside it (``end_m``: the error when the aiding
    returns, the GNSS/INS peers' figure); ``missing`` where no keyframe lies inside."""
    m = in_windows(rel_s, [(start, dur)])
    if not m.any():
        return {"start_s": float(start), "duration_s": float(dur), "rmse_m": missing, "max_m": missing, "end_m": missing}
    return {"start_s": float(start), "duration_s": float(dur), "rmse_m": rmse(e[m]), "max_m": float(e[m].max()),
            "end_m": float(e[m][-1])}


def score(res: FusionResult, t_ns: np.ndarray, p_gt: np.ndarray, q_wxyz_gt: np.ndarray,
          outages: Seq[Tuple[float, float]] = (), align: bool = False) -> Dict[str, object]:
    """``{causal|smoothed: {pos_rmse_m, rot_rmse_deg, outages: [{start_s, duration_s, rmse_m, max_m, end_m}]}}``;
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
        per = [window_errors(e, rel_s, start, dur) for start, dur in outages]
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


def score_online(res, t_ns: np.ndarray, p_gt: np.ndarray, q_wxyz_gt: np.ndarray,
                 outages: Sequence[Tuple[float, float]] = (), first: int = 0, align: bool = False) -> Dict[str, object]:
    """The causal scores of :func:`imu_learn.fuse.score.score` (position and rotation RMSE at the
    keyframes, drift in each outage), plus the position RMSE of the causal state at every sample;
    from sample ``first`` on (a data start's alignment window is not scored), SE(3)-aligned first
    with ``align`` (relative aiding started from the data; the per-sample RMSE is then left out)."""
    s = dict(score(crop(res.as_fusion_result(), 0, first), t_ns, p_gt, q_wxyz_gt, outages, align=align)["causal"])
    if not align:
        s["pos_rmse_every_sample_m"] = float(np.sqrt(np.mean(np.sum((res.p[first:] - p_gt[first:]) ** 2, axis=1))))
    return s


def error_stats(e: np.ndarray) -> Dict[str, float]:
    """RMS, maximum and last of the errors ``e`` [m] (NaN when there are none), and their number."""
    if len(e) == 0:
        return {"rms_m": float("nan"), "max_m": float("nan"), "end_m": float("nan"), "n": 0}
    return {"rms_m": float(np.sqrt(np.mean(e ** 2))), "max_m": float(e.max()), "end_m": float(e[-1]), "n": int(len(e))}


def interpolate_groundtruth(gt, t_ns: np.ndarray):
    """Ground truth at ``t_ns`` inside its span: (mask of stamps inside, p (M, 3), R (M, 3, 3))."""
    g_t = np.asarray(gt.t_ns, dtype=np.int64)
    inside = (t_ns >= g_t[0]) & (t_ns <= g_t[-1])
    t = t_ns[inside]
    x = (t - g_t[0]).astype(np.float64)
    xp = (g_t - g_t[0]).astype(np.float64)
    p = np.stack([np.interp(x, xp, gt.p[:, k]) for k in range(3)], axis=1)
    q = np.asarray(gt.q_wxyz)[:, [1, 2, 3, 0]]
    R = Slerp(xp, Rotation.from_quat(q))(x).as_matrix()
    return inside, p, R


def _errors(p_est, R_est, p_gt, R_gt, align: bool, R_al=None, t_al=None):
    if align and R_al is None:
        R_al, t_al = umeyama(p_est, p_gt)
    if not align:
        R_al, t_al = np.eye(3), np.zeros(3)
    p = p_est @ R_al.T + t_al
    e = np.linalg.norm(p - p_gt, axis=1)
    out = {"pos_rmse_m": float(np.sqrt(np.mean(e ** 2))), "pos_max_m": float(e.max()), "n": int(len(e))}
    if R_est is not None:
        dR = Rotation.from_matrix(np.einsum("nki,nkj->nij", R_gt, np.einsum("ij,njk->nik", R_al, R_est)))
        out["rot_rmse_deg"] = float(np.rad2deg(np.sqrt(np.mean(dR.magnitude() ** 2))))
    return out, e, R_al, t_al


def read_truth(path: Path):
    """``--groundtruth`` as navigate reads it: a Fetch recording's motion capture by its header
    (:func:`imu_learn.data.formats.fetch.read_mocap`), else a TUM file or an ASL CSV."""
    return fetch.read_mocap(Path(path)) if fetch.is_mocap_file(Path(path)) else read_groundtruth(Path(path))


def score_against(groundtruth: Path, kf_t: np.ndarray, res, rows, R_WA: np.ndarray, t0_ns: int, align: bool,
                  gaps: Seq[Tuple[float, float]] = ()) -> Dict[str, object]:
    """Position (and rotation) RMSE of the causal and smoothed trajectories of a navigated recording
    (``res``, at keyframe stamps ``kf_t``), and of its aiding ``rows`` alone (their world rotated into
    the navigation frame by ``R_WA``), against the ``groundtruth`` file interpolated at their stamps;
    after a rigid SE(3) alignment (Umeyama, no scale: ``evo_ape -a``) with ``align``, else as they are;
    plus the error inside each gap (``gaps``: seconds from ``t0_ns``, the first IMU sample)."""
    gt = read_truth(Path(groundtruth))
    inside, p_gt, R_gt = interpolate_groundtruth(gt, kf_t)
    if inside.sum() < 3:
        raise AidingError(f"{groundtruth}: fewer than 3 keyframes inside the ground truth's time span", str(groundtruth))
    out: Dict[str, object] = {"aligned": align, "alignment": "SE(3) Umeyama, no scale (evo_ape -a)" if align else "none"}
    rel_s = (kf_t[inside] - t0_ns) * 1e-9
    in_gap = in_windows(rel_s, gaps)
    for kind, p, R in (("causal", res.causal_p, res.causal_R), ("smoothed", res.smoothed_p, res.smoothed_R)):
        s, e, _, _ = _errors(p[inside], R[inside], p_gt, R_gt, align)
        if gaps:
            s["gaps"] = [window_errors(e, rel_s, a, d, missing=None) for a, d in gaps]
            s["outside_gaps_rmse_m"] = float(np.sqrt(np.mean(e[~in_gap] ** 2))) if (~in_gap).any() else None
        out[kind] = s
    # the aiding alone (its body positions, in W) at its own stamps, aligned the same way
    a_in, a_p_gt, a_R_gt = interpolate_groundtruth(gt, rows.t_ns)
    if a_in.sum() >= 3:
        p_a = (rows.p @ R_WA.T)[a_in]
        R_a = None if rows.R is None else np.einsum("ij,njk->nik", R_WA, rows.R)[a_in]
        out["aiding_only"], _, _, _ = _errors(p_a, R_a, a_p_gt, a_R_gt, align)
        # the fused trajectories at the same stamps (the aiding's samples are keyframes)
        pos = {int(t): k for k, t in enumerate(kf_t)}
        ks = np.array([pos[int(t)] for t in rows.imu_t_ns[a_in] if int(t) in pos])
        if len(ks) >= 3:
            for kind, p, R in (("causal", res.causal_p, res.causal_R), ("smoothed", res.smoothed_p, res.smoothed_R)):
                gi, gp, gR = interpolate_groundtruth(gt, kf_t[ks])
                out[f"{kind}_at_aiding_stamps"], _, _, _ = _errors(p[ks][gi], R[ks][gi], gp, gR, align)
            out["against_aiding"] = against_aiding(out)
    return out


WORSE_THAN_AIDING = 0.01  # a fused track more than 1 % above the aiding alone at its stamps is said
AIDING_IS_TRUTH_M = 1e-4  # an aiding this close to the ground truth is the ground truth: no ratio to it


def against_aiding(scores: Dict[str, object]) -> Dict[str, object]:
    """Each fused track's position RMSE at the aiding's stamps over the aiding's alone, and the tracks
    above it by more than :data:`WORSE_THAN_AIDING` (fusion made the aiding's positions worse there); none
    where the aiding is the ground truth (within :data:`AIDING_IS_TRUTH_M`: every track is above it)."""
    alone = float(scores["aiding_only"]["pos_rmse_m"])
    if not alone > AIDING_IS_TRUTH_M:
        return {"ratio": None, "worse": [], "why": f"the aiding is the ground truth ({alone:.2g} m alone): no ratio"}
    ratios = {k: float(scores[f"{k}_at_aiding_stamps"]["pos_rmse_m"]) / alone for k in ("causal", "smoothed")}
    return {"ratio": ratios, "worse": [k for k, r in ratios.items() if r > 1 + WORSE_THAN_AIDING]}


def score_against_fixes(fixes, kf_t: np.ndarray, res, lever: np.ndarray, origin_llh: Seq[float], t0_ns: int,
                        gaps: Sequence[Tuple[float, float]] = ()) -> Dict[str, object]:
    """Position errors of the causal and smoothed tracks of a GNSS-aided run against RTK-fixed positions
    (``fixes``: an :class:`~.aiding.rtklib.RtkSolution`, Q = 1 rows only): each track's antenna (the body
    position plus its attitude times ``lever``) linearly interpolated at the fixes' stamps, in the run's ENU
    frame at ``origin_llh`` (no alignment: one world); 3-D and horizontal RMSE, and inside each ``--gaps``
    window (``gaps``: seconds from ``t0_ns``, the first IMU sample) its RMSE, maximum and the error when the
    aiding returns, at the fixes the run withheld there, 3-D and (``horizontal``) in east-north, the GNSS/INS
    peers' figure."""
    fixed = np.asarray(fixes.q) == 1
    t = np.asarray(fixes.t_ns, dtype=np.int64)[fixed]
    p_gt = llh_to_enu(enu_to_llh(np.asarray(fixes.enu)[fixed], fixes.origin_llh), origin_llh)
    inside = (t >= kf_t[0]) & (t <= kf_t[-1])
    if inside.sum() < 3:
        raise AidingError(f"{fixes.path}: fewer than 3 RTK-fixed rows (Q = 1) inside the run's time span",
                          str(fixes.path))
    t, p_gt = t[inside], p_gt[inside]
    x, xq = (kf_t - kf_t[0]) * 1e-9, (t - kf_t[0]) * 1e-9
    nearest = np.clip(np.searchsorted(kf_t, t), 0, len(kf_t) - 1)
    rel_s = (t - t0_ns) * 1e-9
    out: Dict[str, object] = {"aligned": False, "alignment": "none (the run's ENU frame)",
                              "truth": f"RTK-fixed rows (Q = 1) of {fixes.path}: {int(inside.sum())} inside the run",
                              "at": "the antenna (the track's body position + its attitude x the lever arm)"}
    for kind, p, R in (("causal", res.causal_p, res.causal_R), ("smoothed", res.smoothed_p, res.smoothed_R)):
        ant = np.stack([np.interp(xq, x, p[:, k]) for k in range(3)], axis=1) + R[nearest] @ np.asarray(lever, float)
        d = ant - p_gt
        e = np.linalg.norm(d, axis=1)
        s: Dict[str, object] = {"pos_rmse_m": rmse(e), "horizontal_rmse_m": rmse(np.linalg.norm(d[:, :2], axis=1))}
        if gaps:
            e_h = np.linalg.norm(d[:, :2], axis=1)
            s["gaps"] = [{**window_errors(e, rel_s, a, g, missing=None),
                          "horizontal": {k: v for k, v in window_errors(e_h, rel_s, a, g, missing=None).items()
                                         if k.endswith("_m")}} for a, g in gaps]
            m = in_windows(rel_s, gaps)
            s["outside_gaps_rmse_m"] = rmse(e[~m]) if (~m).any() else None
        out[kind] = s
    return out
