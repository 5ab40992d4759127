"""A position reference's metric scale against the accelerometer: one estimator and one rule for
``imu-learn calibrate`` (a poses reference, :mod:`.reference`) and ``imu-learn navigate`` (pose
aiding, :func:`imu_learn.fuse.noise_fit.fit_scale`).

For triples of reference rows (a, b, c), ``stride`` rows apart and spanning about
:data:`SPAN_S`, the reference's change of mean velocity ``Δv̄ = (p_c − p_b)/Δ2 − (p_b − p_a)/Δ1``
(its world, its unit) against the IMU's specific force over the same span in that world,
``∫ k(s) R f ds`` (kernel ``k``: ``(s − t_a)/Δ1`` on [a, b], ``(t_c − s)/Δ2`` on [b, c]):

    ∫ k R f ds = (1/s) Δv̄ − g w,     w = (Δ1 + Δ2)/2,

``s`` the reference's units per metre (1: metric), ``g`` gravity in its world; linear least squares
for (1/s, g), Huber-reweighted on the residual 3-vectors (a loop-closure jump pulls only linearly).
The IMU side is regressed on the reference's, not the reverse: over half a second a reference's
change of mean velocity is nearly noise-free, the IMU's carries the vibration, and a scale
regressed on the noisier side reads low (on EuRoC's ORB-SLAM2 stereo poses the reverse regression
over 1 s read 0.80-0.99 on the 24 flight-runs; this one reads 0.99-1.02 over 0.5 s). Overlapping
triples are correlated: the standard error is the regression's times √(2 stride).

The rule (:attr:`ScaleFit.off`): a reference is off metric where its scale is more than
:data:`TOLERANCE` from 1 and :data:`SIGMAS` standard errors, and, where a constant accelerometer bias is
fitted with it (a part's optional fourth entry), so is the fit without that bias, the same way. No
caller fits the bias now: a multirotor's specific force lies along its thrust axis at about g, so a
body-frame bias there is nearly the scale's own column and the two trade, more the longer the span
(EuRoC's motion-capture flights in the Vicon room read 1.03-1.06 over 0.5 s with it, 1.02-1.03
without; ORB-SLAM2's stereo poses of V1_03 1.103 with it, 1.026 without; the Machine Hall's 1.00
either way).
A standard error above
:data:`MAX_STD` of the scale is "not observed" (too little acceleration), and so is a fit whose
1/s is not :data:`SIGMAS` standard errors above zero (the positions do not follow the accelerometer).
Where the caller gives each triple's ``∫ k R ds`` (``bias_rows``), so is a scale that an accelerometer
bias of :data:`ACC_BIAS_CLASS` would move by more than :data:`MAX_STD`: the bias is not fitted (above),
but its leverage is measured. A ground robot turning at a steady rate feels a centripetal acceleration
fixed in its body frame, which a body-frame bias imitates: Fetch's 06_right_turn read 0.43 units per
metre of its metric motion capture, where a 0.1 m/s² bias moves 1/scale by 17 % (07_left_turn 42 %).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional, Sequence, Tuple

import numpy as np

SPAN_S = 0.5  # (Δ1 + Δ2)/2 of the triples [s]
TOLERANCE = 0.05  # a scale further than this from 1 (and SIGMAS standard errors) is off metric
SIGMAS = 4.0
MAX_STD = 0.1  # a wider relative standard error: not observed
MIN_TRIPLES = 40
# a MEMS accelerometer's bias [m/s²], the order of what calibrate estimates (EuRoC's ADIS16448 0.03-0.14, TUM-VI's
# BMI160 0.03, the GNSS walk's IMU 0.12): the leverage of such a bias on a scale says whether the motion tells it
ACC_BIAS_CLASS = 0.1


@dataclass(frozen=True)
class ScaleFit:
    """The reference's units per metre the accelerometer measures (``scale``: 1 for a metric one) with its
    standard error, the triples it came from, and why it is not observed (``reason``; empty when it is)."""

    scale: Optional[float]
    std: Optional[float]
    triples: int
    span_s: float
    reason: str = ""
    # the same fit without the accelerometer-bias columns (where they were fitted): the second reading the
    # rule asks for (module doc); None where there were none
    without_bias: Optional[ScaleFit] = None

    @property
    def observed(self) -> bool:
        return self.scale is not None and not self.reason

    @property
    def off(self) -> bool:
        """Observed, and more than :data:`TOLERANCE` and :data:`SIGMAS` standard errors from 1."""
        if not self.observed:
            return False
        d = float(self.scale) - 1.0
        off = abs(d) > TOLERANCE and abs(d) > SIGMAS * float(self.std)
        other = self.without_bias
        if not off or other is None:
            return off
        e = float(other.scale) - 1.0 if other.observed else 0.0
        return e * d > 0 and abs(e) > TOLERANCE and abs(e) > SIGMAS * float(other.std)

    def to_dict(self) -> Dict[str, object]:
        return {"scale": None if self.scale is None else round(float(self.scale), 5),
                "std": None if self.std is None else round(float(self.std), 5), "triples": self.triples,
                "span_s": round(self.span_s, 3), "observed": self.observed, "off_metric": self.off,
                "reason": self.reason or None}


def stride_of(period_s: float) -> int:
    """Rows between a triple's rows for a reference of median row period ``period_s``."""
    return max(1, int(round(SPAN_S / period_s))) if np.isfinite(period_s) and period_s > 0 else 1


