"""Gyro denoising baseline after Brossard, Bonnabel & Barrau 2020, "Denoising IMU gyroscopes with deep
learning for open-loop attitude estimation" (RA-L). Written from the paper's description.

Model: the corrected angular rate is a learned calibration plus a learned correction,

    ω̂_n = C ω_n + ω̃_n,      ω̃_n = s · CNN(normalised u_{n-R..n})     (C initialised to I)

where u = (ω_m, a_m) is the 6-axis IMU and the CNN is causal: dilated 1-D convolutions (kernel 7,
dilations 1, 4, 16, 64) with batch norm, GELU and dropout between them and a 1×1 convolution to the
3 outputs (its weights start at zero, so the untrained model is ω̂ = ω_m). Inputs are normalised by
the training set's per-channel mean/std; the left edge is padded by replicating the first sample.
The receptive field is R = (k − 1) Σ d samples (510 at the defaults, 2.55 s at 200 Hz). The
accelerometer is passed through unchanged (``rotation_only``).

Loss: rotation increments at several scales. For each scale j (16, 32, 64 samples) the window is
cut into non-overlapping sub-windows of j samples; the integrated increment over each sub-window,
Π Exp(ω̂_i dt_i), is compared with the ground truth R_{t}ᵀ R_{t+j} by Huber(|Log(Δq_gt ⊗ Δq̂⁻¹)|),
averaged over sub-windows and summed over scales (the paper's multi-scale loss, built by pairwise
products of consecutive increments). Adam.

Training windows: W = ``FitSettings.window`` samples with R samples of real context before them
(the network sees R + W samples, the loss only the last W), drawn uniformly from the training
sequences with a seeded numpy generator, no augmentation. (Drawn here rather than through the
Rust ``BatchSampler`` because the loss needs the per-sample ground-truth orientation and the
context before each window, neither of which a sampler batch carries.)
"""
from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np
import torch
from torch import nn

from imu_learn.baselines.base import FitSettings, Method, fit_steps
from imu_learn.data.types import Segment
from imu_learn.nn.device import pick_device
from imu_learn.nn.losses import huber_norm
from imu_learn.nn.so3 import quat_conj, quat_mul, so3_exp, so3_log

Tensor = torch.Tensor


class GyroDenoiseNet(nn.Module):
    """Causal dilated CNN: (B, N, 6) IMU -> (B, N, 3) corrected gyro ω̂ = C ω_m + scale · CNN(u)."""

    def __init__(
        self,
        channels: Seq[int] = (16, 32, 64, 128),
        kernel: int = 7,
        dilations: Seq[int] = (1, 4, 16, 64),
        dropout: float = 0.1,
        out_scale: float = 0.01,
        mean: Optional[Tensor] = None,
        std: Optional[Tensor] = None,
    ) -> None:
        super().__init__()
        if len(channels) != len(dilations):
            raise ValueError("channels and dilations must have the same length")
        self.args = {"channels": list(channels), "kernel": kernel, "dilations": list(dilations),
                     "dropout": dropout, "out_scale": out_scale}
        layers: List[nn.Module] = []
        c_in = 6
        for c, d in zip(channels, dilations):
            layers += [nn.Conv1d(c_in, c, kernel, dilation=d), nn.BatchNorm1d(c), nn.GELU(), nn.Dropout(dropout)]
            c_in = c
        out = nn.Conv1d(c_in, 3, 1)
        nn.init.zeros_(out.weight)
        nn.init.zeros_(out.bias)
        layers.append(out)
        self.net = nn.Sequential(*layers)
        self.receptive_field = (kernel - 1) * sum(dilations)
        self.out_scale = out_scale
        self.C = nn.Parameter(torch.eye(3))
        self.register_buffer("mean", torch.zeros(6) if mean is None else torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.ones(6) if std is None else torch.as_tensor(std, dtype=torch.float32))

    def forward(self, imu: Tensor) -> Tensor:
        x = ((imu - self.mean) / self.std).transpose(1, 2)  # (B, 6, N)
        x = nn.functional.pad(x, (self.receptive_field, 0), mode="replicate")
        corr = self.net(x).transpose(1, 2) * self.out_scale  # (B, N, 3)
        return imu[..., :3] @ self.C.T + corr


