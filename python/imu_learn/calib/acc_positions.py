"""The accelerometer's affine calibration from a reference's *positions*, without differentiating them:
what a sparse pose reference (a 20 Hz VO/SLAM trajectory) observes of the accelerometer.

A pose-only reference's velocity comes from a local quadratic over several poses
(:class:`imu_learn.data.loading.AlignOptions`), which attenuates the accelerations the floor's
velocity residuals fit the accelerometer's scale against (:func:`imu_learn.calib.reference.resolves_acceleration`).
Positions themselves are not attenuated. Over a long baseline ``T`` around a stamp t, the mean
velocity over [t, t + T1] minus the one over [t − T2, t],

    (p(t + T1) − p(t)) / T1 − (p(t) − p(t − T2)) / T2  =  ∫ k(s) a(s) ds,

is the world acceleration a = R (M_a f − c) + g weighted by a triangle kernel k of width T1 + T2
(c = M_a b_a; f the raw specific force): linear in (M_a, c), no velocity needed, and a position
noise σ becomes about σ·√6 / T in the residual (m/s), σ·√6 / T² in acceleration. The integral is the
floor's own integration (the zero-order hold, ``p += v dt + a dt²/2``, the IMU resampled at its time
offset ``tau``), so the same (M_a, b_a) make both agree on a reference that resolves everything.

The reference's positions are those of its own origin: a camera a few centimetres from the IMU reads
p_ref = p_imu + R l (l: the reference origin in the IMU frame, R the IMU's attitude). Its effect,
R (ω × (ω × l) + α × l), is here the same second difference of R l, linear in l with no derivative:
l is estimated jointly (:attr:`AccFit.lever_m`). The attitude rotating the specific force is the
reference's (on the IMU stamps, in the IMU frame, the world levelled; slerped between its poses) or,
given calibrated gyro rates, theirs integrated and held to the reference's by a correction averaged
over ``attitude_smooth_s`` (:func:`gyro_attitude`: on EuRoC's ORB-SLAM2 poses it lowers the residual
by 9 %); gravity is fixed at ``gravity`` along −z (as the floor fixes it); optionally (``fit_tilt``)
each recording's world may be tilted by a small horizontal gravity component (the levelling's error,
told from the bias by the attitude's changes of heading).

The scale of the positions is taken as it is (calibrate applies a monocular scale before): an
overall scale s of the positions trades with the accelerometer's scale across gravity (for a
multirotor, whose specific force stays near its thrust axis, nearly entirely).

Robust: Huber reweighting on each residual 3-vector (a loop-closure jump pulls only linearly).
Uncertainty (:attr:`AccFit.std`): cluster-robust (sandwich) standard errors with the rows of
contiguous stretches of ``cluster_s`` as clusters (overlapping baselines share their noise).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.calib.frames import rotation_matrices
from imu_learn.core.integration import preintegrate
from imu_learn.core.quat import quat_conj, quat_log, quat_mul
from imu_learn.data.types import Segment

# unknowns: vec(M_a) row-major (9), c = M_a b_a (3), lever l (3), then 2 tilt terms per recording
N_AFFINE = 12
N_LEVER = 3
BIAS_TERMS = (9, 10, 11)  # ``free`` of a fit of the bias alone, the matrix at its prior (identity)


@dataclass(frozen=True)
class AccOptions:
    """``baseline_s``: T of each side of the second difference; ``stride_s``: centres this far apart;
    ``huber``: Huber's threshold on |residual| [m/s] as a multiple of the median |residual|;
    ``cluster_s``: the sandwich's clusters; ``fit_lever``: estimate the reference origin's offset;
    ``fit_tilt``: estimate each recording's world tilt (2 per recording); ``attitude_smooth_s``: with
    calibrated gyro rates given, the attitude is theirs integrated, held to the reference's by a
    correction averaged over this span (:func:`gyro_attitude`)."""

    baseline_s: float = 0.5
    stride_s: float = 0.05
    huber: float = 1.5
    iterations: int = 6
    cluster_s: float = 10.0
    fit_lever: bool = True
    fit_tilt: bool = False
    attitude_smooth_s: float = 10.0


@dataclass
class AccFit:
    """``M_a``, ``b_a`` (the floor's model a = M_a (f − b_a)), the reference origin ``lever_m`` in the
    IMU frame, each recording's world ``tilt`` (g's horizontal components [m/s²]; zeros unless
    fitted), their standard errors, and the fit's numbers (``rows`` residual 3-vectors, ``rms`` [m/s]
    after, ``rms_identity`` with M_a = I and the bias fitted alone)."""

    M_a: np.ndarray
    b_a: np.ndarray
    lever_m: np.ndarray
    M_a_std: np.ndarray
    b_a_std: np.ndarray
    lever_std_m: np.ndarray
    tilt: np.ndarray
    rows: int
    rms: float
    rms_identity: float
    options: AccOptions
    attitude: str = "the reference's"  # or the calibrated gyro's, held to the reference's
    extra: Dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> Dict[str, Any]:
        """What profile.json's ``reference.accelerometer_from_positions`` records."""
        o = self.options
        return {"method": "second differences of the reference positions over +-T (triangle-weighted "
                          "specific force, the zero-order hold), lever arm jointly",
                "baseline_s": o.baseline_s, "stride_s": o.stride_s, "fit_lever": o.fit_lever, "fit_tilt": o.fit_tilt,
                "attitude": self.attitude, "attitude_smooth_s": o.attitude_smooth_s,
                "M_a": self.M_a.tolist(), "M_a_std": self.M_a_std.tolist(), "b_a": self.b_a.tolist(),
                "b_a_std": self.b_a_std.tolist(), "lever_arm_m": self.lever_m.tolist(),
                "lever_arm_std_m": self.lever_std_m.tolist(), "world_tilt_mps2": self.tilt.tolist(),
                "rows": self.rows, "rms_m_s": self.rms, "rms_identity_m_s": self.rms_identity, **self.extra}