def fit(parts: Sequence[Tuple[np.ndarray, ...]], stride: int, span_s: float,
        bias_rows: Optional[Sequence[np.ndarray]] = None) -> ScaleFit:
    """The scale from ``parts``, each (Δv̄ (M, 3) in the reference's units, ``∫ k R f ds`` (M, 3) in its
    world [m/s], w (M,) [s]) of triples ``stride`` rows apart (module docstring) in a world of its own (its
    own gravity: one part per recording's segment), with a fourth entry ``∫ k R ds`` (M, 3, 3) [s] where a
    constant accelerometer bias (one IMU) is fitted too (every part or none). ``bias_rows``: the same
    ``∫ k R ds`` of every part, not fitted: a scale an accelerometer bias of :data:`ACC_BIAS_CLASS` moves
    by more than :data:`MAX_STD` is not observed (module doc)."""
    if bias_rows is not None:
        bias_rows = [b for x, b in zip(parts, bias_rows) if len(x[2])]
    parts = [x for x in parts if len(x[2])]
    m = int(sum(len(x[2]) for x in parts))
    if m < MIN_TRIPLES:
        return ScaleFit(None, None, m, span_s, f"{m} reference triples over {span_s:.2g} s; {MIN_TRIPLES} needed")
    d = np.concatenate([x[0] for x in parts])
    y = np.concatenate([x[1] for x in parts]).reshape(-1)
    bias = bool(parts) and all(len(x) > 3 for x in parts)
    k = len(parts)  # each part its own world: its own gravity
    n = 1 + 3 * k + (3 if bias else 0)
    A = np.zeros((m, 3, n))
    A[:, :, 0] = d
    row = 0
    for i, x in enumerate(parts):
        A[row:row + len(x[2]), :, 1 + 3 * i:4 + 3 * i] = -np.eye(3) * x[2][:, None, None]
        row += len(x[2])
    if bias:
        A[:, :, n - 3:] = -np.concatenate([x[3] for x in parts])
    A = A.reshape(-1, n)
    wt = np.ones(m)
    for _ in range(6):
        sw = np.repeat(np.sqrt(wt), 3)
        x, *_ = np.linalg.lstsq(A * sw[:, None], y * sw, rcond=None)
        r = np.linalg.norm((y - A @ x).reshape(-1, 3), axis=1)
        wt = np.minimum(1.0, (1.5 * np.median(r) + 1e-12) / np.maximum(r, 1e-12))
    ww = np.repeat(wt, 3)
    res = y - A @ x
    s2 = float(np.sum(ww * res ** 2) / max(1, len(y) - n))
    normal_inv = np.linalg.pinv((A * ww[:, None]).T @ A)
    cov = s2 * normal_inv
    inv, inv_std = float(x[0]), float(np.sqrt(max(cov[0, 0], 0.0)) * np.sqrt(2 * stride))
    lever = math.nan  # how far an accelerometer bias of ACC_BIAS_CLASS moves 1/scale
    if bias_rows is not None:
        B = np.concatenate(bias_rows).reshape(-1, 3)  # y moves by B b for an accelerometer bias b
        lever = ACC_BIAS_CLASS * float(np.linalg.norm((normal_inv @ (A * ww[:, None]).T @ B)[0]))
    cannot = (f"the motion cannot tell it from an accelerometer bias: {ACC_BIAS_CLASS:g} m/s^2 would move 1/scale by "
              "+-{:.2g} (acceleration fixed in the body, e.g. a steady turn)")
    if not inv > SIGMAS * inv_std:
        if SIGMAS * lever > 1.0:  # a metric reference's 1/scale (1) within the bias's reach of zero
            return ScaleFit(None, None, m, span_s, cannot.format(lever))
        return ScaleFit(None, None, m, span_s, f"the IMU's changes of velocity do not follow the reference's "
                                               f"(1/scale {inv:.3g} +- {inv_std:.2g})")
    scale, std = 1.0 / inv, inv_std / inv ** 2
    reason = "" if std <= MAX_STD * scale else f"too little acceleration (+-{std / scale:.0%})"
    if not reason and lever > MAX_STD * inv:
        reason = cannot.format(lever / inv)
    return ScaleFit(scale, std, m, span_s, reason, fit([x[:3] for x in parts], stride, span_s) if bias else None)


