"""Calibrating a covariance head's per-sample variances over the keyframe interval.

A covariance head (``model.covariance = true``) predicts each refined sample's noise variances,
discrete-time, per sample ((rad/s)², (m/s²)²; :mod:`imu_learn.core.covariance`). A factor graph
takes them as white noise and propagates them into each IMU factor's covariance over a keyframe
interval of K samples. If the sample errors are not white (vibration that cancels when integrated),
that propagated covariance is wrong by a factor; this module measures the factor from data.

Method (:func:`interval_residuals`, :func:`scale_from_residuals`): over consecutive intervals of K
samples of an aligned :class:`~imu_learn.data.types.Segment` (stride K, no overlap),

* the residual of the refined samples' preintegrated increments against ground truth's
  (:func:`imu_learn.core.integration.integrate_windows` and :func:`~imu_learn.core.integration.window_labels`,
  gravity removed in the labels): ``δθ = Log(Δq_gt Δq̂⁻¹)`` [rad] (left perturbation, frame of the
  interval's start) and ``δβ = Δβ_gt − Δβ̂`` [m/s];
* the predicted variances: the diagonal of the propagated covariance of (δθ, δβ) under the head's
  per-sample variances (:func:`imu_learn.core.covariance.interval_covariances`, what the graph's
  IMU factor carries);
* each sequence's constant bias removed: the mean residual per axis subtracted (the graph estimates
  the bias itself);
* per axis group (gyro → δθ, acc → δβ) the normalised squared residuals ``z² = r² / σ²_pred``, and
  the scale ``k`` that makes them unit variance: robust ``median(z²) / 0.4549`` (0.4549 the median of
  χ²₁: the variance ratio for Gaussian residuals, insensitive to the heavy tails), and the plain
  ``mean(z²)`` beside it.

``k < 1``: the head's variances propagated as white noise are too large over K samples (the graph
should multiply them by k); ``k > 1``: too small. Ground truth's own noise over the interval adds to
the empirical residual, so k is an upper bound on the IMU's share.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Dict, Iterable, Optional

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.core.covariance import interval_covariances
from imu_learn.core.integration import integrate_windows, window_labels
from imu_learn.data.types import Segment
from imu_learn.errors import InvalidInputError

log = logging.getLogger(__name__)

CHI2_1_MEDIAN = 0.454936423119572  # median of a chi-square with one degree of freedom


@dataclass(frozen=True)
class IntervalResiduals:
    """Per interval (M of them): residuals ``rot`` [rad] and ``vel`` [m/s] (M, 3) and the predicted
    variances ``var_rot`` [rad²] and ``var_vel`` [(m/s)²] (M, 3) of the same components."""

    rot: np.ndarray
    vel: np.ndarray
    var_rot: np.ndarray
    var_vel: np.ndarray

    def __len__(self) -> int:
        return len(self.rot)


@dataclass(frozen=True)
class VarianceScale:
    """Scales of the gyro and acc variances (dimensionless; robust and mean estimators) and the
    number of intervals ``n`` they come from."""

    k_gyro: float
    k_acc: float
    k_gyro_mean: float
    k_acc_mean: float
    n: int

    def as_dict(self) -> Dict[str, float]:
        return {"k_gyro": self.k_gyro, "k_acc": self.k_acc, "k_gyro_mean": self.k_gyro_mean,
                "k_acc_mean": self.k_acc_mean, "intervals": self.n}


def interval_residuals(seq: Segment, var: np.ndarray, K: int = 20, gravity: float = 9.81) -> IntervalResiduals:
    """Residuals and predicted variances over consecutive intervals of ``K`` samples of ``seq``.

    ``seq``: the refined IMU with ground truth on its stamps; ``var`` (N, 6): per-sample discrete-time
    variances, gyro then acc; ``gravity`` [m/s²] as the labels take it (world z up). Intervals start
    at samples 0, K, 2K, ... while the whole interval fits; fewer than one gives empty arrays.
    """
    var = np.asarray(var, dtype=np.float64)
    if var.shape != (len(seq), 6):
        raise InvalidInputError(f"var must be (N, 6) = ({len(seq)}, 6), got {var.shape}")
    if int(K) < 1:
        raise InvalidInputError(f"K must be >= 1, got {K}")
    K = int(K)
    m = (len(seq) - 1) // K
    if m < 1:
        z = np.zeros((0, 3))
        return IntervalResiduals(z, z, z, z)
    starts = np.arange(m, dtype=np.int64) * K
    lab = window_labels(seq, K, K, (1.0,), gravity)
    imu = integrate_windows(seq, starts, np.array([K], dtype=np.int64))
    gt_q, hat_q = lab.dq_wxyz[:m, 0], imu.dq_wxyz[:, 0]
    rot = (Rotation.from_quat(gt_q[:, [1, 2, 3, 0]]) * Rotation.from_quat(hat_q[:, [1, 2, 3, 0]]).inv()).as_rotvec()
    vel = lab.dv[:m, 0] - imu.dv[:, 0]
    cov = interval_covariances(seq.t_ns, seq.gyro, seq.acc, var, np.append(starts, m * K))
    d = np.diagonal(cov, axis1=1, axis2=2)
    return IntervalResiduals(rot, vel, d[:, 0:3], d[:, 3:6])


def remove_bias(res: IntervalResiduals) -> IntervalResiduals:
    """``res`` with its mean residual per axis subtracted (a constant bias, which the graph estimates)."""
    if len(res) == 0:
        return res
    return IntervalResiduals(res.rot - res.rot.mean(0), res.vel - res.vel.mean(0), res.var_rot, res.var_vel)


def _ratio(r: np.ndarray, v: np.ndarray) -> tuple:
    """(robust, mean) variance ratio of residuals ``r`` to predicted variances ``v`` (same shape)."""
    ok = v > 0
    z2 = r[ok] ** 2 / v[ok]
    if z2.size == 0:
        return float("nan"), float("nan")
    return float(np.median(z2) / CHI2_1_MEDIAN), float(np.mean(z2))


def scale_from_residuals(parts: Iterable[IntervalResiduals]) -> VarianceScale:
    """k_gyro, k_acc pooled over ``parts`` (each already bias-removed): every axis of every interval
    one normalised squared residual."""
    parts = [p for p in parts if len(p)]
    if not parts:
        raise InvalidInputError("no interval to calibrate the variances on")
    cat = IntervalResiduals(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                              ("rot", "vel", "var_rot", "var_vel")))
    kg, kg_mean = _ratio(cat.rot, cat.var_rot)
    ka, ka_mean = _ratio(cat.vel, cat.var_vel)
    return VarianceScale(kg, ka, kg_mean, ka_mean, len(cat))


def sequence_residuals(seq: Segment, var: np.ndarray, K: int = 20, gravity: float = 9.81,
                       skip_s: float = 0.0) -> IntervalResiduals:
    """:func:`interval_residuals` of one sequence after its first ``skip_s`` seconds, bias removed."""
    s = 0
    if skip_s > 0:
        s = int(np.searchsorted(seq.t_ns, seq.t_ns[0] + int(round(skip_s * 1e9))))
    if s:
        seq = Segment(seq.name, seq.t_ns[s:], seq.gyro[s:], seq.acc[s:], seq.p[s:], seq.v[s:], seq.q_wxyz[s:])
        var = np.asarray(var)[s:]
    return remove_bias(interval_residuals(seq, var, K, gravity))


def calibrate_model(model, sequences: Iterable[Segment], K: int = 20, gravity: float = 9.81,
                    skip_s: float = 0.0) -> Dict[str, object]:
    """Refine each (raw) sequence with ``model`` (a refiner with a covariance head) and calibrate its
    variances over ``K``-sample intervals: ``{"per_sequence": {name: VarianceScale}, "pooled":
    VarianceScale}``. Each sequence's bias is removed separately before pooling."""
    from imu_learn.infer.windowing import apply

    if getattr(model, "cov_head", None) is None:
        raise InvalidInputError("the model has no covariance head: nothing to calibrate")
    per: Dict[str, VarianceScale] = {}
    parts = []
    for seq in sequences:
        g, a, var = apply(model, seq.gyro, seq.acc, variance=True)
        refined = Segment(seq.name, seq.t_ns, g, a, seq.p, seq.v, seq.q_wxyz)
        res = sequence_residuals(refined, var, K, gravity, skip_s)
        if len(res) == 0:
            log.warning(f"{seq.name}: shorter than one interval of {K} samples, skipped")
            continue
        name = seq.name if seq.name not in per else f"{seq.name}#{len(per)}"
        per[name] = scale_from_residuals([res])
        parts.append(res)
        log.info(f"{name}: {per[name].as_dict()}")
    pooled: Optional[VarianceScale] = scale_from_residuals(parts)
    return {"per_sequence": per, "pooled": pooled}
