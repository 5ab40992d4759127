"""Evaluation: relative pose error of IMU dead reckoning over n samples, and start-up bias fitting.

Relative pose error over n IMU samples. For each window start k (every ``stride`` samples), start
from the ground-truth state (p_k, v_k, R_k) and integrate the IMU samples k..k+n-1 (the core's
``integrate_windows``: zero-order hold, exact SO(3) exponential) to the state at k+n::

    R̂ = R_k Δq
    p̂ = p_k + v_k Δt + ½ g Δt² + R_k Δγ          g = [0, 0, -gravity]

rotation error = angle of R_{k+n}ᵀ R̂ [rad, also reported in deg]; translation error = |p̂ − p_{k+n}|
[m]. The reported number is the RMSE over windows. To evaluate a refined (or bias-corrected) IMU,
put its gyro/acc into the sequence with :func:`with_imu`; ground truth stays the same.

Start-up bias (:func:`fit_startup_bias`): a constant gyro and accelerometer bias fitted on the first
``seconds`` of a sequence against its ground truth, as an estimator's initialisation would:
Gauss–Newton over short windows (``window_s`` long, overlapping by ¾), first the gyro bias from the
rotation residuals Log(Δq̂(b_g)⁻¹ Δq_gt), then the accelerometer bias from the velocity residuals
Δβ_gt − Δβ̂(b_g, b_a). The rotations do not depend on b_a, so the gyro bias is fitted once; Δβ̂ is
linear in b_a (Δβ̂ = Σ R_k (a_k − b_a) dt_k with R_k fixed by b_g), so its least squares is solved in
one step. The gyro's Jacobian is exact (the core's rotation window sums: the same zero-order hold and
exponential as the metric's integration), the accelerometer's the differences of that integration at
unit biases (exact: linear), so the fit is consistent with the metric. Apply with :func:`remove_bias` (subtraction).
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np

from imu_learn.core.integration import Increments, integrate_windows, preintegrate, rotation_window_sums, window_labels
from imu_learn.core.quat import quat_conj, quat_log, quat_mul, quat_rotate, so3_right_jacobian_inverse
from imu_learn.data.types import Segment
from imu_learn.errors import InvalidInputError
from imu_learn.score.protocol import VARIANTS

GRAVITY = 9.81


def _angle(q_wxyz: np.ndarray) -> np.ndarray:
    return np.linalg.norm(quat_log(q_wxyz), axis=-1)


def rmse(x: np.ndarray) -> float:
    """Root mean square of a 1-D array of errors (nan for none)."""
    x = np.asarray(x, dtype=np.float64)
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def with_imu(seq: Segment, gyro: np.ndarray, acc: np.ndarray, name: Optional[str] = None) -> Segment:
    """The same sequence (ground truth, stamps) with its gyro/acc replaced."""
    gyro = np.ascontiguousarray(gyro, dtype=np.float64)
    acc = np.ascontiguousarray(acc, dtype=np.float64)
    if gyro.shape != seq.gyro.shape or acc.shape != seq.acc.shape:
        raise InvalidInputError(f"gyro/acc of shape {gyro.shape}/{acc.shape} do not match the sequence's {seq.gyro.shape}")
    return Segment(seq.name if name is None else name, seq.t_ns, gyro, acc, seq.p, seq.v, seq.q_wxyz)


def remove_bias(seq: Segment, gyro_bias: np.ndarray, acc_bias: np.ndarray) -> Segment:
    """``seq`` with a constant bias subtracted from its gyro and accelerometer."""
    return with_imu(seq, seq.gyro - np.asarray(gyro_bias)[None], seq.acc - np.asarray(acc_bias)[None])


def index_at(seq: Segment, seconds: float) -> int:
    """First sample index at or after ``seconds`` from the sequence start."""
    return int(np.searchsorted(seq.t_ns, seq.t_ns[0] + int(round(seconds * 1e9))))


def relative_pose_errors(
    seq: Segment, n: int, stride: int = 1, gravity: float = GRAVITY, first: int = 0, last: Optional[int] = None,
    pre: Optional[Increments] = None,
) -> Dict[str, np.ndarray]:
    """Per-window errors of dead reckoning over ``n`` samples from the ground-truth state.

    Windows start at first, first+stride, ... with k + n <= last (default the last sample).
    Returns ``starts``, ``rot_rad`` and ``trans_m`` (one entry per window). Each window's increments
    are composed from the recording's cumulative ones (:func:`window_increments`); ``pre``: the
    :func:`~imu_learn.core.integration.preintegrate` of ``seq``'s IMU when already computed.
    """
    if n < 1 or stride < 1:
        raise InvalidInputError(f"n = {n} and stride = {stride} must be at least 1")
    last = len(seq) - 1 if last is None else min(int(last), len(seq) - 1)
    starts = np.arange(int(first), last - n + 1, int(stride), dtype=np.uint64)
    if starts.size == 0:
        return {"starts": starts, "rot_rad": np.zeros(0), "trans_m": np.zeros(0)}
    k = starts.astype(np.int64)
    j = k + n
    dq, dp, dt = window_increments(preintegrate(seq.t_ns, seq.gyro, seq.acc) if pre is None else pre, k, j)
    g = np.array([0.0, 0.0, -gravity])
    q_k = seq.q_wxyz[k]
    q_hat = quat_mul(q_k, dq)
    rot = _angle(quat_mul(quat_conj(seq.q_wxyz[j]), q_hat))
    p_hat = seq.p[k] + seq.v[k] * dt[:, None] + 0.5 * g[None] * (dt * dt)[:, None] + quat_rotate(q_k, dp)
    trans = np.linalg.norm(p_hat - seq.p[j], axis=-1)
    return {"starts": starts, "rot_rad": rot, "trans_m": trans}


def window_increments(pre: Increments, k: np.ndarray, j: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Δq (M, 4), Δγ (M, 3), Δt (M,)) of the IMU over samples k..j-1 for each pair, composed from the
    recording's cumulative increments ``pre`` (:func:`~imu_learn.core.integration.preintegrate`):
    Δq_kj = q_kᵀ q_j, Δγ_kj = R_kᵀ (γ_j − γ_k − β_k Δt_kj); the same sums the core's ``integrate_windows``
    runs window by window (to 1e-10 m on a 100 s flight), in one pass over the recording instead of one
    per window."""
    qk = quat_conj(pre.dq_wxyz[k])
    dt = pre.dt[j] - pre.dt[k]
    return quat_mul(qk, pre.dq_wxyz[j]), quat_rotate(qk, pre.dp[j] - pre.dp[k] - pre.dv[k] * dt[:, None]), dt


