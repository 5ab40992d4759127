"""The IMU's white-noise densities fitted from the aiding, for a device with no profile, no
``--imu-noise`` and no sensor.yaml: one scale factor on the MEMS class default (EuRoC's ADIS16448
figures, :data:`imu_learn.calib.profile.CLASS_DEFAULT_SOURCE`) chosen so that the aiding's
innovations against the IMU's prediction are consistent with the noise assumed.

The innovations are those of :mod:`.aiding.noise` (the aiding's own noise estimate): for rows
``a, b, c`` (``stride`` rows apart, no break longer than ``max_gap_s``) the change of mean velocity
``(p_c - p_b)/Δ2 - (p_b - p_a)/Δ1`` against the IMU's ``∫ k(s) (R f + g) ds`` over the same span
(kernel ``k``: ``(s - t_a)/Δ1`` on [a, b], ``(t_c - s)/Δ2`` on [b, c]). Without an attitude (position
fixes) both are compared by their norms: ``|Δv̄ - g (Δ1 + Δ2)/2|`` against ``|∫ k C f ds|`` (the
specific force carried by the gyro inside the span; a norm needs no attitude, and to first order
neither the attitude error nor the gyro noise moves it). The residual, less its least-squares fit on
a constant accelerometer bias (about ``-w u·b``, ``u`` the specific force's direction in the body) and
less its running median (what remains of the bias along gravity), has the variance

    σ_p² (1/Δ1² + (1/Δ1 + 1/Δ2)² + 1/Δ2²)  +  σ_a² (Δ1 + Δ2)/3

(white aiding noise σ_p per axis, white accelerometer noise σ_a): the aiding dominates short spans,
the IMU long ones. Over strides 1, 2, 4, ... (spans up to :data:`MAX_SPAN_S`) the robust variance
(1.4826 × MAD, squared) of each stride is fitted by both terms (non-negative least squares on the
ratios), giving σ_p and ``factor² = σ_a² / σ_a,class²``; the gyro density takes the same factor
(position fixes do not observe it), the random walks stay the class defaults
(:data:`imu_learn.calib.profile.CLASS_DEFAULTS`). ``chi2_ratio`` checks the result: the median of the
squared normalised residuals over the median of χ²(1) (1: consistent). A factor outside
:data:`FACTOR_BOUNDS` is not used: the class default is, and the warning says so.

The same triples tell pose aiding's metric scale (:func:`fit_scale`, the estimator and rule of
:mod:`imu_learn.calib.metric_scale`): a monocular VO's positions are in a unit of its own, and a filter
fusing them as metres follows them anyway (on an EuRoC flight with its stereo poses scaled by 0.4: exit
0, the noise fit x45, the track 4.1 m off).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from imu_learn.calib import metric_scale
from imu_learn.calib.metric_scale import ScaleFit
from imu_learn.calib.profile import CLASS_DEFAULT_SOURCE, CLASS_DEFAULTS
from imu_learn.core.nnls import nonneg_lstsq

from .aiding.noise import detrend, robust_sigma
from .aiding.pairs import gyro_orientation, runs, within
from .aiding.sampling import snap_to_samples
from .noise import ImuNoise

FACTOR_BOUNDS = (0.05, 100.0)  # 0.1 (a class default 10x too noisy) sits inside with room for the fit's scatter
MAX_SPAN_S = 4.0  # the longest span (Δ1 + Δ2)/2 compared [s]
MIN_TRIPLES = 20  # a stride with fewer residuals is not used
TREND_S = 60.0  # the running median removing the acc bias along gravity [s] (at least TREND_SPANS spans)
TREND_SPANS = 20  # overlapping spans are correlated: a shorter window would remove their variance
CHI2_1_MEDIAN = 0.454936  # the median of a chi-square with one degree of freedom
CLASS_WHITE = (ImuNoise.gyro_noise_density, ImuNoise.acc_noise_density)  # the same device's white noise


def class_default(source: str = CLASS_DEFAULT_SOURCE) -> ImuNoise:
    """The MEMS class default: EuRoC ADIS16448's white noise, the profile's class random walks."""
    return ImuNoise(CLASS_WHITE[0], CLASS_WHITE[1], CLASS_DEFAULTS["gyroscope_random_walk"],
                    CLASS_DEFAULTS["accelerometer_random_walk"], source=source)


@dataclass(frozen=True)
class NoiseFit:
    """The fit: ``factor`` on the class default's white noise (None: no fit), the aiding's white
    noise per axis it implies [m], the consistency check, the residuals and spans it came from, and
    why it is not used (``reason``; empty when it is)."""

    factor: Optional[float]
    aiding_sigma_m: Optional[float]
    chi2_ratio: Optional[float]
    residuals: int
    spans_s: Tuple[float, ...]
    reason: str = ""

    @property
    def used(self) -> bool:
        return self.factor is not None and not self.reason


def residuals(pr: Prepared, p: np.ndarray, R: Optional[np.ndarray], g_vec: Optional[np.ndarray], a: np.ndarray,
              stride: int):
    """(residual norms (M,), Δ1, Δ2, their regressors on a constant accelerometer bias (M, 3)) of the triples from
    rows ``a``, ``stride`` rows apart (module docstring); ``R`` (pose aiding): gravity in the aiding's world
    estimated as the median of the per-triple ones (:func:`imu_learn.calib.metric_scale.gravity`)."""
    b = a + stride
    d_vo, d1, d2 = metric_scale.triples(pr.tau, p, a, stride)
    imu = metric_scale.kernel_integral(pr.S, pr.tau, a, stride)
    w = 0.5 * (d1 + d2)
    if g_vec is None:
        g_vec = metric_scale.gravity((d_vo, metric_scale.to_world(R, pr.C, pr.sample, b, imu), w))
    norm = np.linalg.norm(imu, axis=1)
    e = np.linalg.norm(d_vo - g_vec * w[:, None], axis=1) - norm
    # a constant accelerometer bias b moves e by about -w (u . b), u the specific force's direction in the body
    u = np.einsum("nji,nj->ni", pr.C[pr.sample[b]], imu / np.maximum(norm, 1e-9)[:, None])
    return e, d1, d2, w[:, None] * u


@dataclass(frozen=True)
class Prepared:
    """The aiding's stamps [s from the first IMU sample], each row's IMU sample, the gyro's orientation
    ``C``, the running integrals of the specific force in its frame (:func:`imu_learn.calib.metric_scale.running_integrals`),
    each row's run (:func:`.aiding.pairs.runs`) and the aiding's median period [s]: what :func:`fit_noise`
    and :func:`fit_scale` both compare."""

    tau: np.ndarray
    sample: np.ndarray
    C: np.ndarray
    S: metric_scale.Integrals
    run: np.ndarray
    period: float


def prepare(imu_t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, aid_t_ns: np.ndarray,
            max_gap_s: float = 0.5) -> Prepared:
    t0 = int(imu_t_ns[0])
    t = (np.asarray(imu_t_ns, dtype=np.int64) - t0) * 1e-9
    tau = (np.asarray(aid_t_ns, dtype=np.int64) - t0) * 1e-9
    # each row's nearest sample (the rows' own rule, :func:`.aiding.snap_to_samples`): the first sample at or after a
    # row put two rows of a capture faster than the IMU on one sample, a break of their run at every such pair
    # (Fetch's ~100 Hz motion capture on its 100 Hz IMU: 398 runs of 3339 rows, no triple for the scale check)
    sample = snap_to_samples(imu_t_ns, aid_t_ns)[0] if len(imu_t_ns) > 1 else np.zeros(len(tau), dtype=np.int64)
    C = gyro_orientation(imu_t_ns, gyro)
    S = metric_scale.gyro_frame_integrals(t, C, acc)
    run = runs(imu_t_ns, sample, max_gap_s)  # the aiding's one pairing rule (.aiding.pairs)
    period = float(np.median(np.diff(tau))) if len(tau) > 1 else float("nan")
    return Prepared(tau, sample, C, S, run, period)


def fit_noise(imu_t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, aid_t_ns: np.ndarray, p: np.ndarray,
              R: Optional[np.ndarray] = None, gravity: Optional[float] = 9.81, max_gap_s: float = 0.5,
              default: Optional[ImuNoise] = None, prep: Optional[Prepared] = None) -> NoiseFit:
    """The fit (module docstring) from the IMU (stamps [ns], gyro [rad/s], acc [m/s^2], any frame)
    and aiding rows inside its span (stamps [ns] on the IMU's clock, positions ``p`` (M, 3) [m]; with
    ``R`` (M, 3, 3) body-to-aiding-world rotations, gravity is found in that world, else the world is
    z up with ``gravity`` [m/s^2]). ``default``: the noise the factor scales (the class default);
    ``prep``: :func:`prepare` of the same inputs, when already computed."""
    default = class_default() if default is None else default
    pr = prep if prep is not None else prepare(imu_t_ns, gyro, acc, aid_t_ns, max_gap_s)
    tau, run, period = pr.tau, pr.run, pr.period
    g_vec = None if R is not None else np.array([0.0, 0.0, -float(gravity)])
    rows: List[Tuple[float, float, float]] = []  # (variance, aiding coefficient, IMU coefficient)
    parts: List[Tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    spans: List[float] = []
    stride = 1
    while 2 * stride < len(tau) and stride * period <= MAX_SPAN_S:
        a = within(run, 2 * stride)
        if len(a) >= MIN_TRIPLES:
            e, d1, d2, X = residuals(pr, p, R, g_vec, a, stride)
            e = e - X @ np.linalg.lstsq(X, e, rcond=None)[0]  # less the constant bias's part
            span = float(np.median(0.5 * (d1 + d2)))
            e = detrend(e[:, None], int(round(max(TREND_S, TREND_SPANS * span) / period)))[:, 0]
            G = 1 / d1 ** 2 + (1 / d1 + 1 / d2) ** 2 + 1 / d2 ** 2
            B = default.acc_noise_density ** 2 * (d1 + d2) / 3
            rows.append((float(robust_sigma(e[:, None])[0] ** 2), float(np.median(G)), float(np.median(B))))
            parts.append((e, G, B))
            spans.append(round(span, 3))
        stride *= 2
    return _solve(rows, parts, tuple(spans))


def _solve(rows, parts, spans) -> NoiseFit:
    """Both terms' weights from the strides' robust variances (relative least squares, non-negative)."""
    n = int(sum(len(e) for e, _, _ in parts))
    if len(rows) < 2:
        return NoiseFit(None, None, None, n, spans, f"{len(rows)} span length(s) with {MIN_TRIPLES}+ aiding triples; "
                                                    "2 needed")
    v = np.array([r[0] for r in rows])
    X = np.array([[r[1], r[2]] for r in rows]) / v[:, None]
    (alpha, beta), _ = nonneg_lstsq(X, np.ones(len(rows)))
    factor = float(np.sqrt(beta))
    q = np.concatenate([e ** 2 / (alpha * G + beta * B) for e, G, B in parts]) if beta > 0 or alpha > 0 else None
    chi2 = None if q is None else round(float(np.median(q)) / CHI2_1_MEDIAN, 3)
    reason = ""
    if not FACTOR_BOUNDS[0] <= factor <= FACTOR_BOUNDS[1]:
        reason = f"the fitted factor x{factor:.3g} is outside [{FACTOR_BOUNDS[0]:g}, {FACTOR_BOUNDS[1]:g}]"
    return NoiseFit(factor, float(np.sqrt(alpha)), chi2, n, spans, reason)


def fitted_noise(fit: NoiseFit, default: Optional[ImuNoise] = None) -> ImuNoise:
    """The noise the graph assumes after ``fit``: the class default's white noise times the factor,
    or the class default where the fit is not used; its source says which."""
    default = class_default() if default is None else default
    if not fit.used:
        return ImuNoise(default.gyro_noise_density, default.acc_noise_density, default.gyro_random_walk,
                        default.acc_random_walk, source=f"{CLASS_DEFAULT_SOURCE}: no fit from the aiding's "
                                                        f"innovations ({fit.reason})")
    k = float(fit.factor)
    return ImuNoise(k * default.gyro_noise_density, k * default.acc_noise_density, default.gyro_random_walk,
                    default.acc_random_walk,
                    source=f"fitted from the aiding's innovations: x{k:.3g} the MEMS class default's white noise "
                           f"(chi2/dof {fit.chi2_ratio}, {fit.residuals} residuals over spans {list(fit.spans_s)} s; "
                           f"aiding {1e3 * float(fit.aiding_sigma_m):.3g} mm per axis)")


def fit_scale(p: np.ndarray, R: np.ndarray, prep: Prepared) -> ScaleFit:
    """Pose aiding's metric scale (:mod:`imu_learn.calib.metric_scale`): the IMU's specific force over each
    triple turned into the aiding's world by the aiding's attitude at its middle row (``R_b C_bᵀ``)."""
    stride = metric_scale.stride_of(prep.period)
    a = within(prep.run, 2 * stride)
    span = float(stride * prep.period) if np.isfinite(prep.period) else float("nan")
    if not len(a):
        return metric_scale.fit([], stride, span)
    t = prep.S[0]
    # an accelerometer bias along each IMU axis, turned as the specific force is: its leverage on the scale (a ground
    # robot's steady turn, whose centripetal acceleration a bias imitates: Fetch's metric 06_right_turn read x0.561)
    bias = np.stack([metric_scale.to_world(R, prep.C, prep.sample, a + stride, metric_scale.kernel_integral(
        metric_scale.gyro_frame_integrals(t, prep.C, np.broadcast_to(np.eye(3)[j], (len(t), 3))), prep.tau, a, stride))
        for j in range(3)], axis=2)
    return metric_scale.fit([metric_scale.pose_terms(prep.S, prep.C, prep.tau, prep.sample, p, R, a, stride)],
                            stride, span, [bias])
