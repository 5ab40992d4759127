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
evaluation uses (the scheme of :func:`imu_learn.nn.integration.integrate`, in float64; agrees with
the core's ``integrate_windows`` to ~1e-15), on short windows of the
training sequences (``window`` samples, labels at the paper's fractions of it):

1. gyro: residuals Log(Δq_gt ⊗ Δq̂⁻¹) at every horizon of every window;
2. accel, with the fitted gyro model fixed: residuals Δβ_gt − Δβ̂ and Δγ_gt − Δγ̂.

Both are solved by Levenberg–Marquardt with Huber IRLS weights on the norm of each residual
3-vector (``huber_rot`` rad, ``huber_vel``; ground-truth glitches pull only linearly), in torch
float64. The model is affine in its 21 (gyro) and 12 (accel) parameters, so the problem is close
to linear and converges in a few iterations (about five). The Jacobians are exact and analytic, one
pass over the windows each: for the gyro, perturbing sample k's rate by δ rotates the increment by
R(Q_k) J_r(ω_k dt) dt δ (Q_k the product up to sample k, J_r SO(3)'s right Jacobian) and the residual
by −J_r⁻¹(r) of that (:func:`_rot_jacobian`); the velocity/position residuals are bilinear in
(M_a, b_a) (:meth:`_VelResiduals.jacobian`). They agree with central differences to ~1e-11 relative,
and replaced forward differences with every parameter perturbed in one batched evaluation (22 and
13 integrations per iteration, ~6e-8 relative error): the same parameters to ~1e-8, 10× less work.
The rotation residuals only need the products up to the horizons
(:func:`rotation_increments`), and with the gyro fixed the accelerometer residuals are cumulative
sums over fixed rotations (:class:`_VelResiduals`; those rotations are computed once per split and
gyro cutoff, not per accelerometer cutoff). A weak prior (``prior`` × (M − I), ``prior`` × G,
as residuals) keeps directions the training motion does not excite at the identity.

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

Threads: the fit runs with ``threads`` torch threads (default 1, at most ``settings.threads``;
:func:`imu_learn.util.threads.thread_limits`, restored afterwards). It is thousands of operations
of a few milliseconds each: beside other CPU-bound work on two cores, two OpenMP threads made the
EuRoC fit and its refits 4-5× slower than one (41-60 s against 9-14 s: every parallel region waits
for its descheduled second thread); what a second thread gains on an idle machine was not measured.

``refit`` fits the affine parameters again on a part of the data with a fit's cutoffs kept and its
parameters as the start (the time offset searched again): what calibrate's uncertainty needs per
recording, at a fraction of a fit's cost.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np
import torch

from imu_learn.baselines import affine
from imu_learn.baselines.affine import TraditionalParams, lowpass  # noqa: F401  (lowpass: re-exported)
from imu_learn.baselines.base import FitSettings, Method
from imu_learn.baselines.timing import RotationWindows, fit_offset, shifted
from imu_learn.core.integration import PAPER_FRACTIONS, window_labels
from imu_learn.data.types import Segment, sample_rate_hz
from imu_learn.nn.so3 import quat_conj, quat_mul, so3_exp, so3_log
from imu_learn.util.threads import thread_limits

Tensor = torch.Tensor

DEFAULT_CUTOFFS: Tuple[Optional[float], ...] = (None, 40.0, 20.0, 10.0, 5.0)
ACC_BIAS_ONLY = 1e6  # ``acc_prior`` that holds M_a at the identity (|M_a - I| below 1e-9 on real data)


def _gyro_model(theta: Tensor, g_m: Tensor, a_m: Tensor) -> Tensor:
    """θ (..., 21) = (M_g − I, b_g, G) row-major; inputs (B, W, 3) -> (..., B, W, 3)."""
    lead = theta.shape[:-1]
    M = torch.eye(3, dtype=theta.dtype) + theta[..., :9].reshape(*lead, 3, 3)
    b = theta[..., 9:12].reshape(*lead, 1, 1, 3)
    G = theta[..., 12:21].reshape(*lead, 3, 3)
    return torch.einsum("...ij,...bwj->...bwi", M, g_m - b) - torch.einsum("...ij,bwj->...bwi", G, a_m)


def _acc_model(theta: Tensor, a_m: Tensor) -> Tensor:
    """θ (..., 12) = (M_a − I, b_a); input (B, W, 3) -> (..., B, W, 3)."""
    lead = theta.shape[:-1]
    M = torch.eye(3, dtype=theta.dtype) + theta[..., :9].reshape(*lead, 3, 3)
    b = theta[..., 9:12].reshape(*lead, 1, 1, 3)
    return torch.einsum("...ij,...bwj->...bwi", M, a_m - b)


@dataclass
class _Windows:
    """Training/validation windows of one or more sequences, gathered (all float64 tensors)."""

    gyro: Tensor  # (B, W, 3) filtered with the gyro cutoff
    acc_g: Tensor  # (B, W, 3) specific force filtered with the gyro cutoff (g-sensitivity input)
    acc: Tensor  # (B, W, 3) filtered with the accel cutoff
    dt: Tensor  # (B, W)
    dq: Tensor  # (B, H, 4)
    dv: Tensor  # (B, H, 3)
    dp: Tensor  # (B, H, 3)
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
        self._cache: Dict[tuple, object] = {}  # filtered signals and gathered windows

    def __len__(self) -> int:
        return sum(len(it[3].starts) for it in self.items)

    def _filtered(self, which: str, cutoff: Optional[float]) -> List[np.ndarray]:
        key = ("filtered", which, cutoff)
        if key not in self._cache:
            self._cache[key] = [lowpass(getattr(s, which), fs, cutoff, self.order) for s, fs, _, _ in self.items]
        return self._cache[key]  # type: ignore[return-value]

    def _gathered(self, which: str, cutoff: Optional[float] = None) -> Tensor:
        """The windows of one signal ("gyro"/"acc" at a cutoff, or "dt", "dq", "dv", "dp") gathered
        into one tensor, once per (signal, cutoff): the grid asks for the same ones many times."""
        key = ("gather", which, cutoff)
        if key not in self._cache:
            ar = np.arange(self.window)
            if which in ("gyro", "acc"):
                src = self._filtered(which, cutoff)
                parts = [src[i][lab.starts.astype(np.int64)[:, None] + ar] for i, (_, _, _, lab) in enumerate(self.items)]
            elif which == "dt":
                parts = [dt[lab.starts.astype(np.int64)[:, None] + ar] for _, _, dt, lab in self.items]
            else:
                parts = [getattr(lab, "dq_wxyz" if which == "dq" else which) for _, _, _, lab in self.items]
            self._cache[key] = torch.from_numpy(np.ascontiguousarray(np.concatenate(parts), dtype=np.float64))
        return self._cache[key]

    def windows(self, cutoff_gyro: Optional[float], cutoff_acc: Optional[float]) -> _Windows:
        g = self._gathered
        return _Windows(gyro=g("gyro", cutoff_gyro), acc_g=g("acc", cutoff_gyro), acc=g("acc", cutoff_acc), dt=g("dt"),
                        dq=g("dq"), dv=g("dv"), dp=g("dp"), horizons=self.horizons, key=(id(self), cutoff_gyro))


def _tree_product(q: Tensor) -> Tensor:
    """Ordered product q[..., 0, :] ⊗ q[..., 1, :] ⊗ ... along dim -2 by pairwise reduction."""
    while q.shape[-2] > 1:
        if q.shape[-2] % 2:
            ident = torch.zeros_like(q[..., :1, :])
            ident[..., 0] = 1.0
            q = torch.cat((q, ident), dim=-2)
        q = quat_mul(q[..., 0::2, :], q[..., 1::2, :])
    return q[..., 0, :]


def rotation_increments(gyro: Tensor, dt: Tensor, horizons: Seq[int]) -> Tensor:
    """Δq (..., H, 4) after the first h samples, h in ``horizons`` (increasing): the same zero-order
    hold as :func:`imu_learn.nn.integration.integrate`, but only the products up to the horizons
    (pairwise within each segment between horizons, then chained), so about W quaternion products
    instead of W·log2 W. gyro (..., W, 3), dt broadcastable to (..., W)."""
    step = so3_exp(gyro * dt.unsqueeze(-1))
    out, acc, prev = [], None, 0
    for h in horizons:
        seg = _tree_product(step[..., prev:h, :])
        acc = seg if acc is None else quat_mul(acc, seg)
        out.append(acc)
        prev = h
    return torch.stack(out, dim=-2)


def _rot_residuals(theta: Tensor, w: _Windows) -> Tensor:
    """θ (K, 21) -> (K, B·H·3) residuals Log(Δq_gt ⊗ Δq̂⁻¹)."""
    dq = rotation_increments(_gyro_model(theta, w.gyro, w.acc_g), w.dt, w.horizons)
    return so3_log(quat_mul(w.dq, quat_conj(dq))).reshape(theta.shape[0], -1)


class _RotResiduals:
    """:func:`_rot_residuals` on fixed windows, with its exact Jacobian (:func:`_rot_jacobian`)."""

    def __init__(self, w: _Windows) -> None:
        self.w = w

    def __call__(self, theta: Tensor) -> Tensor:
        return _rot_residuals(theta, self.w)

    def jacobian(self, theta: Tensor, r: Tensor) -> Tensor:
        return _rot_jacobian(theta, r, self.w)


def _so3_jacobian_coefficients(t2: Tensor, inverse: bool) -> Tuple[Tensor, Tensor]:
    """(c1, c2) of J_r = I − c1 [φ]× + c2 [φ]×² (or of its inverse) at θ² = ``t2``."""
    small = t2 < 1e-8
    t2s = torch.where(small, torch.ones_like(t2), t2)
    t = torch.sqrt(t2s)
    if inverse:
        c2 = torch.where(small, torch.full_like(t2, 1.0 / 12.0), 1.0 / t2s - (1.0 + torch.cos(t)) / (2.0 * t * torch.sin(t)))
        return torch.full_like(t2, -0.5), c2
    c1 = torch.where(small, 0.5 - t2 / 24.0, (1.0 - torch.cos(t)) / t2s)
    c2 = torch.where(small, 1.0 / 6.0 - t2 / 120.0, (t - torch.sin(t)) / (t2s * t))
    return c1, c2


def _so3_jacobian(phi: Tensor, inverse: bool) -> Tensor:
    """The right Jacobian J_r(φ) of SO(3) (Exp(φ + δ) ≈ Exp(φ) Exp(J_r δ)), or its inverse, (..., 3, 3):
    J_r = I − c1 [φ]× + c2 [φ]×² with c1 = (1 − cos θ)/θ², c2 = (θ − sin θ)/θ³; J_r⁻¹ = I + ½ [φ]× +
    (1/θ² − (1 + cos θ)/(2θ sin θ)) [φ]×²; [φ]×² = φφᵀ − θ² I. Written out entry by entry."""
    x, y, z = phi.unbind(-1)
    t2 = x * x + y * y + z * z
    c1, c2 = _so3_jacobian_coefficients(t2, inverse)
    a = 1.0 - c2 * t2
    cx, cy, cz = c1 * x, c1 * y, c1 * z
    xy, xz, yz = c2 * x * y, c2 * x * z, c2 * y * z
    return torch.stack((a + c2 * x * x, xy + cz, xz - cy, xy - cz, a + c2 * y * y, yz + cx, xz + cy, yz - cx,
                        a + c2 * z * z), dim=-1).reshape(*phi.shape[:-1], 3, 3)


def _quat_matrix(q: Tensor) -> Tensor:
    """Rotation matrix (..., 3, 3) of unit quaternions (..., 4) (w, x, y, z)."""
    w, x, y, z = q.unbind(-1)
    xx, yy, zz, xy, xz, yz, wx, wy, wz = x * x, y * y, z * z, x * y, x * z, y * z, w * x, w * y, w * z
    return torch.stack((1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy), 2 * (xy + wz), 1 - 2 * (xx + zz),
                        2 * (yz - wx), 2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)), dim=-1).reshape(*q.shape[:-1], 3, 3)


def _horizon_sums(A: Tensor, f: Tensor, horizons: Seq[int]) -> Tensor:
    """Σ_{k<h} A_k ⊗ f_k (B, H, 3, 3, F) for A (B, W, 3, 3), f (B, W, F): one batched matrix product per
    stretch between horizons, then chained."""
    B, W = A.shape[:2]
    At = A.reshape(B, W, 9).transpose(1, 2)
    out, acc, prev = [], None, 0
    for h in horizons:
        seg = At[:, :, prev:h] @ f[:, prev:h]  # (B, 9, F)
        acc = seg if acc is None else acc + seg
        out.append(acc)
        prev = h
    return torch.stack(out, dim=1).reshape(B, len(out), 3, 3, f.shape[-1])


def _rot_jacobian(theta: Tensor, r: Tensor, w: _Windows) -> Tensor:
    """The exact Jacobian (B·H·3, 21) of :func:`_rot_residuals` at θ (21,) with residuals r (B·H·3,).

    Perturbing sample k's rate by δ_k turns Δq̂ into Exp(ψ) Δq̂ with ψ = Σ_{k<h} R(Q_k) J_r(ω_k dt_k) dt_k δ_k
    (Q_k the product up to and including sample k), and the residual Log(E Exp(−ψ)) moves by
    −J_r⁻¹(r) ψ; the model is affine in θ, so ∂ω_k/∂θ is exact. One pass over the windows instead of
    one integration per parameter (the forward differences this replaces)."""
    B, W, _ = w.gyro.shape
    M = torch.eye(3, dtype=theta.dtype) + theta[:9].reshape(3, 3)
    b = theta[9:12]
    phi = _gyro_model(theta[None], w.gyro, w.acc_g)[0] * w.dt.unsqueeze(-1)
    # A_k = R(Q_k) J_r(φ_k) dt_k column by column: J_r = a I − c1 [φ]× + c2 φφᵀ, a = 1 − c2 θ², so
    # A[:, j] = (a R_j − c1 (R [φ]×)_j + c2 φ_j R φ) dt with R_j the columns of R(Q_k)
    R = _quat_matrix(_prefix_rotations(so3_exp(phi)))
    R0, R1, R2 = R[..., 0], R[..., 1], R[..., 2]
    x, y, z = (c.unsqueeze(-1) for c in phi.unbind(-1))
    c1, c2 = _so3_jacobian_coefficients((phi * phi).sum(-1, keepdim=True), False)
    a, Rphi, dt = 1.0 - c2 * (x * x + y * y + z * z), x * R0 + y * R1 + z * R2, w.dt.unsqueeze(-1)
    A = torch.stack(((a * R0 - c1 * (z * R1 - y * R2) + c2 * x * Rphi) * dt,
                     (a * R1 - c1 * (x * R2 - z * R0) + c2 * y * Rphi) * dt,
                     (a * R2 - c1 * (y * R0 - x * R1) + c2 * z * Rphi) * dt), dim=-1)  # (B, W, 3, 3)
    H = len(w.horizons)
    f = torch.cat((w.gyro - b, w.acc_g, torch.ones_like(w.dt).unsqueeze(-1)), dim=-1)  # (B, W, 7)
    S = _horizon_sums(A, f, w.horizons)  # Σ_{k<h} A_k ⊗ f_k
    dM, dG, A_h = S[..., :3].reshape(B, H, 3, 9), S[..., 3:6].reshape(B, H, 3, 9), S[..., 6]
    dpsi = torch.cat((dM, -(A_h @ M), -dG), dim=-1)  # (B, H, 3, 21)
    return -(_so3_jacobian(r.reshape(B, H, 3), True) @ dpsi).reshape(B * H * 3, 21)


def _prefix_rotations(step: Tensor) -> Tensor:
    """Inclusive prefix product along dim 1 of quaternions (B, W, 4): out[:, k] = step[:, 0] ⊗ ... ⊗ step[:, k],
    chained sample by sample (the integration's own order) over (B,) columns in numpy: W small products
    cost less than a log-depth scan's W·log2 W on this size."""
    s = np.ascontiguousarray(step.detach().numpy().transpose(1, 2, 0))  # (W, 4, B)
    out = np.empty_like(s)
    w, x, y, z = out[0] = s[0]
    for k in range(1, s.shape[0]):
        bw, bx, by, bz = s[k]
        w, x, y, z = (w * bw - x * bx - y * by - z * bz, w * bx + x * bw + y * bz - z * by,
                      w * by - x * bz + y * bw + z * bx, w * bz + x * by - y * bx + z * bw)
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = w, x, y, z
    return torch.from_numpy(np.ascontiguousarray(out.transpose(2, 0, 1)))


def _held_rotations(gyro: Tensor, dt: Tensor) -> Tensor:
    """Rotation matrices (B, W, 3, 3) in force while each sample is held (R_0 = I, R_{i+1} = R_i Exp(ω_i dt_i))."""
    incl = _prefix_rotations(so3_exp(gyro * dt.unsqueeze(-1)))
    ident = torch.zeros_like(incl[:, :1])
    ident[..., 0] = 1.0
    return _quat_matrix(torch.cat((ident, incl[:, :-1]), dim=1))


class _VelResiduals:
    """Δβ/Δγ residuals for accelerometer parameters θ (K, 12) with the rotations fixed by the
    (already calibrated) gyro: R_i from the same integration, then Δβ, Δγ are cumulative sums.
    ``Rm``: those rotations (:func:`_held_rotations` of ``gyro``) when already computed (they do not
    depend on the accelerometer's cutoff)."""

    def __init__(self, gyro: Optional[Tensor], w: _Windows, Rm: Optional[Tensor] = None) -> None:
        self.Rm = _held_rotations(gyro, w.dt) if Rm is None else Rm
        self.cols = [self.Rm[..., j].contiguous() for j in range(3)]
        self.w = w
        self.idx = torch.as_tensor([h - 1 for h in w.horizons], dtype=torch.long)

    def jacobian(self, theta: Tensor, r: Optional[Tensor] = None) -> Tensor:
        """The exact Jacobian (2·B·H·3, 12) of the residuals at θ (12,) (r unused: the residuals are
        bilinear in (M_a, b_a)): Δβ_h = Σ_{k<h} R_k u_k dt_k and Δγ_h = Σ_{k<h} R_k u_k dt_k (½ dt_k + t_h − t_{k+1}),
        u_k = M_a (a_k − b_a)."""
        w = self.w
        B, W, _ = w.acc.shape
        H = len(w.horizons)
        M = torch.eye(3, dtype=theta.dtype) + theta[:9].reshape(3, 3)
        T = torch.cat((torch.zeros_like(w.dt[:, :1]), torch.cumsum(w.dt, dim=1)), dim=1)  # t_m = Σ_{k<m} dt_k
        # Δγ's weight ½ dt_k + t_h − t_{k+1} = t_h − s_k: Σ_{k<h} s_k (...) rides along as more columns
        s = (T[:, 1:] - 0.5 * w.dt).unsqueeze(-1)
        f = torch.cat((w.acc - theta[9:12], torch.ones_like(s)), dim=-1)  # (B, W, 4)
        S = _horizon_sums(self.Rm * w.dt[..., None, None], torch.cat((f, s * f), dim=-1), w.horizons)
        t_h = T[:, list(w.horizons)][:, :, None, None, None]
        out = []
        for Sx in (S[..., :4], t_h * S[..., :4] - S[..., 4:]):  # Δβ, Δγ
            out.append(torch.cat((Sx[..., :3].reshape(B, H, 3, 9), -(Sx[..., 3] @ M)), dim=-1).reshape(-1, 12))
        return -torch.cat(out)

    def __call__(self, theta: Tensor) -> Tensor:
        w = self.w
        dt3 = w.dt.unsqueeze(-1)
        u = _acc_model(theta, w.acc)  # (K, B, W, 3)
        R0, R1, R2 = self.cols
        ra_dt = (R0 * u[..., 0:1] + R1 * u[..., 1:2] + R2 * u[..., 2:3]) * dt3  # R_i u_i dt_i, column by column
        dv_incl = torch.cumsum(ra_dt, dim=-2)
        dv_excl = dv_incl - ra_dt
        dp_incl = torch.cumsum(dv_excl * dt3 + 0.5 * ra_dt * dt3, dim=-2)
        K = theta.shape[0]
        r_v = (w.dv - dv_incl[:, :, self.idx]).reshape(K, -1)
        r_p = (w.dp - dp_incl[:, :, self.idx]).reshape(K, -1)
        return torch.cat((r_v, r_p), dim=1)


def _rms(res: Callable[[Tensor], Tensor], theta: np.ndarray) -> float:
    """RMS over windows and horizons of the norm of each 3-vector residual."""
    with torch.no_grad():
        r = res(torch.as_tensor(np.asarray(theta, dtype=np.float64))[None])[0].reshape(-1, 3)
    return float(torch.sqrt((r * r).sum(-1).mean()))


def _huber_weights(r: Tensor, delta: float) -> Tensor:
    """IRLS weights of the Huber loss on the norm of each 3-vector of r (R,), repeated per component."""
    n = r.reshape(-1, 3).norm(dim=-1)
    wt = torch.where(n <= delta, torch.ones_like(n), delta / n.clamp_min(1e-300))
    return wt.repeat_interleave(3)


def _huber_cost(r: Tensor, delta: float) -> float:
    n = r.reshape(-1, 3).norm(dim=-1)
    return float(torch.where(n <= delta, 0.5 * n * n, delta * (n - 0.5 * delta)).sum())


def _solve(
    res: Callable[[Tensor], Tensor], x0: np.ndarray, prior_idx: np.ndarray, prior: float, delta: float,
    max_iter: int, step: float = 1e-6, chunk: int = 8, tol: float = 1e-10,
) -> np.ndarray:
    """Levenberg–Marquardt with Huber IRLS weights on Σ ρ_δ(|r_j(θ)|) + ½ prior² |θ[prior_idx]|².

    The Jacobian is ``res.jacobian(θ, r)`` where the residuals have one (both of :meth:`Traditional.fit`'s
    stages: exact, one pass), else forward differences with all parameters perturbed in one batched
    evaluation (``chunk`` candidates at a time). Everything stays in torch float64 (the normal
    equations are P×P)."""
    P = len(x0)
    pmask = torch.zeros(P, dtype=torch.float64)
    pmask[torch.as_tensor(prior_idx, dtype=torch.long)] = prior * prior

    def batch(X: Tensor) -> Tensor:
        return torch.cat([res(X[i:i + chunk]) for i in range(0, len(X), chunk)])

    def cost(x: Tensor, r: Tensor) -> float:
        return _huber_cost(r, delta) + 0.5 * float((pmask * x * x).sum())

    jac = getattr(res, "jacobian", None)
    with torch.no_grad():
        x = torch.as_tensor(np.asarray(x0, dtype=np.float64)).clone()
        r = batch(x[None])[0]
        c = cost(x, r)
        lam = 1e-3
        for _ in range(max_iter):
            if jac is not None:
                J = jac(x, r)  # (R, P)
            else:
                J = ((batch(x[None] + step * torch.eye(P, dtype=torch.float64)) - r[None]) / step).T
            wt = _huber_weights(r, delta)
            Jw = J * wt[:, None]
            A = J.T @ Jw + torch.diag(pmask)
            g = Jw.T @ r + pmask * x
            improved = False
            for _ in range(10):
                d = torch.linalg.solve(A + lam * torch.diag(torch.diagonal(A)), -g)
                xn = x + d
                rn = batch(xn[None])[0]
                cn = cost(xn, rn)
                if cn < c:
                    improved = True
                    break
                lam *= 10.0
            if not improved:
                break
            small = float(d.norm()) <= tol * (1.0 + float(x.norm())) or (c - cn) <= tol * c
            x, r, c = xn, rn, cn
            lam = max(lam / 10.0, 1e-9)
            if small:
                break
    return x.numpy().copy()


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
        acc_prior: Optional[float] = None,
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
        # the prior on the accelerometer matrix (M_a - I); None: ``prior``. A large one (ACC_BIAS_ONLY) holds
        # M_a at the identity: a reference that cannot resolve accelerations observes the acc bias only
        self.acc_prior = acc_prior
        self.params = TraditionalParams.identity()

    # -- applying the model ---------------------------------------------------------------------

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        return affine.apply(self.params, seq.t_ns, seq.gyro, seq.acc, self.filter_order)

    # -- fitting --------------------------------------------------------------------------------

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        with thread_limits(min(self.threads, settings.threads)):
            return self._fit(train, val, settings)

    def _offset_first(self, train: List[Segment], val: List[Segment], settings: FitSettings,
                      shift_val: bool = True) -> Tuple[int, float, Dict[str, list], List[Segment], List[Segment]]:
        """What :meth:`fit` and :meth:`refit` do first: the seed, the window, and (``fit_offset``) the
        time offset, with the training split (and ``val`` where ``shift_val``) resampled at it.
        Returns (window, tau, its log, train, val)."""
        torch.manual_seed(settings.seed)
        window = int(self.window or settings.window)
        if not self.fit_offset:
            return window, 0.0, {}, train, val
        if not any(len(s) > window for s in train):
            raise ValueError(f"no training sequence is longer than the window ({window} samples)")
        tau, tau_log = self._fit_time_offset(train, val, self.offset_window, settings.gravity)
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
        def rot(w: _Windows) -> Callable[[Tensor], Tensor]:
            return _RotResiduals(w)

        theta_g, c_g, val_rot, wg = self._fit_at_best_cutoff(
            rot, lambda c: tr.windows(c, None), lambda c: va.windows(c, None), grid, np.zeros(21), g_idx, self.huber_rot)
        g_before, g_after = _rms(rot(wg), np.zeros(21)), _rms(rot(wg), theta_g)

        # 2. accel with the gyro model fixed: the same on velocity/position residuals (the rotations
        # depend on the gyro windows only, not on the accelerometer's cutoff: computed once per split).
        held: Dict[Tuple[int, Optional[float]], Tensor] = {}

        def vel(w: _Windows) -> Callable[[Tensor], Tensor]:
            with torch.no_grad():
                if w.key not in held:
                    held[w.key] = _held_rotations(_gyro_model(torch.from_numpy(theta_g), w.gyro, w.acc_g), w.dt)
                return _VelResiduals(None, w, held[w.key])

        theta_a, c_a, val_vel, wa = self._fit_at_best_cutoff(
            vel, lambda c: tr.windows(c_g, c), lambda c: va.windows(c_g, c), grid, np.zeros(12), a_idx, self.huber_vel,
            self._acc_prior)
        # "before" = raw IMU (identity model, no filter) on the same windows
        raw = tr.windows(None, None)
        ident = _gyro_model(torch.zeros(21, dtype=torch.float64), raw.gyro, raw.acc_g)
        a_before = _rms(_VelResiduals(ident, raw), np.zeros(12))
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
        window, tau, tau_log, train, _ = self._offset_first(train, val, settings, shift_val=False)
        tr = _Data(train, window, self.max_windows, settings.gravity, self.filter_order)
        if len(tr) == 0:
            raise ValueError(f"no training sequence is longer than the window ({window} samples)")
        w = tr.windows(start.cutoff_gyro, start.cutoff_acc)
        g0 = np.concatenate([(start.M_g - np.eye(3)).ravel(), start.b_g, start.G.ravel()])
        a0 = np.concatenate([(start.M_a - np.eye(3)).ravel(), start.b_a])
        theta_g = _solve(_RotResiduals(w), g0, np.r_[0:9, 12:21], self.prior, self.huber_rot, self.max_iter)
        with torch.no_grad():
            vel = _VelResiduals(_gyro_model(torch.from_numpy(theta_g), w.gyro, w.acc_g), w)
        theta_a = _solve(vel, a0, np.r_[0:9], self._acc_prior, self.huber_vel, self.max_iter)
        self.params = TraditionalParams(
            M_g=np.eye(3) + theta_g[:9].reshape(3, 3), b_g=theta_g[9:12].copy(), G=theta_g[12:21].reshape(3, 3).copy(),
            M_a=np.eye(3) + theta_a[:9].reshape(3, 3), b_a=theta_a[9:12].copy(),
            cutoff_gyro=start.cutoff_gyro, cutoff_acc=start.cutoff_acc, time_offset=tau,
        )
        return {"train_windows": [len(tr)], "stride": [tr.stride], **tau_log}

    def _fit_time_offset(self, train: List[Segment], val: List[Segment], window: int,
                         gravity: float) -> Tuple[float, Dict[str, list]]:
        """The temporal calibration: tau [samples] by the timing baseline's 1-D search on the raw
        gyro's rotation residuals over ``offset_window``-sample training windows (short, for the
        reason :mod:`imu_learn.baselines.timing` gives), kept only if it lowers the validation cost."""
        tr = RotationWindows(train, window, 5 * self.max_windows, gravity)
        tau, _, _ = fit_offset(tr, self.max_shift, 0.25, 1e-3, self.huber_rot)
        va = RotationWindows(val, window, 5 * self.max_windows, gravity) if val else tr
        va = va if len(va) else tr
        zero, got = va.cost(0.0, self.huber_rot), va.cost(tau, self.huber_rot)
        kept = tau if got < zero else 0.0
        return kept, {"tau_samples": [kept], "tau_fitted": [tau], "tau_val_cost": [zero, got]}

    @property
    def _acc_prior(self) -> float:
        return self.prior if self.acc_prior is None else self.acc_prior

    def _fit_at_best_cutoff(self, residuals: Callable, train_at: Callable, val_at: Callable, grid: list,
                            theta0: np.ndarray, idx: np.ndarray, huber: float, prior: Optional[float] = None) -> tuple:
        """One stage of :meth:`fit`: solve at the grid's first cutoff, score every cutoff on the
        validation windows, re-solve at the best one (``prior``: on ``idx``, default ``self.prior``).
        Returns (theta, chosen cutoff, validation RMS per cutoff, the training windows at the chosen
        cutoff)."""
        prior = self.prior if prior is None else prior
        first = grid[0]
        theta = _solve(residuals(train_at(first)), theta0, idx, prior, huber, self.max_iter)
        val = [_rms(residuals(val_at(c)), theta) for c in grid]
        chosen = grid[int(np.argmin(val))]
        windows = train_at(chosen)
        if chosen != first:
            theta = _solve(residuals(windows), theta, idx, prior, huber, self.max_iter)
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