def relative_pose_rmse(
    seq: Segment, n: int, stride: int = 1, gravity: float = GRAVITY, first: int = 0, last: Optional[int] = None
) -> Dict[str, float]:
    """RMSE of :func:`relative_pose_errors`: ``rot_rad``, ``rot_deg``, ``trans_m``, ``windows``."""
    e = relative_pose_errors(seq, n, stride, gravity, first, last)
    r = rmse(e["rot_rad"])
    return {"rot_rad": r, "rot_deg": math.degrees(r), "trans_m": rmse(e["trans_m"]), "windows": int(e["starts"].size)}


def relative_pose_rmse_many(seqs: Seq[Segment], n: int, stride: int = 1, gravity: float = GRAVITY,
                            first_s: float = 0.0) -> Dict[str, float]:
    """RMSE pooled over the windows of several sequences (each from ``first_s`` seconds in)."""
    rots, trans = [], []
    for s in seqs:
        e = relative_pose_errors(s, n, stride, gravity, first=index_at(s, first_s))
        rots.append(e["rot_rad"])
        trans.append(e["trans_m"])
    r = rmse(np.concatenate(rots)) if rots else float("nan")
    return {"rot_rad": r, "rot_deg": math.degrees(r), "trans_m": rmse(np.concatenate(trans)) if trans else float("nan"),
            "windows": int(sum(len(x) for x in rots))}


# ---------------------------------------------------------------------------------------------
# start-up bias