def _chunk_products(q: Tensor, scales: Seq[int]) -> Dict[int, Tensor]:
    """Per-sample increments q (B, W, 4) -> {j: products over consecutive non-overlapping j-sample
    chunks (B, W // j, 4)} for power-of-two scales j, by repeated pairwise products."""
    out: Dict[int, Tensor] = {}
    size = 1
    cur = q
    for j in sorted(scales):
        while size < j:
            n = cur.shape[1] // 2
            cur = quat_mul(cur[:, 0:2 * n:2], cur[:, 1:2 * n:2])
            size *= 2
        out[j] = cur
    return out


def multiscale_rotation_loss(gyro: Tensor, dt: Tensor, q_gt: Tensor, scales: Seq[int], delta: float) -> Tensor:
    """Σ_j mean Huber(|Log(Δq_gt ⊗ Δq̂⁻¹)|) over non-overlapping j-sample chunks.

    gyro (B, W, 3) corrected rate; dt (B, W) hold times; q_gt (B, W + 1, 4) ground-truth orientation
    at the W + 1 sample stamps (body -> world, w x y z)."""
    step = so3_exp(gyro * dt.unsqueeze(-1))
    prods = _chunk_products(step, scales)
    loss = gyro.new_zeros(())
    for j, est in prods.items():
        n = est.shape[1]
        q0 = q_gt[:, 0:n * j:j]
        q1 = q_gt[:, j:(n + 1) * j:j]
        gt = quat_mul(quat_conj(q0), q1)
        r = so3_log(quat_mul(gt, quat_conj(est)))
        loss = loss + huber_norm(r, delta).mean()
    return loss


def _dt(seq: Segment) -> np.ndarray:
    t = np.asarray(seq.t_ns, dtype=np.int64)
    dt = np.empty(len(t))
    dt[:-1] = np.diff(t) * 1e-9
    dt[-1] = dt[-2] if len(t) > 1 else 0.0
    return dt


