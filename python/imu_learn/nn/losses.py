"""The paper's training losses (Sec. IV-B/C): Huber losses on the integrated Δq/Δβ/Δγ over several
horizons, plus a dead-zone regulariser that keeps the refined IMU near the raw one.

    L = w_q Σ_h |Log(Δq_s ⊗ Δq̂⁻¹)|_h + w_v Σ_h |Δβ_s − Δβ̂|_h + w_p Σ_h |Δγ_s − Δγ̂|_h
        + w_reg · mean_{b,t} Σ_c max(|u_m − û| − λ_c, 0)

where s marks the ground-truth labels, ^ the increments integrated from the refined measurements,
the horizon sums run over the label horizons (the paper's 20/40/60/80/100 % of the window), and
every term is averaged over the batch.

Huber (|·|_h) is applied to the Euclidean norm of each 3-vector residual (isotropic, so independent
of the body axes): 0.5 r² for r ≤ δ and δ (r − ½δ) beyond, i.e. ``torch.nn.HuberLoss`` on the norm.
The δ defaults are of the order of what a bias-corrected MEMS IMU (EuRoC's ADIS16448 grade) drifts
over a ~1 s window, so well-fitting windows sit on the quadratic branch while gross ground-truth
glitches (and the raw, uncorrected device early in training) only pull linearly:
δ_q = 0.005 rad (≈ 0.3°), δ_v = 0.05 m/s, δ_p = 0.01 m. Beyond δ the gradient magnitude is δ, so the
deltas also set the terms' relative pull on a poorly fitting window; rescale with w_q/w_v/w_p.

Bias-augmented form (``bias_aware=True``, the paper's Eq. after "manually add random biases"): the
network input is the recorded IMU plus a known random bias b (per sample, (B, W, 6)). The refined
output still carries a bias at inference (it is time-varying and left to the estimator), so the
network must be rewarded for passing the added bias through rather than for removing it. The paper
composes the refined increments with the integrated bias (q_b, β_b, γ_b) to first order; here the
refined increments are computed *exactly* by integrating (û − b) instead, which is what that
composition approximates (for a constant gyro bias, Exp is not additive and β_b/γ_b depend on the
refined rotation, so the composition is exact only to first order in b). With ``bias_aware=False``
û is integrated directly, and a model learns to remove the device's (and the augmentation's) bias.
"""
from __future__ import annotations

from typing import Dict, Optional, Tuple, Union

import numpy as np
import torch

from imu_learn.nn.config import LossConfig
from imu_learn.nn.covariance import increment_covariance
from imu_learn.nn.integration import Horizons, integrate
from imu_learn.nn.so3 import quat_conj, quat_mul, so3_log

Tensor = torch.Tensor
ArrayLike = Union[Tensor, np.ndarray]


def huber_norm(r: Tensor, delta: float) -> Tensor:
    """Huber of the Euclidean norm of r (..., 3) -> (...): 0.5|r|² inside δ, δ(|r| − δ/2) outside.

    The square root is only taken on the linear branch, so the gradient is finite (zero) at r = 0.
    """
    n2 = (r * r).sum(-1)
    quad = n2 <= delta * delta
    n = torch.sqrt(torch.where(quad, torch.full_like(n2, delta * delta), n2))
    return torch.where(quad, 0.5 * n2, delta * (n - 0.5 * delta))


def dead_zone(diff: Tensor, lam: Tensor) -> Tensor:
    """max(|diff| − λ, 0) elementwise."""
    return torch.clamp(diff.abs() - lam, min=0.0)


def gaussian_nll(r: Tensor, cov: Tensor) -> Tensor:
    """½ (rᵀ Σ⁻¹ r + log det Σ) for r (..., 9) and Σ (..., 9, 9), without the constant (9/2) log 2π.

    Solved in float64 whatever the inputs' dtype: the blocks of Σ differ by many orders of magnitude
    (rad² against m² at 10 samples), which float32's Cholesky does not survive. A relative jitter of
    1e-9 on the diagonal keeps a window whose covariance is numerically rank-deficient solvable.
    """
    c = cov.double()
    d = torch.diagonal(c, dim1=-2, dim2=-1)
    c = c + torch.diag_embed(1e-9 * d)
    L = torch.linalg.cholesky(c)
    z = torch.linalg.solve_triangular(L, r.double().unsqueeze(-1), upper=False).squeeze(-1)
    logdet = 2.0 * torch.log(torch.diagonal(L, dim1=-2, dim2=-1)).sum(-1)
    return (0.5 * ((z * z).sum(-1) + logdet)).to(r.dtype)