def _velocity_residuals(seq: Segment, starts: np.ndarray, n: int, labels, bg: np.ndarray, ba: np.ndarray) -> np.ndarray:
    """Δβ_gt − Δβ̂(b_g, b_a) over the windows, flattened."""
    inc = integrate_windows(remove_bias(seq, bg, ba), starts, np.array([n], dtype=np.uint64))
    return (labels.dv[:, 0] - inc.dv[:, 0]).reshape(-1)


def _startup_gyro_bias(seq: Segment, starts: np.ndarray, n: int, labels, iters: int = 10, tol: float = 1e-9
                       ) -> np.ndarray:
    """The gyro bias minimising the rotation residuals Log(Δq̂(b)⁻¹ Δq_gt), Gauss-Newton on their exact
    Jacobian: the core's :func:`rotation_window_sums` (rates g - b) gives Q = Δq̂ and A = Σ_k R(Q_k) J_r(φ_k) dt_k;
    a bias step δ turns Q into Exp(-A δ) Q, so r = Log(Q⁻¹ Δq) moves by J_l⁻¹(r) R(Q)ᵀ A δ (J_l⁻¹(r) = J_r⁻¹(-r))."""
    k = starts.astype(np.int64)[:, None] + np.arange(n)
    gyro, acc = seq.gyro[k], seq.acc[k]
    dt = (np.diff(np.asarray(seq.t_ns, dtype=np.int64)) * 1e-9)[k]
    dq = labels.dq_wxyz[:, 0]
    theta = np.zeros(21)  # (M_g - I, b_g, G): the bias alone
    for _ in range(iters):
        d = rotation_window_sums(gyro, acc, dt, theta, (n,), True)
        Q = d["q_wxyz"][:, 0]
        A = d["sums"][:, 0, :, 6].reshape(-1, 3, 3)  # type: ignore[index]
        r = quat_log(quat_mul(quat_conj(Q), dq))
        RtA = np.swapaxes(quat_rotate(quat_conj(Q)[:, None, :], np.swapaxes(A, 1, 2)), 1, 2)
        J = so3_right_jacobian_inverse(-r) @ RtA
        step, *_ = np.linalg.lstsq(J.reshape(-1, 3), -r.reshape(-1), rcond=None)
        theta[9:12] += step
        if np.max(np.abs(step)) < tol:
            break
    return theta[9:12].copy()