class GyroDenoise(Method):
    """Brossard et al. 2020 gyro denoiser; the accelerometer passes through unchanged."""

    name = "gyro-denoise"
    rotation_only = True

    def __init__(
        self,
        channels: Seq[int] = (16, 32, 64, 128),
        kernel: int = 7,
        dilations: Seq[int] = (1, 4, 16, 64),
        dropout: float = 0.1,
        out_scale: float = 0.01,
        scales: Seq[int] = (16, 32, 64),
        huber_delta: float = 0.005,
        weight_decay: float = 0.0,
    ) -> None:
        for j in scales:
            if j < 1 or j & (j - 1):
                raise ValueError(f"loss scales must be powers of two, got {j}")
        self.net_args = {"channels": list(channels), "kernel": kernel, "dilations": list(dilations),
                         "dropout": dropout, "out_scale": out_scale}
        self.scales = tuple(scales)
        self.huber_delta = huber_delta
        self.weight_decay = weight_decay
        self.model = GyroDenoiseNet(**self.net_args)
        self.device = torch.device("cpu")

    # -- training -------------------------------------------------------------------------------

    def _windows(self, seqs: List[Segment], W: int, B: int, rng: np.random.Generator, R: int):
        """B windows: imu (B, R + W, 6) with R samples of context, dt (B, W), q_gt (B, W + 1, 4)."""
        lens = np.array([len(s) for s in seqs], dtype=np.float64)
        which = rng.choice(len(seqs), size=B, p=lens / lens.sum())
        imu, dts, qs = [], [], []
        for i in which:
            s = seqs[i]
            lo = min(R, len(s) - W - 1)
            k = int(rng.integers(lo, len(s) - W))  # window k..k+W-1; label needs q at k+W
            a = max(0, k - R)
            x = np.concatenate([s.gyro[a:k + W], s.acc[a:k + W]], axis=1)
            if k - a < R:  # too little history: replicate the first sample (as at inference)
                x = np.concatenate([np.repeat(x[:1], R - (k - a), axis=0), x])
            imu.append(x)
            dts.append(self._dts[i][k:k + W])
            qs.append(s.q_wxyz[k:k + W + 1])
        f = lambda a, dt: torch.from_numpy(np.ascontiguousarray(np.stack(a), dtype=dt))  # noqa: E731
        return f(imu, np.float32), f(dts, np.float64), f(qs, np.float64)

    def _loss(self, imu: Tensor, dt: Tensor, q: Tensor, R: int) -> Tensor:
        gyro = self.model(imu.to(self.device))[:, R:].double()
        return multiscale_rotation_loss(gyro, dt.to(self.device), q.to(self.device), self.scales, self.huber_delta)

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        dev = pick_device(settings.device)
        if dev.type == "cpu":
            torch.set_num_threads(settings.threads)
        torch.manual_seed(settings.seed)
        rng = np.random.default_rng(settings.seed)
        W = int(settings.window)
        scales = [j for j in self.scales if j <= W]
        if not scales:
            raise ValueError(f"window {W} is shorter than every loss scale {self.scales}")
        self.scales = tuple(scales)
        train = [s for s in train if len(s) > W + 1]
        if not train:
            raise ValueError(f"no training sequence is longer than the window ({W} samples)")
        val = [s for s in (val or []) if len(s) > W + 1]

        allimu = np.concatenate([np.concatenate([s.gyro, s.acc], axis=1) for s in train])
        mean, std = allimu.mean(0), np.maximum(allimu.std(0), 1e-6)
        self.model = GyroDenoiseNet(**self.net_args, mean=torch.as_tensor(mean, dtype=torch.float32),
                                    std=torch.as_tensor(std, dtype=torch.float32)).to(dev)
        self.device = dev
        R = self.model.receptive_field
        self._dts = [_dt(s) for s in train]
        opt = torch.optim.Adam(self.model.parameters(), lr=settings.lr, weight_decay=self.weight_decay)

        val_batch = None
        if val:
            vrng = np.random.default_rng(settings.seed + 1)
            saved = self._dts
            self._dts = [_dt(s) for s in val]
            val_batch = self._windows(val, W, max(settings.batch_size, 64), vrng, R)
            self._dts = saved

        log: Dict[str, list] = {"train_loss": [], "val_loss": []}
        val_every = max(1, settings.steps // 20)
        self.model.train()
        for step in fit_steps(settings.steps, settings, "gyro-denoise"):
            imu, dt, q = self._windows(train, W, settings.batch_size, rng, R)
            loss = self._loss(imu, dt, q, R)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            log["train_loss"].append(float(loss.detach()))
            if val_batch is not None and ((step + 1) % val_every == 0 or step + 1 == settings.steps):
                self.model.eval()
                with torch.no_grad():
                    log["val_loss"].append(float(self._loss(*val_batch, R)))
                self.model.train()
        self.model.eval()
        del self._dts
        return log

    # -- inference ------------------------------------------------------------------------------

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        self.model.eval()
        x = np.concatenate([seq.gyro, seq.acc], axis=1)
        with torch.no_grad():
            inp = torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))[None].to(self.device)
            g = self.model(inp)[0].double().cpu().numpy()
        return np.ascontiguousarray(g, dtype=np.float64), np.asarray(seq.acc, dtype=np.float64)

    # -- persistence ----------------------------------------------------------------------------

    def save(self, path: Path) -> None:
        state = {k: v.detach().cpu() for k, v in self.model.state_dict().items()}
        torch.save({"method": self.name, "net_args": dict(self.net_args), "scales": list(self.scales),
                    "huber_delta": self.huber_delta, "state_dict": state}, Path(path))

    def load(self, path: Path) -> GyroDenoise:
        d = torch.load(Path(path), map_location="cpu", weights_only=True)
        if d.get("method") != self.name:
            raise ValueError(f"{path} holds {d.get('method')!r} weights, not {self.name!r}")
        self.net_args = dict(d["net_args"])
        self.scales = tuple(d["scales"])
        self.huber_delta = float(d["huber_delta"])
        self.model = GyroDenoiseNet(**self.net_args)
        self.model.load_state_dict(d["state_dict"])
        self.model.to(self.device).eval()
        return self