def _as(x: ArrayLike, like: Tensor) -> Tensor:
    if isinstance(x, np.ndarray):
        x = torch.from_numpy(np.ascontiguousarray(x))
    return torch.as_tensor(x).to(dtype=like.dtype, device=like.device)


def imu_loss(
    refined: Tensor,
    raw: ArrayLike,
    dt: ArrayLike,
    dq_wxyz: ArrayLike,
    dv: ArrayLike,
    dp: ArrayLike,
    horizons: Horizons,
    bias: Optional[ArrayLike] = None,
    cfg: LossConfig = LossConfig(),
    var: Optional[Tensor] = None,
) -> Tuple[Tensor, Dict[str, Tensor]]:
    """Total loss and its detached terms ``{"q", "v", "p", "reg", "total"}`` (and ``"nll"`` when
    ``cfg.w_nll`` > 0) for logging.

    refined: (B, W, 6) network output û, gyro then acc (its dtype/device are used throughout);
    raw: (B, W, 6) network input u_m (recorded IMU plus the added bias, if any); dt: (B, W) [s];
    dq_wxyz (B, H, 4), dv/dp (B, H, 3): ground-truth labels at ``horizons`` (H,) sample counts;
    bias: (B, W, 6) the bias added to the input (None or ignored when ``cfg.bias_aware`` is False).
    Arrays may be numpy (e.g. straight from :class:`imu_learn.BatchSampler`) or tensors.
    var: (B, W, 6) the model's per-sample noise variances, needed when ``cfg.w_nll`` > 0.
    """
    raw_t = _as(raw, refined)
    dt_t = _as(dt, refined)
    dq_s = _as(dq_wxyz, refined)
    dv_s = _as(dv, refined)
    dp_s = _as(dp, refined)

    u = refined
    if cfg.bias_aware and bias is not None:
        u = refined - _as(bias, refined)
    inc = integrate(u[..., :3], u[..., 3:], dt_t, horizons)

    r_q = so3_log(quat_mul(dq_s, quat_conj(inc.dq_wxyz)))  # (B, H, 3)
    r_v, r_p = dv_s - inc.dv, dp_s - inc.dp
    l_nll = None
    if cfg.w_nll > 0:
        if var is None:
            raise ValueError("loss.w_nll > 0 needs the model's variances (model.covariance = true)")
        # The trajectory the covariance is linearised about is held fixed (detached): the NLL
        # trains the noise levels, not the refined samples through the Jacobians' dependence on them.
        ud = u.detach()
        cov = increment_covariance(ud[..., :3], ud[..., 3:], dt_t, var, horizons)
        l_nll = gaussian_nll(torch.cat((r_q, r_v, r_p), dim=-1), cov).sum(-1).mean()
    if cfg.horizon_scale == "inverse":
        h = torch.as_tensor([float(x) for x in horizons], dtype=r_q.dtype, device=r_q.device)
        scale = (h.max() / h)[:, None]  # (H, 1)
        r_q, r_v, r_p = r_q * scale, r_v * scale, r_p * scale
    elif cfg.horizon_scale != "none":
        raise ValueError(f"loss.horizon_scale: must be none or inverse, got {cfg.horizon_scale!r}")
    l_q = huber_norm(r_q, cfg.huber_q).sum(-1).mean()
    l_v = huber_norm(r_v, cfg.huber_v).sum(-1).mean()
    l_p = huber_norm(r_p, cfg.huber_p).sum(-1).mean()

    lam = refined.new_tensor([cfg.reg_gyro] * 3 + [cfg.reg_acc] * 3)
    l_reg = dead_zone(raw_t - refined, lam).sum(-1).mean()

    total = cfg.w_q * l_q + cfg.w_v * l_v + cfg.w_p * l_p + cfg.w_reg * l_reg
    terms = {"q": l_q.detach(), "v": l_v.detach(), "p": l_p.detach(), "reg": l_reg.detach()}
    if l_nll is not None:
        total = total + cfg.w_nll * l_nll
        terms["nll"] = l_nll.detach()
    terms["total"] = total.detach()
    return total, terms
