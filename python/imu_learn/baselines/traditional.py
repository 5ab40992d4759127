"""The "traditional" baseline (the paper's "Tr." column, after Farrell 2008): a low-pass filter and
an intrinsic calibration model per sensor, fitted against ground truth through the integration.

Model (body frame, per sample)::

    gyro   ω = M_g (LP_g(ω_m) − b_g) − G LP_g(a_m)      M_g 3×3 (scale factors + misalignment),
                                                         b_g bias, G 3×3 g-sensitivity [rad/s per m/s²]
    accel  a = M_a (LP_a(a_m) − b_a)                     M_a 3×3, b_a bias

LP is a zero-phase Butterworth low-pass (``scipy.signal.sosfiltfilt`` on each axis, a separate cutoff
per sensor, or none); the specific force that drives the g-sensitivity is the recorded one filtered
with the gyro's cutoff.

Fit (``fit``): nonlinear least squares *through the same zero-order-hold integration* that the
evaluation uses (the scheme of :func:`imu_learn.nn.integration.integrate` and of the core's
``integrate_windows``, in float64; they agree to ~1e-15), on short windows of the training
sequences (``window`` samples, labels at the paper's fractions of it):

1. gyro: residuals Log(Δq_gt ⊗ Δq̂⁻¹) at every horizon of every window;
2. accel, with the fitted gyro model fixed: residuals Δβ_gt − Δβ̂ and Δγ_gt − Δγ̂.

Both are solved by Levenberg–Marquardt with Huber IRLS weights on the norm of each residual
3-vector (``huber_rot`` rad, ``huber_vel``; ground-truth glitches pull only linearly), in numpy
float64 (no torch: ``imu-learn calibrate`` never loads it), the per-sample chains in the core
(``rotation_window_sums``, ``velocity_window_sums``: Rust, the GIL released; their numpy oracle is
:mod:`imu_learn.core.numpy_reference`). The model is affine in its 21 (gyro) and
12 (accel) parameters, so the problem is close to linear and converges in a few iterations. The
Jacobians are exact and analytic, one pass over the windows each: for the gyro, perturbing sample
k's rate by δ rotates the increment by R(Q_k) J_r(ω_k dt) dt δ (Q_k the product up to sample k, J_r
SO(3)'s right Jacobian) and the residual by −J_r⁻¹(r) of that (:meth:`_RotResiduals.jacobian`, on the
products the residuals just computed). With the gyro fixed the accelerometer residuals are *linear*
in (M_a − I, c = M_a b_a): :class:`_VelResiduals` sums each window's rotations against the samples
once (``Φ``, per split and cutoff; the rotations once per split and gyro cutoff) and every residual
and Jacobian after that is a product with ``Φ`` (the solve stays in (M_a, b_a), the same minimum).
A weak prior (``prior`` × (M − I), ``prior`` × G, as residuals) keeps directions the training motion
does not excite at the identity. The solve stops when a step lowers the cost by at most ``tol`` of
it or moves θ by at most ``tol`` of its size: 1e-8 for the gyro (on EuRoC's five training flights the
same iterations as the torch fit this replaced, at 1e-10), 1e-12 for the accelerometer (its evaluations
are products with Φ); the parameters are the torch fit's within 2e-5 of their standard deviation
(docs/experiments/benchmarks.md, "calibrate's time").

The cutoffs are chosen from a small grid (``cutoffs_hz``, ``None`` = no filter) on the *validation*
sequences by the same residuals (RMS of |r| over windows and horizons, no prior): the gyro model is
fitted at the grid's first cutoff, every cutoff of the grid is scored on the validation windows with
that model, and the model is refitted (warm start) at the best one; then the same for the
accelerometer with the chosen gyro model fixed. (Filter and model are both linear, so they nearly
commute and the model barely depends on the cutoff; refitting per cutoff would cost a fit each.)
Without validation sequences the training windows score the grid.

Temporal calibration (``fit_offset=True``, registered as ``traditional+timing``): before the
affine model, one constant time offset tau [samples] is fitted by the 1-D search of
:mod:`imu_learn.baselines.timing` on the same gyro rotation residuals (raw samples, no model, over
``offset_window`` = 10-sample windows, 5 × ``max_windows`` of them), as
Kalibr fits a camera's time offset; both sensors are resampled by linear interpolation at
t + tau·dt, then filtered and calibrated as above (``refine`` applies them in that order). The
validation split keeps tau = 0 when the fitted offset does not lower its cost. Plain
``traditional`` keeps tau = 0 (its saved fits, with or without a ``time_offset`` entry, load as
before).

Threads: the fit runs with ``threads`` BLAS threads (default 1, at most ``settings.threads``;
:func:`imu_learn.util.threads.thread_limits`, restored afterwards; torch's pool too where torch is
loaded). It is many numpy operations of a millisecond or less: beside other CPU-bound work on two
cores a second thread waits more than it helps (when the fit ran in torch, two OpenMP threads made
it 4-5× slower than one).

``refit`` fits the affine parameters again on a part of the data with a fit's cutoffs kept and its
parameters as the start, and the time offset searched again from the fit's (a golden-section
search within ±``timing.OFFSET_BRACKET`` samples of it; the whole grid where the minimum lies at that
bracket's edge): what calibrate's uncertainty needs per recording, at a fraction of a fit's cost.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np

from imu_learn.baselines import affine
from imu_learn.baselines.affine import TraditionalParams, lowpass  # noqa: F401  (lowpass: re-exported)
from imu_learn.baselines.base import FitSettings, Method
from imu_learn.baselines.timing import RotationWindows, fit_offset_near, shifted
from imu_learn.core.integration import PAPER_FRACTIONS, rotation_window_sums, velocity_window_sums, window_labels
from imu_learn.core.quat import quat_conj, quat_log, quat_mul, so3_right_jacobian_inverse
from imu_learn.data.types import Segment, sample_rate_hz
from imu_learn.util.threads import thread_limits

DEFAULT_CUTOFFS: Tuple[Optional[float], ...] = (None, 40.0, 20.0, 10.0, 5.0)
BIAS_ONLY = {"gyro": np.r_[9:12], "acc": np.r_[9:12]}  # what a sensor in ``held`` fits: its bias alone
TOL = 1e-8  # the solve's stopping rule (relative cost decrease or step; module doc)
ACC_TOL = 1e-12  # the accelerometer stage's: a residual there is a product with Φ (~1 ms), so it runs to the end


def _gyro_model(theta: np.ndarray, g_m: np.ndarray, a_m: np.ndarray) -> np.ndarray:
    """θ (21,) = (M_g − I, b_g, G) row-major; inputs (B, W, 3) -> (B, W, 3)."""
    M = np.eye(3) + theta[:9].reshape(3, 3)
    G = theta[12:21].reshape(3, 3)
    return ((g_m - theta[9:12]).reshape(-1, 3) @ M.T - a_m.reshape(-1, 3) @ G.T).reshape(g_m.shape)


@dataclass
class _Windows:
    """Training/validation windows of one or more sequences, gathered (all float64 arrays)."""

    gyro: np.ndarray  # (B, W, 3) filtered with the gyro cutoff
    acc_g: np.ndarray  # (B, W, 3) specific force filtered with the gyro cutoff (g-sensitivity input)
    acc: np.ndarray  # (B, W, 3) filtered with the accel cutoff
    dt: np.ndarray  # (B, W)
    dq: np.ndarray  # (B, H, 4)
    dv: np.ndarray  # (B, H, 3)
    dp: np.ndarray  # (B, H, 3)
    horizons: List[int]
    key: Tuple[int, Optional[float]] = (0, None)  # (id of the _Data, the gyro cutoff): same key, same gyro windows


class _Data:
    """Per-sequence raw arrays plus window labels, so windows can be re-gathered for any cutoff."""

    def __init__(self, seqs: Seq[Segment], window: int, max_windows: int, gravity: float, order: int = 2) -> None:
        self.order = order
        self.items = []
        usable = [s for s in seqs if len(s) > window + 1]
        total = sum(len(s) - window for s in usable)
        stride = max(1, math.ceil(total / max_windows)) if max_windows > 0 else 1
        self.stride = stride
        for s in usable:
            lab = window_labels(s, window, stride, PAPER_FRACTIONS, gravity)
            if len(lab.starts) == 0:
                continue
            t = np.asarray(s.t_ns, dtype=np.int64)
            dt = np.empty(len(t))
            dt[:-1] = np.diff(t) * 1e-9
            dt[-1] = dt[-2]
            self.items.append((s, sample_rate_hz(s.t_ns), dt, lab))
        self.horizons = [int(h) for h in self.items[0][3].horizons] if self.items else []
        self.window = window
        self._cache: Dict[tuple, Any] = {}  # filtered signals and gathered windows

    def __len__(self) -> int:
        return sum(len(it[3].starts) for it in self.items)

    def _filtered(self, which: str, cutoff: Optional[float]) -> List[np.ndarray]:
        key = ("filtered", which, cutoff)
        if key not in self._cache:
            self._cache[key] = [lowpass(getattr(s, which), fs, cutoff, self.order) for s, fs, _, _ in self.items]
        return self._cache[key]  # type: ignore[return-value]

    def _gathered(self, which: str, cutoff: Optional[float] = None) -> np.ndarray:
        """The windows of one signal ("gyro"/"acc" at a cutoff, or "dt", "dq", "dv", "dp") gathered
        into one array, once per (signal, cutoff): the grid asks for the same ones many times."""
        key = ("gather", which, cutoff)
        if key not in self._cache:
            if which in ("gyro", "acc", "dt"):
                src = self._filtered(which, cutoff) if which != "dt" else [dt for _, _, dt, _ in self.items]
                self._cache[key] = self._windows_of(src)
            else:
                parts = [getattr(lab, "dq_wxyz" if which == "dq" else which) for _, _, _, lab in self.items]
                self._cache[key] = np.ascontiguousarray(np.concatenate(parts), dtype=np.float64)
        return self._cache[key]

    def _windows_of(self, src: List[np.ndarray]) -> np.ndarray:
        """Every item's windows of its signal in ``src`` (one per item, (N,) or (N, 3)), one after another
        in one array (B, W) or (B, W, 3), gathered straight into it."""
        ar = np.arange(self.window)
        counts = [len(lab.starts) for _, _, _, lab in self.items]
        out = np.empty((sum(counts), self.window) + src[0].shape[1:], dtype=np.float64)
        k = 0
        for x, (_, _, _, lab), n in zip(src, self.items, counts):
            np.take(np.asarray(x, dtype=np.float64), lab.starts.astype(np.int64)[:, None] + ar, axis=0, out=out[k:k + n])
            k += n
        return out

    def windows(self, cutoff_gyro: Optional[float], cutoff_acc: Optional[float]) -> _Windows:
        g = self._gathered
        return _Windows(gyro=g("gyro", cutoff_gyro), acc_g=g("acc", cutoff_gyro), acc=g("acc", cutoff_acc), dt=g("dt"),
                        dq=g("dq"), dv=g("dv"), dp=g("dp"), horizons=self.horizons, key=(id(self), cutoff_gyro))


class _RotResiduals:
    """Rotation residuals Log(Δq_gt ⊗ Δq̂⁻¹) (B·H·3,) of θ (21,) on fixed windows, with their exact
    Jacobian (:meth:`jacobian`). The per-sample work (the model's rates, their products and the
    Jacobian's sums) is the core's :func:`~imu_learn.core.integration.rotation_window_sums`; the last
    evaluation is kept for the Jacobian at that θ."""

    def __init__(self, w: _Windows) -> None:
        self.w = w
        self._last: Optional[Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]] = None  # (θ, Q (B, H, 4), sums)
        # within a solve (:func:`_solve`): each trial also takes the Jacobian's sums, as an accepted one
        # needs them next (one pass per iteration, not a plain pass and then a pass with sums)
        self.sums_on_call = False

    def _sums(self, theta: np.ndarray, jacobian: bool) -> Tuple[np.ndarray, Optional[np.ndarray]]:
        """Q at the horizons (B, H, 4) and, with ``jacobian``, the sums (B, H, 9, 7) at θ."""
        last = self._last
        if last is None or not np.array_equal(last[0], theta) or (jacobian and last[2] is None):
            w = self.w
            d = rotation_window_sums(w.gyro, w.acc_g, w.dt, theta, w.horizons, jacobian)
            self._last = last = (np.array(theta, dtype=np.float64), d["q_wxyz"], d["sums"])
        return last[1], last[2]

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        Q = self._sums(theta, self.sums_on_call)[0]
        return quat_log(quat_mul(self.w.dq, quat_conj(Q))).reshape(-1)

    def jacobian(self, theta: np.ndarray, r: np.ndarray, cols: Optional[np.ndarray] = None) -> np.ndarray:
        """The exact Jacobian (B·H·3, 21) at θ with residuals r; with ``cols``, its columns ``cols`` only
        (B·H·3, len(cols)).

        Perturbing sample k's rate by δ_k turns Δq̂ into Exp(ψ) Δq̂ with ψ = Σ_{k<h} R(Q_k) J_r(φ_k) dt_k δ_k
        (Q_k the product up to and including sample k, φ_k = ω_k dt_k), and the residual Log(E Exp(−ψ))
        moves by −J_r⁻¹(r) ψ; the model is affine in θ, so ∂ω_k/∂θ is exact: (g_k − b) ⊗ for M_g, −M_g
        for b_g, −a_k ⊗ for G, and Σ A_k (g_k − b) = Σ A_k g_k − (Σ A_k) b."""
        B, H = len(self.w.gyro), len(self.w.horizons)
        M = np.eye(3) + theta[:9].reshape(3, 3)
        S = self._sums(theta, True)[1].reshape(B, H, 3, 3, 7)  # type: ignore[union-attr]
        cols = np.arange(21) if cols is None else np.asarray(cols, dtype=np.int64)
        A_h = S[..., 6]  # Σ A_k (B, H, 3, 3)
        zero = np.zeros((B, H, 3, 9))
        dM = (S[..., :3] - A_h[..., None] * theta[9:12]).reshape(B, H, 3, 9) if np.any(cols < 9) else zero
        dG = -S[..., 3:6].reshape(B, H, 3, 9) if np.any(cols >= 12) else zero
        dpsi = np.concatenate((dM, -(A_h @ M), dG), axis=-1)[..., cols]  # (B, H, 3, len(cols))
        return -(so3_right_jacobian_inverse(r.reshape(B, H, 3)) @ dpsi).reshape(B * H * 3, len(cols))


class _VelResiduals:
    """Δβ/Δγ residuals (2·B·H·3,) of accelerometer parameters θ (12,) = (M_a − I, b_a) with the
    rotations fixed by the (already calibrated) gyro: R_k from the same integration, then
    Δβ_h = Σ_{k<h} R_k u_k dt_k and Δγ_h = Σ_{k<h} R_k u_k dt_k (½ dt_k + t_h − t_{k+1}), u_k = M_a (a_k − b_a).
    Linear in (D = M_a − I, c = M_a b_a): the sums of R_k dt_k against (a_k, 1) and their Δγ weights
    are taken once here (``Φ``; the core's :func:`~imu_learn.core.integration.velocity_window_sums`, the
    rotations held over each sample chained from ``rates``, the calibrated gyro), so a residual is
    y − Φ (D, c) and the Jacobian in (D, b_a) follows from Φ."""

    tol = ACC_TOL  # the solve's stopping rule here (cheap evaluations: run to the end)

    def __init__(self, rates: np.ndarray, w: _Windows) -> None:
        B, W, _ = w.acc.shape
        H = len(w.horizons)
        T = np.concatenate((np.zeros((B, 1)), np.cumsum(w.dt, axis=1)), axis=1)  # t_m = Σ_{k<m} dt_k
        # Δγ's weight ½ dt_k + t_h − t_{k+1} = t_h − s_k: Σ_{k<h} s_k (...) rides along as more columns
        S = velocity_window_sums(rates, w.acc, w.dt, w.horizons).reshape(B, H, 3, 3, 8)
        t_h = T[:, list(w.horizons)][:, :, None, None, None]
        Sx = np.stack((S[..., :4], t_h * S[..., :4] - S[..., 4:]))  # (2, B, H, 3, 3, 4): Δβ, Δγ
        # prediction Σ R dt (M a − c) = Σ_ij Sx[.., i, j] M_ij − Σ_i Sx[.., i, 3] c_i, M = I + D
        y0 = Sx[..., 0, 0] + Sx[..., 1, 1] + Sx[..., 2, 2]  # (2, B, H, 3)
        self.y = (np.stack((w.dv, w.dp)) - y0).reshape(-1)
        # Φ = (Φ_D, Φ_c) (2·B·H·3, 12): r = y − Φ (D, c), c = M_a b_a; its Gram matrix once a solve asks
        # (:meth:`normal`; residuals that only score a cut-off never do)
        self.phi = np.ascontiguousarray(np.concatenate((Sx[..., :3].reshape(2 * B * H * 3, 9),
                                                        -Sx[..., 3].reshape(2 * B * H * 3, 3)), axis=1))
        self._gram: Optional[np.ndarray] = None

    @staticmethod
    def _dc(theta: np.ndarray) -> np.ndarray:
        """(D, c) (12,) of θ = (D, b): c = (I + D) b."""
        return np.concatenate((theta[:9], (np.eye(3) + theta[:9].reshape(3, 3)) @ theta[9:12]))

    @staticmethod
    def _chain(theta: np.ndarray) -> np.ndarray:
        """∂(D, c)/∂(D, b) (12, 12): the identity on D, ∂c_i/∂D_ij = b_j, ∂c/∂b = M_a."""
        T = np.eye(12)
        for i in range(3):
            T[9 + i, 3 * i:3 * i + 3] = theta[9:12]
        T[9:, 9:] = np.eye(3) + theta[:9].reshape(3, 3)
        return T

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        return self.y - self.phi @ self._dc(theta)

    def jacobian(self, theta: np.ndarray, r: Optional[np.ndarray] = None, cols: Optional[np.ndarray] = None
                 ) -> np.ndarray:
        """The exact Jacobian (2·B·H·3, 12) at θ (r unused), or its columns ``cols``: −Φ ∂(D, c)/∂(D, b)
        (∂r/∂D_ij = −Φ_D[:, ij] − Φ_c[:, i] b_j, ∂r/∂b = −Φ_c M_a)."""
        T = self._chain(theta)
        return -self.phi @ (T if cols is None else T[:, cols])

    def normal(self, theta: np.ndarray, r: np.ndarray, w: np.ndarray, cols: Optional[np.ndarray] = None
               ) -> Tuple[np.ndarray, np.ndarray]:
        """Jᵀ W J and Jᵀ W r (W = diag(w), the IRLS weights) at θ without forming J (:func:`_lm`): with
        T = ∂(D, c)/∂(D, b), Jᵀ W J = Tᵀ (Φᵀ W Φ) T, and Φᵀ W Φ is the Gram matrix less the rows the
        weights take down (Huber's: few). ``cols``: the entries a subset frees."""
        T = self._chain(theta)
        if cols is not None:
            T = T[:, cols]
        down = np.flatnonzero(w < 1.0)
        if 4 * len(down) < len(w):
            if self._gram is None:
                self._gram = self.phi.T @ self.phi
            P = self.phi[down]
            G = self._gram - P.T @ (P * (1.0 - w[down])[:, None])
        else:
            G = self.phi.T @ (self.phi * w[:, None])
        return T.T @ G @ T, -(T.T @ (self.phi.T @ (w * r)))


def _rms(res: Callable[[np.ndarray], np.ndarray], theta: np.ndarray) -> float:
    """RMS over windows and horizons of the norm of each 3-vector residual."""
    r = res(np.asarray(theta, dtype=np.float64)).reshape(-1, 3)
    return float(np.sqrt((r * r).sum(-1).mean()))


def _norms(r: np.ndarray) -> np.ndarray:
    r3 = r.reshape(-1, 3)
    return np.sqrt((r3 * r3).sum(-1))


def _huber_weights(r: np.ndarray, delta: float) -> np.ndarray:
    """IRLS weights of the Huber loss on the norm of each 3-vector of r (R,), repeated per component."""
    n = _norms(r)
    return np.repeat(np.where(n <= delta, 1.0, delta / np.maximum(n, 1e-300)), 3)


def _huber_cost(r: np.ndarray, delta: float) -> float:
    n = _norms(r)
    return float(np.where(n <= delta, 0.5 * n * n, delta * (n - 0.5 * delta)).sum())


class Subset:
    """Residuals of a full θ restricted to its ``free`` entries, the rest held at ``full``'s values."""

    def __init__(self, res: Any, free: np.ndarray, full: np.ndarray) -> None:
        self.res, self.free, self.full = res, np.asarray(free), np.asarray(full, dtype=np.float64)

    def theta(self, x: np.ndarray) -> np.ndarray:
        th = self.full.copy()
        th[self.free] = x
        return th

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.res(self.theta(x))

    def jacobian(self, x: np.ndarray, r: np.ndarray) -> np.ndarray:
        return self.res.jacobian(self.theta(x), r, self.free)

    def normal(self, x: np.ndarray, r: np.ndarray, w: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        if hasattr(self.res, "normal"):
            return self.res.normal(self.theta(x), r, w, self.free)
        return _weighted_normal(self.jacobian(x, r), r, w)


def _solve(res: Any, x0: np.ndarray, prior_idx: np.ndarray, prior: float, delta: float, max_iter: int,
           tol: Optional[float] = None, free: Optional[np.ndarray] = None) -> np.ndarray:
    """Levenberg–Marquardt with Huber IRLS weights on Σ ρ_δ(|r_j(θ)|) + ½ prior² |θ[prior_idx]|²
    (``free``: over those entries of θ alone, the others held at ``x0``'s values).

    ``res(θ)`` gives the residuals (R,) and ``res.jacobian(θ, r)`` their exact Jacobian (R, P) (both
    of :meth:`Traditional.fit`'s stages have one). Stops when a step lowers the cost by at most
    ``tol`` of it or moves θ by at most ``tol`` (1 + |θ|) (default: the residuals' own ``tol``, else
    :data:`TOL`), or when no damping finds a lower cost; a step whose predicted decrease (the
    iteration's quadratic model) or length is that small is not evaluated (:func:`_converged`)."""
    if free is not None:
        free = np.asarray(free, dtype=np.int64)
        out = np.array(x0, dtype=np.float64)
        out[free] = _solve(Subset(res, free, out), out[free], np.flatnonzero(np.isin(free, prior_idx)), prior, delta,
                           max_iter, getattr(res, "tol", TOL) if tol is None else tol)
        return out
    tol = getattr(res, "tol", TOL) if tol is None else tol
    P = len(x0)
    pmask = np.zeros(P)
    pmask[np.asarray(prior_idx, dtype=np.int64)] = prior * prior

    def cost(x: np.ndarray, r: np.ndarray) -> float:
        return _huber_cost(r, delta) + 0.5 * float((pmask * x * x).sum())

    inner = getattr(res, "res", res)  # a level's subset wraps the residuals
    if hasattr(inner, "sums_on_call"):
        inner.sums_on_call = True
        try:
            return _lm(res, x0, cost, delta, max_iter, tol, pmask)
        finally:
            inner.sums_on_call = False
    return _lm(res, x0, cost, delta, max_iter, tol, pmask)


def _weighted_normal(J: np.ndarray, r: np.ndarray, w: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Jᵀ W J and Jᵀ W r of a Jacobian J (R, P), W = diag(w)."""
    Jw = J * w[:, None]
    return J.T @ Jw, Jw.T @ r


def _normal(res: Any, x: np.ndarray, r: np.ndarray, w: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Jᵀ W J (P, P) and Jᵀ W r (P,) at x: the residuals' own ``normal`` where they have one (linear
    residuals: without forming J), else from ``jacobian``."""
    if hasattr(res, "normal"):
        return res.normal(x, r, w)
    return _weighted_normal(res.jacobian(x, r), r, w)


def _converged(d: np.ndarray, x: np.ndarray, c: float, decrease: float, tol: float) -> bool:
    """:func:`_solve`'s stopping rule: a step d from x that moves θ by at most ``tol`` (1 + |x|) or lowers
    the cost c by at most ``tol`` of it (taken, or as the iteration's quadratic model predicts it)."""
    return float(np.linalg.norm(d)) <= tol * (1.0 + float(np.linalg.norm(x))) or decrease <= tol * c


def _lm(res: Any, x0: np.ndarray, cost: Callable[[np.ndarray, np.ndarray], float], delta: float, max_iter: int,
        tol: float, pmask: np.ndarray) -> np.ndarray:
    """:func:`_solve`'s iterations."""
    x = np.array(x0, dtype=np.float64)
    r = res(x)
    c = cost(x, r)
    lam = 1e-3
    for _ in range(max_iter):
        A, g = _normal(res, x, r, _huber_weights(r, delta))
        A, g = A + np.diag(pmask), g + pmask * x
        improved = False
        for attempt in range(10):
            d = np.linalg.solve(A + lam * np.diag(np.diagonal(A)), -g)
            if attempt == 0 and _converged(d, x, c, -float(g @ d + 0.5 * d @ A @ d), tol):
                return x  # the step the model offers is below the tolerance: not worth a pass over the windows
            xn = x + d
            rn = res(xn)
            cn = cost(xn, rn)
            if cn < c:
                improved = True
                break
            lam *= 10.0
        if not improved:
            break
        small = _converged(d, x, c, c - cn, tol)
        x, r, c = xn, rn, cn
        lam = max(lam / 10.0, 1e-9)
        if small:
            break
    return x


class Traditional(Method):
    """Low-pass filter + intrinsic model (scale, misalignment, bias, g-sensitivity) per sensor."""

    name = "traditional"
    rotation_only = False
    save_suffix = ".json"

    def __init__(
        self,
        cutoffs_hz: Seq[Optional[float]] = DEFAULT_CUTOFFS,
        filter_order: int = 2,
        window: Optional[int] = None,
        max_windows: int = 1000,
        prior: float = 1e-3,
        huber_rot: float = 0.01,
        huber_vel: float = 0.1,
        max_iter: int = 20,
        fit_offset: bool = False,
        max_shift: float = 3.0,
        offset_window: int = 10,
        threads: int = 1,
        held: Tuple[str, ...] = (),
    ) -> None:
        self.cutoffs_hz = tuple(cutoffs_hz)
        self.filter_order = filter_order
        self.window = window
        self.max_windows = max_windows
        self.prior = prior
        self.huber_rot = huber_rot
        self.huber_vel = huber_vel
        self.max_iter = max_iter
        self.fit_offset = fit_offset
        self.max_shift = max_shift
        self.offset_window = offset_window
        self.threads = threads
        # the sensors ("gyro", "acc") whose bias alone is fitted, their matrix (and the gyro's G) held at the
        # identity (zero): a reference that cannot resolve accelerations observes the acc bias only
        self.held = tuple(held)
        self.params = TraditionalParams.identity()

    # -- applying the model ---------------------------------------------------------------------

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        return affine.apply(self.params, seq.t_ns, seq.gyro, seq.acc, self.filter_order)

    # -- fitting --------------------------------------------------------------------------------

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        with thread_limits(min(self.threads, settings.threads)):
            return self._fit(train, val, settings)

    def _offset_first(self, train: List[Segment], val: List[Segment], settings: FitSettings,
                      shift_val: bool = True, start: Optional[float] = None
                      ) -> Tuple[int, float, Dict[str, list], List[Segment], List[Segment]]:
        """What :meth:`fit` and :meth:`refit` do first: the window and (``fit_offset``) the time
        offset (searched from ``start`` where given), with the training split (and ``val`` where
        ``shift_val``) resampled at it.
        Returns (window, tau, its log, train, val)."""
        window = int(self.window or settings.window)
        if not self.fit_offset:
            return window, 0.0, {}, train, val
        if not any(len(s) > window for s in train):
            raise ValueError(f"no training sequence is longer than the window ({window} samples)")
        tau, tau_log = self._fit_time_offset(train, val, self.offset_window, settings.gravity, start)
        return (window, tau, tau_log, [shifted(s, tau) for s in train],
                [shifted(s, tau) for s in val] if shift_val else val)

    def _fit(self, train: List[Segment], val: List[Segment], settings: FitSettings) -> Dict[str, list]:
        window, tau, tau_log, train, val = self._offset_first(train, val, settings)
        tr = _Data(train, window, self.max_windows, settings.gravity, self.filter_order)
        if len(tr) == 0:
            raise ValueError(f"no training sequence is longer than the window ({window} samples)")
        va = _Data(val, window, self.max_windows, settings.gravity, self.filter_order) if val else tr
        if len(va) == 0:
            va = tr
        fs = min(it[1] for it in tr.items)
        grid = [c for c in self.cutoffs_hz if c is None or c < 0.5 * fs] or [None]
        g_idx, a_idx = np.r_[0:9, 12:21], np.r_[0:9]

        # 1. gyro: fit at the first cutoff, score the grid on validation, refit at the chosen one.
        def rot(w: _Windows) -> _RotResiduals:
            return _RotResiduals(w)

        theta_g, c_g, val_rot, wg = self._fit_at_best_cutoff(
            rot, lambda c: tr.windows(c, None), lambda c: va.windows(c, None), grid, np.zeros(21), g_idx, self.huber_rot,
            self._free("gyro"))
        g_before, g_after = _rms(rot(wg), np.zeros(21)), _rms(rot(wg), theta_g)

        # 2. accel with the gyro model fixed: the same on velocity/position residuals (the rotations
        # depend on the gyro windows only, not on the accelerometer's cutoff: computed once per split).
        rates: Dict[Tuple[int, Optional[float]], np.ndarray] = {}
        sums: Dict[Tuple[Tuple[int, Optional[float]], int], _VelResiduals] = {}

        def vel(w: _Windows) -> _VelResiduals:
            if w.key not in rates:
                rates[w.key] = _gyro_model(theta_g, w.gyro, w.acc_g)
            if (w.key, id(w.acc)) not in sums:
                sums[(w.key, id(w.acc))] = _VelResiduals(rates[w.key], w)
            return sums[(w.key, id(w.acc))]

        theta_a, c_a, val_vel, wa = self._fit_at_best_cutoff(
            vel, lambda c: tr.windows(c_g, c), lambda c: va.windows(c_g, c), grid, np.zeros(12), a_idx, self.huber_vel,
            self._free("acc"))
        # "before" = raw IMU (identity model, no filter) on the same windows
        raw = tr.windows(None, None)
        a_before = _rms(_VelResiduals(raw.gyro, raw), np.zeros(12))  # the identity gyro model: the raw rates
        a_after = _rms(vel(wa), theta_a)

        self.params = TraditionalParams(
            M_g=np.eye(3) + theta_g[:9].reshape(3, 3), b_g=theta_g[9:12].copy(), G=theta_g[12:21].reshape(3, 3).copy(),
            M_a=np.eye(3) + theta_a[:9].reshape(3, 3), b_a=theta_a[9:12].copy(),
            cutoff_gyro=c_g, cutoff_acc=c_a, time_offset=tau,
        )
        # Losses: RMS over the training windows/horizons of |residual| before (raw IMU) and after the
        # fit, rotation [rad] and velocity+position [m/s, m]; train_loss adds the two (unitless sum).
        log: Dict[str, list] = {
            "cutoffs_hz": grid, "val_rot_rmse": val_rot, "val_vel_rmse": val_vel,
            "gyro_loss": [g_before, g_after], "acc_loss": [a_before, a_after],
            "train_loss": [g_before + a_before, g_after + a_after],
            "cutoff_gyro": [c_g], "cutoff_acc": [c_a], "train_windows": [len(tr)], "stride": [tr.stride],
            **tau_log,
        }
        return log

    def refit(self, train: List[Segment], val: List[Segment], start: TraditionalParams,
              settings: FitSettings = FitSettings()) -> Dict[str, list]:
        """The affine parameters alone on other data (a part of what ``start`` was fitted on):
        ``start``'s cutoffs kept (no grid, ``val`` selects nothing but the time offset), its parameters
        the starting point of both stages; with ``fit_offset`` the time offset is searched again as
        :meth:`fit` does. What calibrate's uncertainty refits per recording: the same estimator of
        the affine model and the offset at a fraction of a fit's cost."""
        with thread_limits(min(self.threads, settings.threads)):
            return self._refit(train, val, start, settings)

    def _refit(self, train: List[Segment], val: List[Segment], start: TraditionalParams,
               settings: FitSettings) -> Dict[str, list]:
        window, tau, tau_log, train, _ = self._offset_first(train, val, settings, shift_val=False,
                                                            start=start.time_offset)
        tr = _Data(train, window, self.max_windows, settings.gravity, self.filter_order)
        if len(tr) == 0:
            raise ValueError(f"no training sequence is longer than the window ({window} samples)")
        w = tr.windows(start.cutoff_gyro, start.cutoff_acc)
        g0 = np.concatenate([(start.M_g - np.eye(3)).ravel(), start.b_g, start.G.ravel()])
        a0 = np.concatenate([(start.M_a - np.eye(3)).ravel(), start.b_a])
        theta_g = _solve(_RotResiduals(w), g0, np.r_[0:9, 12:21], self.prior, self.huber_rot, self.max_iter,
                         free=self._free("gyro"))
        vel = _VelResiduals(_gyro_model(theta_g, w.gyro, w.acc_g), w)
        theta_a = _solve(vel, a0, np.r_[0:9], self.prior, self.huber_vel, self.max_iter, free=self._free("acc"))
        self.params = TraditionalParams(
            M_g=np.eye(3) + theta_g[:9].reshape(3, 3), b_g=theta_g[9:12].copy(), G=theta_g[12:21].reshape(3, 3).copy(),
            M_a=np.eye(3) + theta_a[:9].reshape(3, 3), b_a=theta_a[9:12].copy(),
            cutoff_gyro=start.cutoff_gyro, cutoff_acc=start.cutoff_acc, time_offset=tau,
        )
        return {"train_windows": [len(tr)], "stride": [tr.stride], **tau_log}

    def _fit_time_offset(self, train: List[Segment], val: List[Segment], window: int, gravity: float,
                         start: Optional[float] = None) -> Tuple[float, Dict[str, list]]:
        """The temporal calibration: tau [samples] by the timing baseline's 1-D search on the raw
        gyro's rotation residuals over ``offset_window``-sample training windows (short, for the
        reason :mod:`imu_learn.baselines.timing` gives), kept only if it lowers the validation cost.
        With ``start`` (a refit): a golden-section search within ±``timing.OFFSET_BRACKET`` samples of it,
        the whole grid where its minimum lies at the bracket's edge."""
        tr = RotationWindows(train, window, 5 * self.max_windows, gravity)
        tau = fit_offset_near(tr, start, self.max_shift, 0.25, 1e-3, self.huber_rot)
        va = RotationWindows(val, window, 5 * self.max_windows, gravity) if val else tr
        va = va if len(va) else tr
        zero, got = va.cost(0.0, self.huber_rot), va.cost(tau, self.huber_rot)
        kept = tau if got < zero else 0.0
        return kept, {"tau_samples": [kept], "tau_fitted": [tau], "tau_val_cost": [zero, got]}

    def _free(self, sensor: str) -> Optional[np.ndarray]:
        """The entries of ``sensor``'s θ that are fitted (None: all)."""
        return BIAS_ONLY[sensor] if sensor in self.held else None

    def _fit_at_best_cutoff(self, residuals: Callable, train_at: Callable, val_at: Callable, grid: list,
                            theta0: np.ndarray, idx: np.ndarray, huber: float, free: Optional[np.ndarray] = None
                            ) -> tuple:
        """One stage of :meth:`fit`: solve at the grid's first cutoff, score every cutoff on the
        validation windows, re-solve at the best one (the prior on ``idx``; ``free``: only those entries
        solved, :func:`_solve`). Returns (theta, chosen cutoff, validation RMS per cutoff, the training
        windows at the chosen cutoff)."""
        first = grid[0]
        theta = _solve(residuals(train_at(first)), theta0, idx, self.prior, huber, self.max_iter, free=free)
        val = [_rms(residuals(val_at(c)), theta) for c in grid]
        chosen = grid[int(np.argmin(val))]
        windows = train_at(chosen)
        if chosen != first:
            theta = _solve(residuals(windows), theta, idx, self.prior, huber, self.max_iter, free=free)
        return theta, chosen, val, windows

    # -- persistence ----------------------------------------------------------------------------

    def to_dict(self) -> dict:
        p = self.params
        return {
            "method": self.name, "M_g": p.M_g.tolist(), "b_g": p.b_g.tolist(), "G": p.G.tolist(),
            "M_a": p.M_a.tolist(), "b_a": p.b_a.tolist(), "cutoff_gyro": p.cutoff_gyro, "cutoff_acc": p.cutoff_acc,
            "filter_order": self.filter_order, "time_offset": p.time_offset,
        }

    def save(self, path: Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2))

    def load(self, path: Path) -> Traditional:
        d = json.loads(Path(path).read_text())
        if d.get("method") != self.name:
            raise ValueError(f"{path} holds {d.get('method')!r} parameters, not {self.name!r}")
        self.filter_order = int(d.get("filter_order", self.filter_order))
        self.params = TraditionalParams.from_dict(d)
        return self


class TraditionalTiming(Traditional):
    """``traditional`` with its temporal calibration: a time offset fitted first, then the model."""

    name = "traditional+timing"

    def __init__(self, *args, fit_offset: bool = True, **kwargs) -> None:
        super().__init__(*args, fit_offset=fit_offset, **kwargs)