def fit_startup_bias(
    seq: Segment,
    seconds: float = 10.0,
    window_s: float = 1.0,
    gravity: float = GRAVITY,
) -> Tuple[np.ndarray, np.ndarray]:
    """Constant (gyro_bias [rad/s], acc_bias [m/s²]) fitted on the first ``seconds`` against ground
    truth, by least squares through the integration over ``window_s`` windows (see module doc)."""
    m = index_at(seq, seconds) + 1
    sub = Segment(seq.name, seq.t_ns[:m], seq.gyro[:m], seq.acc[:m], seq.p[:m], seq.v[:m], seq.q_wxyz[:m])
    if len(sub) < 3:
        raise InvalidInputError(f"{seq.name}: fewer than 3 samples in the first {seconds} s")
    rate = (len(sub) - 1) / max(sub.duration_s, 1e-9)
    n = int(min(max(2, round(window_s * rate)), len(sub) - 1))
    stride = max(1, n // 4)
    labels = window_labels(sub, n, stride, fractions=(1.0,), gravity=gravity)
    starts = np.asarray(labels.starts, dtype=np.uint64)
    bg = _startup_gyro_bias(sub, starts, n, labels)
    # Δβ̂ is linear in b_a: residuals at 0 and at each unit bias give the exact Jacobian, one solve
    r0 = _velocity_residuals(sub, starts, n, labels, bg, np.zeros(3))
    J = np.column_stack([_velocity_residuals(sub, starts, n, labels, bg, e) - r0 for e in np.eye(3)])
    ba, *_ = np.linalg.lstsq(J, -r0, rcond=None)
    return bg, ba


# ---------------------------------------------------------------------------------------------
# synthetic trajectories (tests, sanity checks)


def without_fitted_bias(
    seqs: Seq[Segment], seconds: Optional[float] = None, gravity: float = GRAVITY,
) -> Tuple[List[Segment], Dict[str, Dict[str, list]]]:
    """Each sequence with its own constant bias (:func:`fit_startup_bias` on its first ``seconds``;
    None: the whole sequence) subtracted, and the biases by sequence name."""
    fixed, biases = [], {}
    for s in seqs:
        bg, ba = fit_startup_bias(s, s.duration_s + 1.0 if seconds is None else seconds, gravity=gravity)
        biases[s.name] = {"gyro": bg.tolist(), "acc": ba.tolist()}
        fixed.append(remove_bias(s, bg, ba))
    return fixed, biases


def variant_table(seqs: Seq[Segment], fixed: Seq[Segment], horizons: Seq[int], stride: int,
                  startup_bias_s: float, gravity: float = GRAVITY) -> Dict[str, Dict[str, Dict[str, float]]]:
    """The final table's cells: ``{variant: {str(n): relative_pose_rmse_many(...)}}`` for the two
    variants of :data:`imu_learn.score.protocol.VARIANTS`, open loop (``seqs``) and start-up bias
    removed (``fixed``, from :func:`without_fitted_bias`), windows every ``stride`` samples from
    ``startup_bias_s`` seconds on."""
    return {variant: {str(int(n)): relative_pose_rmse_many(ss, int(n), stride, gravity, first_s=startup_bias_s)
                      for n in horizons}
            for variant, ss in zip(VARIANTS, (seqs, fixed))}


def floor_ratios(rows: Dict[str, Dict[str, Dict[str, Dict[str, float]]]], floors: Seq[str],
                 model: str) -> Dict[str, Dict[str, Dict[str, Any]]]:
    """The ``model`` row judged against the best of the ``floors`` rows (e.g. raw and timing) of a
    :func:`variant_table`-shaped ``rows`` ({row: {variant: {n: cell}}}), cell by cell:
    ``{variant: {n: {"rot": ratio, "rot_floor": row, "trans": ratio, "trans_floor": row}}}``, each
    ratio the model's RMSE over the lowest floor RMSE of that cell (below 1: the model beats every
    floor), rotation and translation separately."""
    out: Dict[str, Dict[str, Dict[str, Any]]] = {}
    for variant, by_n in rows[model].items():
        for n, cell in by_n.items():
            got: Dict[str, Any] = {}
            for key, col in (("rot", "rot_deg"), ("trans", "trans_m")):
                best = min(floors, key=lambda f: rows[f][variant][n][col])
                got[key] = cell[col] / max(rows[best][variant][n][col], 1e-300)
                got[key + "_floor"] = best
            out.setdefault(variant, {})[n] = got
    return out


def simulate_sequence(
    t_ns: np.ndarray,
    gyro: np.ndarray,
    acc: np.ndarray,
    q0_wxyz: Seq[float] = (1.0, 0.0, 0.0, 0.0),
    v0: Seq[float] = (0.0, 0.0, 0.0),
    p0: Seq[float] = (0.0, 0.0, 0.0),
    gravity: float = GRAVITY,
    name: str = "synthetic",
) -> Segment:
    """The trajectory whose exact IMU signal (under the core's zero-order-hold integration) is
    ``gyro``/``acc``: ground truth from preintegration of the whole record from the initial state."""
    inc = preintegrate(t_ns, gyro, acc)
    q0 = np.broadcast_to(np.asarray(q0_wxyz, dtype=np.float64), inc.dq_wxyz.shape)
    tt = inc.dt[:, None]
    g = np.array([0.0, 0.0, -gravity])
    q = quat_mul(q0, inc.dq_wxyz)
    v = np.asarray(v0)[None] + g[None] * tt + quat_rotate(q0, inc.dv)
    p = np.asarray(p0)[None] + np.asarray(v0)[None] * tt + 0.5 * g[None] * tt * tt + quat_rotate(q0, inc.dp)
    return Segment(name, np.ascontiguousarray(t_ns, dtype=np.int64), np.asarray(gyro, dtype=np.float64),
                    np.asarray(acc, dtype=np.float64), p, v, q)
