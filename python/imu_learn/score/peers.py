"""The peers' open-loop protocols: Brossard et al.'s AOE and AirIMU's 1 s ROE / RTE (numpy, no torch).

Open loop means: the samples as they are (no bias removed, nothing fitted on ground truth), integrated
from the ground-truth initial state by the core's zero-order hold (sample i held over [t_i, t_{i+1}),
exact SO(3) exponential; :func:`imu_learn.core.integration.preintegrate` / ``integrate_windows``).
Per gap-free segment of a recording (a :class:`~imu_learn.data.types.Segment`), from its first sample:

* **AOE** (absolute orientation error; Brossard, Bonnabel, Barrau 2020, *Denoising IMU Gyroscopes with
  Deep Learning for Open-Loop Attitude Estimation*): the gyro integrated over the whole segment from the
  ground-truth orientation at its first sample, R̂_j = R_0 ΔR_{0j}; error e_j = angle of R_jᵀ R̂_j at
  every sample j (j = 0 included, where it is 0); AOE = sqrt(mean_j e_j²) (Brossard's definition).
  AirIMU's evaluation code (``evaluation/evaluate_state.py``, key ``AOE``) reports the *mean* of e_j
  instead (its ``O_RMSE`` is the RMSE); that figure is kept as ``aoe_mean_deg`` so that tables quoting
  AirIMU's AOE can be compared like for like.
* **yaw AOE**: the same RMSE of the yaw error ψ_j, defined as the yaw (rotation about the world z axis) of
  the world-frame error rotation E_j = R̂_j R_jᵀ in its z-y-x Euler decomposition E = Rz(ψ) Ry(θ) Rx(φ):
  ψ_j = atan2(E_j[1,0], E_j[0,0]) in (-π, π]. For an error purely about world z, |ψ_j| = e_j.
* **ROE / RTE, RO_RMSE / RP_RMSE** (AirIMU's protocol, Qiu et al. 2023): windows of W = round(rate)
  samples (1 s; rate = 1 / median sample period), non-overlapping and consecutive: starts 0, W, 2W, ...
  while k + W <= N - 1. Each window starts from the ground-truth state (p_k, v_k, R_k) and integrates
  samples k..k+W-1 to the state at k + W::

      R̂ = R_k ΔR        p̂ = p_k + v_k Δt + ½ g Δt² + R_k Δγ        g = [0, 0, -gravity]

  orientation error = angle of R_{k+W}ᵀ R̂, position error = |p̂ − p_{k+W}|. ROE and RTE are the means
  over windows, RO_RMSE and RP_RMSE the root mean squares.

A recording split into several gap-free segments is scored segment by segment, each from its own
ground-truth start, and pooled: AOE over all samples of all segments, the window metrics over all
windows. Angles are reported in degrees, positions in metres.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

import numpy as np

from imu_learn.core.integration import integrate_windows, preintegrate
from imu_learn.core.quat import quat_conj, quat_mul, quat_rotate, rotation_angle
from imu_learn.data.types import Segment, sample_rate_hz

PEER_WINDOW_S = 1.0  # AirIMU's window [s]


def _rotmat(q_wxyz: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions w,x,y,z -> (..., 3, 3) rotation matrices."""
    w, x, y, z = np.moveaxis(np.asarray(q_wxyz, dtype=np.float64), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def open_loop_attitude(seq: Segment, gyro: Optional[np.ndarray] = None) -> np.ndarray:
    """Orientation (N, 4) w,x,y,z of ``gyro`` (default ``seq.gyro``) integrated over the whole segment from
    the ground-truth orientation at its first sample (row 0 is that orientation)."""
    g = seq.gyro if gyro is None else gyro
    inc = preintegrate(seq.t_ns, g, np.zeros_like(np.asarray(g, dtype=np.float64)))
    return quat_mul(np.broadcast_to(seq.q_wxyz[0], inc.dq_wxyz.shape), inc.dq_wxyz)


def yaw_error(q_gt: np.ndarray, q_hat: np.ndarray) -> np.ndarray:
    """Yaw [rad] about the world z axis of E = R̂ Rᵀ (z-y-x Euler), in (-π, π]."""
    e = _rotmat(quat_mul(q_hat, quat_conj(q_gt)))
    return np.arctan2(e[..., 1, 0], e[..., 0, 0])


def attitude_errors(seq: Segment, gyro: Optional[np.ndarray] = None) -> Dict[str, np.ndarray]:
    """Per-sample open-loop errors of one segment: ``angle_rad`` (N,) and ``yaw_rad`` (N,)."""
    q_hat = open_loop_attitude(seq, gyro)
    return {"angle_rad": rotation_angle(seq.q_wxyz, q_hat), "yaw_rad": yaw_error(seq.q_wxyz, q_hat)}


def open_loop_aoe_deg(seqs: List[Segment]) -> float:
    """Open-loop AOE [deg] of ``seqs`` as they are (their gyro): each segment integrated from its first
    ground-truth attitude, the RMSE of the angle error over every sample of every segment."""
    e = np.concatenate([attitude_errors(s)["angle_rad"] for s in seqs]) if seqs else np.zeros(0)
    return math.degrees(float(np.sqrt(np.mean(e * e)))) if len(e) else math.nan


def covered(t_ns: np.ndarray, gt_t_ns: np.ndarray, max_gap_s: float) -> np.ndarray:
    """(N,) bool: IMU stamps ``t_ns`` that lie between two ground-truth stamps ``gt_t_ns`` at most
    ``max_gap_s`` apart (or on one): where interpolated ground truth is measured, not bridged."""
    t = np.asarray(t_ns, dtype=np.int64)
    g = np.asarray(gt_t_ns, dtype=np.int64)
    j = np.searchsorted(g, t, side="left")
    exact = (j < len(g)) & (g[np.minimum(j, len(g) - 1)] == t)
    inside = (j > 0) & (j < len(g))
    lo, hi = g[np.clip(j - 1, 0, len(g) - 1)], g[np.clip(j, 0, len(g) - 1)]
    return exact | (inside & (hi - lo <= int(round(max_gap_s * 1e9))))


def masked_aoe(seq: Segment, gyro: np.ndarray, mask: np.ndarray) -> Dict[str, float]:
    """AOE over a whole recording whose ground truth has gaps (AirIMU's ``--mask``, Brossard's TUM-VI
    protocol): ``seq`` is ONE segment spanning the gaps (ground truth interpolated across them, e.g.
    loaded with a large ``AlignOptions.max_gap_s``), the gyro integrated through the gaps from the first
    sample, the error counted only where ``mask`` (:func:`covered`) says ground truth was measured.
    Returns AOE (RMSE) and the mean error angle [deg], yaw AOE [deg] and the samples counted."""
    m = np.asarray(mask, dtype=bool)
    if m.shape != (len(seq),) or not m[0] or not m.any():
        raise ValueError("masked_aoe: the mask must be (N,) with ground truth at the first sample")
    e = attitude_errors(seq, gyro)
    a, y = e["angle_rad"][m], e["yaw_rad"][m]
    return {"aoe_deg": math.degrees(float(np.sqrt(np.mean(a * a)))), "aoe_mean_deg": math.degrees(float(np.mean(a))),
            "yaw_aoe_deg": math.degrees(float(np.sqrt(np.mean(y * y)))), "samples": int(m.sum()), "bridged": int((~m).sum())}


def window_samples(seq: Segment, seconds: float = PEER_WINDOW_S) -> int:
    """round(seconds · rate) samples, rate = :func:`imu_learn.data.types.sample_rate_hz` (at least 1)."""
    rate = sample_rate_hz(seq.t_ns)
    return max(1, int(round(seconds * rate)))


def peer_window_starts(seq: Segment, w: int) -> np.ndarray:
    """Non-overlapping consecutive window starts 0, w, 2w, ... with k + w <= N - 1."""
    return np.arange(0, len(seq) - int(w), int(w), dtype=np.int64)


def window_errors(seq: Segment, gyro: np.ndarray, acc: np.ndarray, w: int, gravity: float = 9.81,
                  starts: Optional[np.ndarray] = None) -> Dict[str, np.ndarray]:
    """Per-window errors over ``w`` samples from the ground-truth state: ``rot_rad``, ``trans_m``, ``starts``."""
    k = peer_window_starts(seq, w) if starts is None else np.asarray(starts, dtype=np.int64)
    if k.size == 0:
        return {"rot_rad": np.zeros(0), "trans_m": np.zeros(0), "starts": k}
    s = Segment(seq.name, seq.t_ns, np.ascontiguousarray(gyro, dtype=np.float64),
                 np.ascontiguousarray(acc, dtype=np.float64), seq.p, seq.v, seq.q_wxyz)
    inc = integrate_windows(s, k, np.array([int(w)], dtype=np.int64))
    qk, dt = seq.q_wxyz[k], inc.dt[:, 0, None]
    g = np.array([0.0, 0.0, -float(gravity)])
    q_end = quat_mul(qk, inc.dq_wxyz[:, 0])
    p_end = seq.p[k] + seq.v[k] * dt + 0.5 * g * dt**2 + quat_rotate(qk, inc.dp[:, 0])
    j = k + int(w)
    return {"rot_rad": rotation_angle(seq.q_wxyz[j], q_end), "trans_m": np.linalg.norm(p_end - seq.p[j], axis=-1),
            "starts": k}


@dataclass
class PeerErrors:
    """Raw errors of one method on the segments of one recording, pooled by :func:`summarise`.
    ``angle_rad``/``yaw_rad``: per-sample AOE errors (None: the method gives no whole-segment attitude);
    ``rot_rad``/``trans_m``: per-window errors (``trans_m`` None: no position)."""

    angle_rad: Optional[List[np.ndarray]] = field(default_factory=list)
    yaw_rad: Optional[List[np.ndarray]] = field(default_factory=list)
    rot_rad: Optional[List[np.ndarray]] = field(default_factory=list)
    trans_m: Optional[List[np.ndarray]] = field(default_factory=list)
    window: List[int] = field(default_factory=list)
    segments: int = 0


def segment_errors(seq: Segment, gyro: np.ndarray, acc: np.ndarray, gravity: float = 9.81,
                   position: bool = True) -> Dict[str, Any]:
    """All peer errors of one refined (or raw) segment, open loop."""
    w = window_samples(seq)
    att = attitude_errors(seq, gyro)
    win = window_errors(seq, gyro, acc, w, gravity)
    return {"angle_rad": att["angle_rad"], "yaw_rad": att["yaw_rad"], "rot_rad": win["rot_rad"],
            "trans_m": win["trans_m"] if position else None, "window": w}


def add_segment(acc: PeerErrors, seg: Dict[str, Any]) -> None:
    """Pool one segment's errors (from :func:`segment_errors` or a regressor's windows) into ``acc``."""
    acc.segments += 1
    acc.window.append(int(seg["window"]))
    for key in ("angle_rad", "yaw_rad", "rot_rad", "trans_m"):
        x = seg.get(key)
        if x is None or getattr(acc, key) is None:
            setattr(acc, key, None)
        else:
            getattr(acc, key).append(np.asarray(x, dtype=np.float64))


def _rms(xs: Optional[List[np.ndarray]]) -> float:
    if xs is None:
        return float("nan")
    x = np.concatenate(xs) if xs else np.zeros(0)
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def _mean(xs: Optional[List[np.ndarray]]) -> float:
    if xs is None:
        return float("nan")
    x = np.concatenate(xs) if xs else np.zeros(0)
    return float(np.mean(x)) if x.size else float("nan")


def summarise(e: PeerErrors) -> Dict[str, Any]:
    """AOE, yaw AOE [deg]; ROE, RO_RMSE [deg]; RTE, RP_RMSE [m]; nan where the method gives no such output."""
    d = math.degrees
    n_samples = 0 if e.angle_rad is None else int(sum(x.size for x in e.angle_rad))
    n_windows = 0 if e.rot_rad is None else int(sum(x.size for x in e.rot_rad))
    return {"aoe_deg": d(_rms(e.angle_rad)), "aoe_mean_deg": d(_mean(e.angle_rad)), "yaw_aoe_deg": d(_rms(e.yaw_rad)),
            "roe_deg": d(_mean(e.rot_rad)), "ro_rmse_deg": d(_rms(e.rot_rad)),
            "rte_m": _mean(e.trans_m), "rp_rmse_m": _rms(e.trans_m),
            "window_samples": (sorted(set(e.window))[0] if len(set(e.window)) == 1 else -1) if e.window else 0,
            "segments": e.segments, "samples": n_samples, "windows": n_windows}


PEER_KEYS = ("aoe_deg", "aoe_mean_deg", "yaw_aoe_deg", "roe_deg", "ro_rmse_deg", "rte_m", "rp_rmse_m")
