"""An AirIMU-style refiner, written from the description in Qiu et al. 2023, "AirIMU: Learning
Uncertainty Propagation for Inertial Odometry" (arXiv:2310.04874), not from its code.

What it takes from the paper:

- the network corrects the IMU additively, per sample: û = u + Δu(u), gyro and accelerometer each
  from its own decoder head, over a window of raw samples;
- the encoder is a 1-D CNN over time (local features) feeding recurrent GRU layers (longer
  context). Here: two Conv1d layers (kernel ``kernel``, same-length padding, GELU), then a
  *bidirectional* GRU and a forward GRU on top of it. Reading: AirIMU corrects whole recorded
  windows offline (the refined IMU is integrated afterwards, as here), so a bidirectional first
  GRU is available to it; ``bidirectional=False`` gives a forward-only GRU stack (the CNN padding
  still looks ``kernel // 2`` samples ahead, so neither variant is causal and the sequence is
  always refined in overlapping windows);
- supervision through a differentiable integrator: the loss is on the increments integrated from
  the corrected IMU over the full training window (rotation, velocity and position:
  :func:`imu_learn.nn.integration.integrate` inside :func:`imu_learn.nn.losses.imu_loss` at the
  single horizon n = window, Huber on each residual's norm, no regulariser, no bias term);
- trained WITHOUT augmentation (the recorded IMU as it is).

Left out: AirIMU's covariance head and covariance-propagation loss (the learned uncertainty only
matters for fusion; it lands with the fusion issue), and its option of feeding world-frame
(ground-truth-rotated) accelerations. The heads are zero-initialised, so the untrained model is the
identity (refine returns the raw IMU bit for bit).

``refine`` applies the net by the one windowing rule (:mod:`imu_learn.infer.windowing`:
overlapping windows of the training length, half overlap, centre-crop stitching). Training uses
:func:`imu_learn.baselines.proposed.train_refiner` (Adam, ``FitSettings`` budget, best validation
weights kept).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np
import torch
from torch import nn

from imu_learn.baselines.base import FitSettings, Method
from imu_learn.baselines.proposed import start_refiner_fit, train_refiner
from imu_learn.core.batches import Batch, BatchConfig
from imu_learn.data.types import Segment
from imu_learn.infer.windowing import Windowing, apply
from imu_learn.nn.device import pick_device
from imu_learn.nn.losses import LossConfig, imu_loss

Tensor = torch.Tensor
FORMAT = "imu_learn.baselines.airimu_style.v1"


@dataclass
class AirImuConfig:
    conv: int = 32  # channels of the CNN layers
    kernel: int = 7  # CNN kernel length [samples] (odd)
    hidden: int = 64  # GRU hidden size (per direction)
    bidirectional: bool = True  # first GRU bidirectional (see the module docstring)
    output_scale: float = 0.1  # correction = output_scale * input std * head output
    dropout: float = 0.0
    huber_q: float = 0.005  # Huber deltas of the increment loss (LossConfig's defaults)
    huber_v: float = 0.05
    huber_p: float = 0.01
    w_q: float = 1.0
    w_v: float = 1.0
    w_p: float = 1.0
    grad_clip: float = 1.0
    evals: int = 10  # validation checks over the run
    val_stride: int = 0  # validation window step [samples]; 0: window // 2

    @property
    def causal(self) -> bool:  # for imu_learn.infer.windowing: always refined in stitched windows
        return False

    def loss_config(self) -> LossConfig:
        return LossConfig(w_q=self.w_q, w_v=self.w_v, w_p=self.w_p, huber_q=self.huber_q, huber_v=self.huber_v,
                          huber_p=self.huber_p, w_reg=0.0, bias_aware=False)


class AirImuNet(nn.Module):
    """imu (B, W, 6) raw gyro then acc -> corrected (B, W, 6) = imu + Δu."""

    def __init__(self, cfg: AirImuConfig, mean: Optional[Tensor] = None, std: Optional[Tensor] = None) -> None:
        super().__init__()
        self.cfg = cfg
        self.register_buffer("mean", torch.zeros(6) if mean is None else torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.ones(6) if std is None else torch.as_tensor(std, dtype=torch.float32))
        k = cfg.kernel
        self.cnn = nn.Sequential(
            nn.Conv1d(6, cfg.conv, k, padding=k // 2), nn.GELU(), nn.Dropout(cfg.dropout),
            nn.Conv1d(cfg.conv, cfg.conv, k, padding=k // 2), nn.GELU(), nn.Dropout(cfg.dropout),
        )
        dirs = 2 if cfg.bidirectional else 1
        self.gru1 = nn.GRU(cfg.conv, cfg.hidden, batch_first=True, bidirectional=cfg.bidirectional)
        self.gru2 = nn.GRU(dirs * cfg.hidden, cfg.hidden, batch_first=True)
        self.gyro_head = nn.Linear(cfg.hidden, 3)
        self.acc_head = nn.Linear(cfg.hidden, 3)
        for h in (self.gyro_head, self.acc_head):
            nn.init.zeros_(h.weight)
            nn.init.zeros_(h.bias)

    def forward(self, imu: Tensor) -> Tensor:
        mean = self.mean.to(imu.dtype)
        std = self.std.to(imu.dtype)
        x = ((imu - mean) / std).transpose(1, 2)  # (B, 6, W)
        x = self.cnn(x).transpose(1, 2)  # (B, W, C)
        x, _ = self.gru1(x)
        x, _ = self.gru2(x)
        corr = torch.cat((self.gyro_head(x), self.acc_head(x)), dim=-1)
        return imu + self.cfg.output_scale * std * corr


class AirImuStyle(Method):
    """CNN + GRU additive IMU corrector trained through integration (see the module docstring)."""

    name = "airimu-style"
    rotation_only = False
    save_suffix = ".pt"

    def __init__(self, config: Optional[AirImuConfig] = None, device: str = "cpu") -> None:
        self.config = config or AirImuConfig()
        self.model = AirImuNet(self.config).eval()
        self.window = 200
        self.device = pick_device(device)

    def _loss(self, model: nn.Module, b: Batch, device: torch.device, training: bool) -> Tensor:
        imu = torch.as_tensor(b.imu, dtype=torch.float32, device=device)
        refined = model(imu)
        W = imu.shape[1]
        # the full window only: the last label horizon is the whole window
        loss, _ = imu_loss(refined, b.imu, b.dt, b.dq_wxyz[:, -1:], b.dv[:, -1:], b.dp[:, -1:], [W],
                           cfg=self.config.loss_config())
        return loss

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        c = self.config
        train, mean, std = start_refiner_fit(self, train, settings)
        W = self.window
        self.model = AirImuNet(c, mean=mean, std=std)
        bc = BatchConfig(window=W, batch_size=settings.batch_size, gravity=settings.gravity)  # no augmentation
        if int(bc.fractions[-1] * W) != W:
            raise ValueError("airimu-style: the last label fraction must be 1.0 (the full window)")
        return train_refiner(self.model, train, val, settings, bc, self._loss, c.evals, c.grad_clip, c.val_stride)

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        gyro, acc, _ = apply(self.model, seq.gyro, seq.acc, Windowing.for_training_window(self.window))
        return gyro, acc

    def save(self, path: Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        torch.save({"format": FORMAT, "config": asdict(self.config), "window": int(self.window),
                    "state": {k: v.detach().cpu() for k, v in self.model.state_dict().items()}}, path)

    def load(self, path: Path) -> AirImuStyle:
        d = torch.load(Path(path), map_location="cpu", weights_only=True)
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise ValueError(f"{path}: not an airimu-style baseline file ({FORMAT})")
        self.config = AirImuConfig(**{k: v for k, v in d["config"].items() if k != "overlap"})  # older files: a refine overlap, now the windowing rule's
        self.model = AirImuNet(self.config)
        self.model.load_state_dict(d["state"])
        self.model.to(self.device).eval()
        self.window = int(d["window"])
        return self
