"""Is a covariance honest? Calibration of the increments' covariance on held-out data.

For windows of n samples started at ground truth, the residual r = (δθ, δβ, δγ) between the ground
truth increments and those integrated from the IMU (the convention of
:mod:`imu_learn.nn.covariance`: δθ = Log(Δq_true Δq̂⁻¹) in the window's start frame) is compared
with the covariance Σ propagated from per-sample noise variances: the datasheet's white noise
(σ² = density²/dt for every sample) or a refiner's covariance head.

The normalised estimation error squared NEES = rᵀ Σ⁻¹ r of a calibrated k-dimensional Gaussian
is χ²(k): its mean is k and a fraction ``chi2.cdf(m², k)`` of the windows lies inside the mσ
ellipsoid (NEES ≤ m²). Reported for the whole 9-vector and for each 3-vector block on its own
(rotation, velocity, position: each with its own marginal covariance). A mean NEES far above k
means the covariance is overconfident, far below k underconfident.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List

import numpy as np
import torch
from scipy.stats import chi2

from imu_learn.core.covariance import increment_covariance
from imu_learn.core.integration import integrate_windows, window_labels
from imu_learn.core.quat import quat_conj, quat_mul, wxyz_to_xyzw
from imu_learn.data.types import Segment
from imu_learn.infer.refiner import refine_with_variance
from imu_learn.score.metrics import fit_startup_bias, index_at, remove_bias, with_imu

SIGMAS = (1, 2, 3)
BLOCKS = {"all": slice(0, 9), "rot": slice(0, 3), "vel": slice(3, 6), "pos": slice(6, 9)}


def nees(r: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """rᵀ Σ⁻¹ r for r (M, k) and Σ (M, k, k), by Cholesky in float64 (NaN where Σ is not positive
    definite)."""
    r = np.asarray(r, dtype=np.float64)
    cov = np.asarray(cov, dtype=np.float64)
    L, info = torch.linalg.cholesky_ex(torch.tensor(cov))
    z = torch.linalg.solve_triangular(L, torch.tensor(r)[..., None], upper=False)[..., 0].numpy()
    out = (z * z).sum(-1)
    out[info.numpy() != 0] = np.nan
    return out


def expected_fraction(m: float, dof: int) -> float:
    """P(χ²(dof) ≤ m²): the fraction of a calibrated Gaussian inside its mσ ellipsoid."""
    return float(chi2.cdf(m * m, dof))


def nees_blocks(r: np.ndarray, cov: np.ndarray) -> Dict[str, np.ndarray]:
    """NEES per window for the whole 9-vector ("all") and each 3-vector block on its own marginal."""
    return {name: nees(r[:, b], cov[:, b, b]) for name, b in BLOCKS.items()}


def summarise_nees(blocks: Dict[str, np.ndarray]) -> Dict[str, Dict[str, float]]:
    """Per block: mean and median NEES, the χ² median (dof), the fraction inside the 1σ/2σ/3σ
    ellipsoids and their χ² expectations. Windows whose Σ is not positive definite are left out."""
    out: Dict[str, Dict[str, float]] = {}
    for name, e in blocks.items():
        e = e[np.isfinite(e)]
        dof = BLOCKS[name].stop - BLOCKS[name].start
        row: Dict[str, float] = {"windows": int(e.size), "dof": dof,
                                 "mean_nees": float(e.mean()) if e.size else float("nan"),
                                 "median_nees": float(np.median(e)) if e.size else float("nan"),
                                 "median_expected": float(chi2.median(dof))}
        for m in SIGMAS:
            row[f"in_{m}sigma"] = float((e <= m * m).mean()) if e.size else float("nan")
            row[f"expected_{m}sigma"] = expected_fraction(m, dof)
        out[name] = row
    return out


def summarise(r: np.ndarray, cov: np.ndarray) -> Dict[str, Dict[str, float]]:
    """:func:`summarise_nees` of r (M, 9) under Σ (M, 9, 9)."""
    return summarise_nees(nees_blocks(r, cov))


@dataclass
class Residuals:
    """r (M, 9) for M windows of n samples, and the IMU (gyro, acc) that was integrated."""

    r: np.ndarray
    starts: np.ndarray
    n: int


def residuals(seq: Segment, gyro: np.ndarray, acc: np.ndarray, starts: np.ndarray, n: int,
              gravity: float = 9.81) -> Residuals:
    """Ground truth minus IMU increments over n samples from each start, as (δθ, δβ, δγ) (M, 9)."""
    from scipy.spatial.transform import Rotation

    starts = np.asarray(starts, dtype=np.uint64)
    imu = Segment(seq.name, seq.t_ns, np.ascontiguousarray(gyro), np.ascontiguousarray(acc), seq.p, seq.v, seq.q_wxyz)
    est = integrate_windows(imu, starts, np.array([n], dtype=np.uint64))
    gt = _labels_at(seq, starts, n, gravity)
    dq = quat_mul(gt.dq_wxyz, quat_conj(est.dq_wxyz[:, 0]))
    r_q = Rotation.from_quat(wxyz_to_xyzw(dq)).as_rotvec()
    r = np.concatenate([r_q, gt.dv - est.dv[:, 0], gt.dp - est.dp[:, 0]], axis=1)
    return Residuals(r, starts.astype(np.int64), n)


@dataclass
class _Labels:
    dq_wxyz: np.ndarray
    dv: np.ndarray
    dp: np.ndarray


def _labels_at(seq: Segment, starts: np.ndarray, n: int, gravity: float) -> _Labels:
    """Ground-truth increments of the windows [s, s + n] (window_labels at stride 1, picked)."""
    lab = window_labels(seq, n, 1, [1.0], gravity)
    idx = np.searchsorted(lab.starts, starts)
    if np.any(idx >= len(lab.starts)) or np.any(lab.starts[np.minimum(idx, len(lab.starts) - 1)] != starts):
        raise ValueError(f"{seq.name}: a window of {n} samples does not fit at every start")
    return _Labels(lab.dq_wxyz[idx, 0], lab.dv[idx, 0], lab.dp[idx, 0])


def window_covariances(seq: Segment, gyro: np.ndarray, acc: np.ndarray, var: np.ndarray, starts: np.ndarray,
                       n: int) -> np.ndarray:
    """Σ (M, 9, 9) of each window's increments under per-sample variances ``var`` (N, 6), float64,
    by imu_core's propagation (:func:`imu_learn.core.covariance.increment_covariance`), one window at a time
    (each costs O(n), so windows of 20 s are as cheap per sample as those of 50 ms)."""
    g = np.ascontiguousarray(gyro, dtype=np.float64)
    a = np.ascontiguousarray(acc, dtype=np.float64)
    v = np.ascontiguousarray(var, dtype=np.float64)
    out = np.empty((len(starts), 9, 9))
    for i, s in enumerate(np.asarray(starts, dtype=np.int64)):
        e = int(s) + int(n) + 1
        out[i] = increment_covariance(seq.t_ns[s:e], g[s:e], a[s:e], v[s:e], [int(n)])[0]
    return out


def datasheet_variances(t_ns: np.ndarray, gyro_noise_density: float, acc_noise_density: float) -> np.ndarray:
    """Per-sample variances (N, 6) of a white-noise datasheet: σ² = density² / dt (the last sample
    reuses the previous dt)."""
    dt = np.diff(np.asarray(t_ns, dtype=np.int64)).astype(np.float64) * 1e-9
    dt = np.r_[dt, dt[-1:]] if len(dt) else np.ones(len(t_ns))
    return np.concatenate([np.repeat((gyro_noise_density ** 2 / dt)[:, None], 3, 1),
                           np.repeat((acc_noise_density ** 2 / dt)[:, None], 3, 1)], axis=1)


def calibrate(seq: Segment, gyro: np.ndarray, acc: np.ndarray, var: np.ndarray, starts: np.ndarray, n: int,
              gravity: float = 9.81) -> Dict[str, np.ndarray]:
    """NEES per block (:func:`nees_blocks`) of the windows of n samples at ``starts`` for the IMU
    (gyro, acc) with per-sample variances ``var``."""
    res = residuals(seq, gyro, acc, starts, n, gravity)
    return nees_blocks(res.r, window_covariances(seq, gyro, acc, var, starts, n))


def format_table(rows: List[Dict[str, object]]) -> List[str]:
    """Markdown table of calibration rows ({sequence, input, covariance, n, summary})."""
    head = ["sequence", "IMU", "covariance", "n", "block", "windows", "mean NEES (dof)",
            "in 1σ (χ²)", "in 2σ (χ²)", "in 3σ (χ²)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        for block in BLOCKS:
            s = row["summary"][block]  # type: ignore[index]
            cells = [str(row["sequence"]), str(row["input"]), str(row["covariance"]), str(row["n"]), block,
                     str(s["windows"]), f"{s['mean_nees']:.3g} ({s['dof']})"]
            cells += [f"{s[f'in_{m}sigma']:.3f} ({s[f'expected_{m}sigma']:.3f})" for m in SIGMAS]
            lines.append("| " + " | ".join(cells) + " |")
    return lines


def evaluate_calibration(model, seqs: List[Segment], horizons: List[int], stride: int, startup_bias_s: float,
                         gyro_noise_density: float, acc_noise_density: float, gravity: float = 9.81,
                         ) -> List[Dict[str, object]]:
    """The calibration rows of the evaluation report: raw IMU and ``model``'s refined IMU, each with
    its start-up bias removed (fitted on the first ``startup_bias_s``, windows start after it, as
    in the relative pose table), under the datasheet's white noise, under the model's learned
    per-sample variances, and under their mean over the sequence per channel ("learned mean": a
    constant noise level, which separates how well the head tracks the motion from its overall
    scale); per test sequence and pooled over all of them ("all test")."""
    pooled: Dict[tuple, Dict[str, List[np.ndarray]]] = {}
    rows: List[Dict[str, object]] = []
    for seq in seqs:
        gyro, acc, learned = refine_with_variance(model, seq.gyro, seq.acc)
        sheet = datasheet_variances(seq.t_ns, gyro_noise_density, acc_noise_density)
        first = index_at(seq, startup_bias_s)
        for name, base in (("raw", seq), ("refined", with_imu(seq, gyro, acc))):
            bg, ba = fit_startup_bias(base, startup_bias_s, gravity=gravity)
            fixed = remove_bias(base, bg, ba)
            flat = np.broadcast_to(learned.mean(0), learned.shape)
            for cov_name, var in (("datasheet", sheet), ("learned", learned), ("learned mean", flat)):
                for n in horizons:
                    starts = np.arange(first, len(seq) - int(n), int(stride), dtype=np.int64)
                    if starts.size == 0:
                        continue
                    blocks = calibrate(seq, fixed.gyro, fixed.acc, var, starts, int(n), gravity)
                    key = (name, cov_name, int(n))
                    for b, e in blocks.items():
                        pooled.setdefault(key, {}).setdefault(b, []).append(e)
                    rows.append({"sequence": seq.name.split("#")[0], "input": name, "covariance": cov_name, "n": int(n),
                                 "summary": summarise_nees(blocks)})
    for (name, cov_name, n), blocks in pooled.items():
        rows.append({"sequence": "all test", "input": name, "covariance": cov_name, "n": n,
                     "summary": summarise_nees({b: np.concatenate(es) for b, es in blocks.items()})})
    return rows