def triples(tau: np.ndarray, p: np.ndarray, a: np.ndarray, stride: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Δv̄ (M, 3), Δ1, Δ2) of the triples starting at rows ``a`` (stamps ``tau`` [s], positions ``p``)."""
    b, c = a + stride, a + 2 * stride
    d1, d2 = tau[b] - tau[a], tau[c] - tau[b]
    return (p[c] - p[b]) / d2[:, None] - (p[b] - p[a]) / d1[:, None], d1, d2


Integrals = Tuple[np.ndarray, np.ndarray, np.ndarray]  # (t, ∫_0^t f ds, ∫_0^t s f ds) at each IMU stamp


def running_integrals(t: np.ndarray, F: np.ndarray) -> Integrals:
    """(``t``, ∫_0^t f ds, ∫_0^t s f ds) at each IMU stamp ``t`` [s] of ``F`` = f dt (each sample held until
    the next): computed once, then read at any triples by :func:`kernel_integral`."""
    dt = np.r_[np.diff(t), 0.0]
    S0 = np.r_[np.zeros((1, 3)), np.cumsum(F, axis=0)[:-1]]
    S1 = np.r_[np.zeros((1, 3)), np.cumsum(F * (t + 0.5 * dt)[:, None], axis=0)[:-1]]
    return t, S0, S1


def gyro_frame_integrals(t: np.ndarray, C: np.ndarray, acc: np.ndarray) -> Integrals:
    """:func:`running_integrals` of the specific force ``acc`` turned into the gyro's frame by its chain ``C``
    (what navigate's noise and scale fits and its breaks' check compare with pose aiding)."""
    dt = np.r_[np.diff(t), 0.0]
    return running_integrals(t, np.einsum("nij,nj->ni", C, acc) * dt[:, None])


def kernel_integral(S: Integrals, tau: np.ndarray, a: np.ndarray, stride: int) -> np.ndarray:
    """``∫ k(s) f ds`` (M, 3) over each triple from rows ``a`` (stamps ``tau``), from the running integrals
    ``S`` (:func:`running_integrals`, interpolated at the rows)."""
    t, S0, S1 = S

    def at(X: np.ndarray, i: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(tau[i], t, X[:, k]) for k in range(3)], axis=1)

    b, c = a + stride, a + 2 * stride
    d1, d2 = tau[b] - tau[a], tau[c] - tau[b]
    late = (tau[c][:, None] * (at(S0, c) - at(S0, b)) - (at(S1, c) - at(S1, b))) / d2[:, None]
    early = ((at(S1, b) - at(S1, a)) - tau[a][:, None] * (at(S0, b) - at(S0, a))) / d1[:, None]
    return late + early


def to_world(R: np.ndarray, C: np.ndarray, sample: np.ndarray, b: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` (M, 3) in the gyro's frame (``C``: its chain) turned into the aiding's world by the aiding's
    attitude ``R`` at rows ``b`` (IMU samples ``sample``): ``R_b C_bᵀ v``."""
    return np.einsum("nij,nkj,nk->ni", R[b], C[sample[b]], v)


def pose_terms(S: Integrals, C: np.ndarray, tau: np.ndarray, sample: np.ndarray, p: np.ndarray, R: np.ndarray,
               a: np.ndarray, stride: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One part for :func:`fit` from pose rows (stamps ``tau``, IMU samples ``sample``, body poses ``R``, ``p``
    in the aiding's world) and the IMU's running integrals ``S`` of its specific force in the gyro's frame
    (chain ``C``): (Δv̄, ``∫ k C f ds`` turned into the aiding's world at each triple's middle row, w)."""
    d_vo, d1, d2 = triples(tau, p, a, stride)
    return d_vo, to_world(R, C, sample, a + stride, kernel_integral(S, tau, a, stride)), 0.5 * (d1 + d2)


def gravity(terms: Tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """Gravity in the aiding's world [m/s²] from :func:`pose_terms`: the median over the triples of
    ``(Δv̄ − ∫ k R f ds) / w`` (a metric aiding's)."""
    d_vo, imu_A, w = terms
    return np.median((d_vo - imu_A) / w[:, None], axis=0)