def _zoh_double_integral(x: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """P (N, ...) with P[0] = 0 and the zero-order hold's p += v dt + x dt²/2, v += x dt, v0 = 0."""
    shape = (1,) + x.shape[1:]
    d = dt.reshape((-1,) + (1,) * (x.ndim - 1))
    v = np.concatenate([np.zeros(shape), np.cumsum(x[:-1] * d, axis=0)])
    step = v[:-1] * d + 0.5 * x[:-1] * d * d
    return np.concatenate([np.zeros(shape), np.cumsum(step, axis=0)])


def _shifted_acc(s: Segment, tau_samples: float) -> np.ndarray:
    """The raw specific force resampled at t + tau·dt (the floor's time offset; ends held)."""
    if tau_samples == 0.0 or len(s) < 2:
        return s.acc
    t = (s.t_ns - s.t_ns[0]).astype(np.float64) * 1e-9
    shift = tau_samples * float(np.median(np.diff(t)))
    return np.stack([np.interp(t + shift, t, s.acc[:, j]) for j in range(3)], axis=1)


def _rotvec_quat(r: np.ndarray) -> np.ndarray:
    a = np.linalg.norm(r, axis=-1, keepdims=True)
    k = r / np.maximum(a, 1e-300)
    return np.concatenate([np.cos(a / 2), np.sin(a / 2) * k], axis=-1)


def gyro_attitude(s: Segment, gyro: np.ndarray, smooth_s: float) -> np.ndarray:
    """The IMU's attitude (w,x,y,z on the segment's stamps) from calibrated rates ``gyro`` integrated
    (the zero-order hold), held to the reference's by a world-side correction C (q_ref = C q_gyro)
    whose rotation vector is averaged over ``smooth_s``: within a second difference the attitude is
    the gyro's (the reference's attitude error, which tilts gravity into the horizontal, averaged over
    the span), over the span the reference's (the gyro's drift removed)."""
    q_g = preintegrate(s.t_ns, gyro, np.zeros_like(gyro)).dq_wxyz
    c = quat_mul(s.q_wxyz, quat_conj(q_g))
    c0 = c[len(c) // 2]
    r = quat_log(quat_mul(c, quat_conj(c0)[None]))
    period = float(np.median(np.diff(s.t_ns))) * 1e-9
    h = max(1, int(round(0.5 * smooth_s / period)))
    cs = np.concatenate([np.zeros((1, 3)), np.cumsum(r, axis=0)])
    i = np.arange(len(r))
    lo, hi = np.maximum(0, i - h), np.minimum(len(r), i + h + 1)
    r_s = (cs[hi] - cs[lo]) / (hi - lo)[:, None]
    q = quat_mul(quat_mul(_rotvec_quat(r_s), c0[None]), q_g)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def segment_rows(s: Segment, options: AccOptions, tau_samples: float = 0.0, gravity: float = 9.81,
                 gyro: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A (rows, 3, 17), y (rows, 3), centre times [s]) of one segment: y = A x, x = (vec M_a, c, l,
    the world's horizontal gravity), gravity's fixed part moved into y; ``gyro``: the segment's
    calibrated rates (the attitude :func:`gyro_attitude`'s), or None (the reference's)."""
    n = len(s)
    dt_all = np.diff(s.t_ns).astype(np.float64) * 1e-9
    if n < 3:
        return np.zeros((0, 3, 17)), np.zeros((0, 3)), np.zeros(0)
    period = float(np.median(dt_all))
    k = max(1, int(round(options.baseline_s / period)))
    c = np.arange(k, n - k, max(1, int(round(options.stride_s / period))))
    if n <= 2 * k or not len(c):
        return np.zeros((0, 3, 17)), np.zeros((0, 3)), np.zeros(0)
    q = s.q_wxyz if gyro is None else gyro_attitude(s, gyro, options.attitude_smooth_s)
    r = rotation_matrices(q)  # IMU -> world
    f = _shifted_acc(s, tau_samples)
    feat = np.zeros((n, 3, 16))
    feat[:, :, 0:9] = np.einsum("nij,nk->nijk", r, f).reshape(n, 3, 9)  # d(R M f)/d M[j,k] = R[:, j] f[k]
    feat[:, :, 9:12] = -r  # -R c
    feat[:, 0, 13] = 1.0  # a horizontal gravity component (world x, y): the tilt basis
    feat[:, 1, 14] = 1.0
    feat[:, 2, 15] = -gravity  # the fixed gravity
    P = _zoh_double_integral(feat.reshape(n, -1), dt_all).reshape(n, 3, 16)
    t = (s.t_ns - s.t_ns[0]).astype(np.float64) * 1e-9
    t1 = (t[c + k] - t[c])[:, None, None]
    t2 = (t[c] - t[c - k])[:, None, None]

    d_int = (P[c + k] - P[c]) / t1 - (P[c] - P[c - k]) / t2  # (rows, 3, 16)
    d_rot = (r[c + k] - r[c]) / t1 - (r[c] - r[c - k]) / t2  # (rows, 3, 3): the lever's columns
    d_p = (s.p[c + k] - s.p[c]) / t1[:, :, 0] - (s.p[c] - s.p[c - k]) / t2[:, :, 0]
    a = np.zeros((len(c), 3, 17))
    a[:, :, 0:12] = d_int[:, :, 0:12]
    a[:, :, 12:15] = d_rot
    a[:, :, 15:17] = d_int[:, :, 13:15]
    y = d_p - d_int[:, :, 15]
    return a, y, t[c]


def _huber_lstsq(a: np.ndarray, y: np.ndarray, huber: float, iterations: int) -> Tuple[np.ndarray, np.ndarray]:
    """x of min Σ ρ(|y_i − A_i x|) over 3-vector rows (Huber IRLS), and the final row weights."""
    rows = len(y)
    a2, y2 = a.reshape(rows * 3, -1), y.reshape(-1)
    w = np.ones(rows)
    x = np.zeros(a.shape[-1])
    for _ in range(iterations):
        sw = np.repeat(np.sqrt(w), 3)
        x, *_ = np.linalg.lstsq(a2 * sw[:, None], y2 * sw, rcond=None)
        norm = np.linalg.norm((y2 - a2 @ x).reshape(rows, 3), axis=1)
        cap = huber * np.median(norm) + 1e-12
        w = np.minimum(1.0, cap / np.maximum(norm, 1e-12))
    return x, w


def _sandwich(a: np.ndarray, res: np.ndarray, w: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """Cluster-robust covariance of the weighted least squares (rows of one cluster share their noise)."""
    rows = len(res)
    a2 = a.reshape(rows * 3, -1) * np.repeat(w, 3)[:, None]
    bread = np.linalg.pinv(a2.T @ a.reshape(rows * 3, -1))
    score = a2 * res.reshape(-1)[:, None]
    cl = np.repeat(clusters, 3)
    meat = np.zeros((a.shape[-1], a.shape[-1]))
    for u in np.unique(cl):
        g = score[cl == u].sum(0)
        meat += np.outer(g, g)
    m = len(np.unique(cl))
    return bread @ meat @ bread.T * (m / max(m - 1, 1))


Rows = Tuple[np.ndarray, np.ndarray, np.ndarray]  # one segment's (A, y, centre times): segment_rows
ATTITUDE = {False: "the reference's", True: "the calibrated gyro's, held to the reference's"}


def recording_rows(recordings: Sequence[Sequence[Segment]], options: AccOptions = AccOptions(),
                   tau_samples: float = 0.0, gravity: float = 9.81,
                   gyros: Optional[Sequence[Sequence[np.ndarray]]] = None) -> List[List[Rows]]:
    """:func:`segment_rows` of every segment of every recording (what a fit on any subset of the
    recordings, at any level, reads)."""
    return [[segment_rows(s, options, tau_samples, gravity, None if gyros is None else gyros[i][j])
             for j, s in enumerate(segs)] for i, segs in enumerate(recordings)]


def fit_acc_from_positions(recordings: Sequence[Sequence[Segment]], options: AccOptions = AccOptions(),
                           tau_samples: float = 0.0, gravity: float = 9.81,
                           gyros: Optional[Sequence[Sequence[np.ndarray]]] = None,
                           free: Optional[Sequence[int]] = None) -> AccFit:
    """The accelerometer's (M_a, b_a) and the reference origin from ``recordings`` (each a list of
    segments: the reference in the IMU frame on the IMU stamps, the world levelled; module doc);
    ``gyros``: each segment's calibrated rates (the attitude then the gyro's, :func:`gyro_attitude`),
    or None (the reference's attitude); ``free``: the affine parameters fitted, as indices into
    (M_a − I row-major, b_a) (:func:`imu_learn.calib.select.free_indices`), the others held at their
    prior (identity, zero); None: all twelve."""
    return fit_acc_from_rows(recording_rows(recordings, options, tau_samples, gravity, gyros), options, free,
                             ATTITUDE[gyros is not None])


def fit_acc_from_rows(recordings: Sequence[Sequence[Rows]], options: AccOptions = AccOptions(),
                      free: Optional[Sequence[int]] = None, attitude: str = ATTITUDE[False]) -> AccFit:
    """:func:`fit_acc_from_positions` on each recording's segments' rows (:func:`recording_rows`);
    ``attitude`` says whose attitude the rows were built on."""
    blocks: List[Tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    cluster_id: List[np.ndarray] = []
    next_cluster = 0
    for i, segs in enumerate(recordings):
        for a, y, t in segs:
            if not len(y):
                continue
            blocks.append((a, y, np.full(len(y), i)))
            ids = np.floor((t - t[0]) / options.cluster_s).astype(int)
            cluster_id.append(ids + next_cluster)
            next_cluster += int(ids.max()) + 1
    if not blocks:
        raise ValueError(f"no segment is longer than twice the baseline ({options.baseline_s:g} s)")
    k = len(recordings)
    n_x = N_AFFINE + N_LEVER + 2 * k
    rows = sum(len(b[1]) for b in blocks)
    a = np.zeros((rows, 3, n_x))
    y = np.zeros((rows, 3))
    j = 0
    for ab, yb, rec in blocks:
        m = len(yb)
        a[j:j + m, :, :15] = ab[:, :, :15]
        for r in np.unique(rec):
            sel = np.arange(j, j + m)[rec == r]
            a[sel, :, 15 + 2 * r:17 + 2 * r] = ab[rec == r][:, :, 15:17]
        y[j:j + m] = yb
        j += m
    free_set = set(range(N_AFFINE)) if free is None else {int(i) for i in free}
    x_prior = np.r_[np.eye(3).ravel(), np.zeros(3)]  # (vec M_a, c) at the prior
    fixed = [i for i in range(N_AFFINE) if i not in free_set]
    y_free = y - np.einsum("rij,j->ri", a[:, :, fixed], x_prior[fixed])  # the held terms moved into the rows
    keep = sorted(free_set)
    if options.fit_lever:
        keep += list(range(N_AFFINE, N_AFFINE + N_LEVER))
    if options.fit_tilt:
        keep += list(range(N_AFFINE + N_LEVER, n_x))
    sub = a[:, :, keep]
    x_sub, w = _huber_lstsq(sub, y_free, options.huber, options.iterations)
    res = y_free - np.einsum("rij,j->ri", sub, x_sub)
    cov_sub = _sandwich(sub, res, w, np.concatenate(cluster_id))
    x = np.zeros(n_x)
    x[fixed] = x_prior[fixed]
    x[keep] = x_sub
    cov = np.zeros((n_x, n_x))
    cov[np.ix_(keep, keep)] = cov_sub
    m_a = x[:9].reshape(3, 3)
    c = x[9:12]
    b_a = np.linalg.solve(m_a, c)
    # b_a = M^-1 c: its covariance by the Jacobian of (vec M, c) -> b
    m_inv = np.linalg.inv(m_a)
    jac = np.zeros((3, 12))
    for p in range(3):
        for q in range(3):
            e = np.zeros((3, 3))
            e[p, q] = 1.0
            jac[:, 3 * p + q] = -m_inv @ e @ b_a
    jac[:, 9:12] = m_inv
    cov_b = jac @ cov[:12, :12] @ jac.T
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    # M_a = I, the bias alone: how much the matrix explains
    ident = np.einsum("rij,j->ri", a[:, :, :9], np.eye(3).ravel())
    keep_i = [9, 10, 11] + [q for q in keep if q >= N_AFFINE]
    xi, wi = _huber_lstsq(a[:, :, keep_i], y - ident, options.huber, options.iterations)
    res_i = y - ident - np.einsum("rij,j->ri", a[:, :, keep_i], xi)
    return AccFit(M_a=m_a, b_a=b_a, lever_m=x[12:15], M_a_std=sd[:9].reshape(3, 3),
                  b_a_std=np.sqrt(np.maximum(np.diag(cov_b), 0.0)), lever_std_m=sd[12:15],
                  tilt=x[15:].reshape(k, 2), rows=rows, rms=_rms(res), rms_identity=_rms(res_i), options=options,
                  attitude=attitude,
                  extra={"tilt_std_mps2": sd[15:].reshape(k, 2).tolist(),
                         "down_weighted_rows": int(np.sum(w < 1.0))})


def heldout_rms(fit: AccFit, segments: Sequence[Segment], tau_samples: float = 0.0, gravity: float = 9.81,
                gyros: Optional[Sequence[np.ndarray]] = None) -> float:
    """The RMS of the residual 3-vector's norm [m/s] of ``fit`` (its M_a, c and reference origin, as
    fitted elsewhere) on a recording it was not fitted on: that recording's world tilt, a property of its
    reference and not of the IMU, fitted alone (least squares); NaN without a row."""
    return heldout_rms_rows(fit, recording_rows([segments], fit.options, tau_samples, gravity,
                                                None if gyros is None else [gyros])[0])


def heldout_rms_rows(fit: AccFit, rows: Sequence[Rows]) -> float:
    """:func:`heldout_rms` on one recording's segments' rows (:func:`recording_rows`)."""
    blocks = [(a, y) for a, y, _t in rows if len(y)]
    if not blocks:
        return math.nan
    a = np.concatenate([b[0] for b in blocks])
    y = np.concatenate([b[1] for b in blocks])
    x = np.r_[fit.M_a.ravel(), fit.M_a @ fit.b_a, fit.lever_m]
    res = y - np.einsum("rij,j->ri", a[:, :, :15], x)
    if fit.options.fit_tilt:
        tilt, *_ = np.linalg.lstsq(a[:, :, 15:17].reshape(-1, 2), res.reshape(-1), rcond=None)
        res = res - np.einsum("rij,j->ri", a[:, :, 15:17], tilt)
    return _rms(res)


def _rms(res: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(res**2, axis=1)))) if len(res) else math.nan


def recording_spread(recordings: Sequence[Sequence[Segment]], options: AccOptions, tau_samples: float = 0.0,
                     gravity: float = 9.81, gyros: Optional[Sequence[Sequence[np.ndarray]]] = None,
                     free: Optional[Sequence[int]] = None) -> Optional[Tuple[np.ndarray, np.ndarray, List[AccFit]]]:
    """The standard error of (M_a, b_a) as the floor states its own (:func:`imu_learn.calib.fit.spread`):
    the fit on each recording alone (of the ``free`` terms, :func:`fit_acc_from_positions`), their spread over
    sqrt(recordings); None with fewer than two."""
    fits = []
    for i, segs in enumerate(recordings):
        try:
            fits.append(fit_acc_from_positions([segs], options, tau_samples, gravity,
                                               None if gyros is None else [gyros[i]], free))
        except ValueError:
            continue
    if len(fits) < 2:
        return None
    n = math.sqrt(len(fits))
    m = np.std(np.stack([f.M_a for f in fits]), axis=0, ddof=1) / n
    b = np.std(np.stack([f.b_a for f in fits]), axis=0, ddof=1) / n
    return m, b, fits
