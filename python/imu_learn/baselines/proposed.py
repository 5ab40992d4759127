"""The proposed method as an evaluated :class:`~imu_learn.baselines.base.Method`: the paper's
refiner (:class:`imu_learn.nn.model.ImuRefiner`, stacked bidirectional LSTM + FC, a residual on the
raw IMU) trained with the paper's loss (:func:`imu_learn.nn.losses.imu_loss`: Huber on integrated
Δq/Δβ/Δγ at the label horizons + the dead-zone regulariser, bias-aware) on augmented Rust batches.

Two ways in:

- ``Proposed.from_checkpoint(path)``: a model trained by ``python -m imu_learn.fit`` (its
  ``best.pt``); the refinement window is the run's ``data.window``;
- ``Proposed().fit(train, val, settings)``: a compact in-process trainer, so that evaluation can
  train every method on the same :class:`~imu_learn.baselines.base.FitSettings` budget. It is not
  ``imu_learn.fit`` (no epochs, resume, DDP or TensorBoard): Adam at ``settings.lr`` for
  ``settings.steps`` augmented batches of ``settings.window`` samples, gradient-norm clipping, and
  the weights with the lowest loss on fixed non-augmented validation windows (checked ``evals``
  times) kept. Augmentation, model and loss default to those of ``imu_learn.fit``'s default run
  (:class:`imu_learn.train.config.DataConfig`, :class:`ModelConfig`, :class:`LossConfig`).

``refine`` applies the model by the one windowing rule (:mod:`imu_learn.infer.windowing`: windows
of the training length, half overlap, centre crop), as fit, evaluate, refine and fuse do. ``save`` writes an ordinary imu_learn
checkpoint (:mod:`imu_learn.infer.checkpoint`), which ``imu-learn refine`` and
``from_checkpoint`` read as well.

:func:`train_refiner` is the training loop shared with the AirIMU-style baseline.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import torch
from torch import nn

from imu_learn.baselines.base import FitSettings, Method, fit_steps
from imu_learn.core.batches import AugmentConfig, Batch, BatchConfig, BatchSampler, batch_seed
from imu_learn.data.config import DataConfig
from imu_learn.data.types import Segment
from imu_learn.infer.checkpoint import load_checkpoint, model_from_checkpoint, save_checkpoint, training_record
from imu_learn.infer.windowing import Windowing, apply
from imu_learn.nn.device import pick_device
from imu_learn.nn.losses import LossConfig, imu_loss
from imu_learn.nn.model import ImuRefiner, ModelConfig

Tensor = torch.Tensor
LossFn = Callable[[nn.Module, Batch, torch.device, bool], Tensor]


def default_augment() -> AugmentConfig:
    """The augmentation of ``imu_learn.fit``'s default run."""
    return DataConfig().augment


def imu_stats(seqs: List[Segment]) -> Tuple[Tensor, Tensor]:
    """Per-channel mean and std (6,) float32 of the raw IMU (gyro then acc) of ``seqs``."""
    raw = np.concatenate([np.c_[s.gyro, s.acc] for s in seqs])
    return (torch.as_tensor(raw.mean(0), dtype=torch.float32),
            torch.as_tensor(np.maximum(raw.std(0), 1e-6), dtype=torch.float32))


def start_refiner_fit(method: Method, train: List[Segment], settings: FitSettings) -> Tuple[List[Segment], Tensor, Tensor]:
    """What a sample refiner's ``fit`` starts with: the training sequences longer than the window
    (a ValueError naming the method when there is none), ``method.window`` and ``method.device``
    set from ``settings``, torch seeded, and the input normalisation (:func:`imu_stats`)."""
    W = int(settings.window)
    train = [s for s in train if len(s) > W]
    if not train:
        raise ValueError(f"{method.name}: no training sequence longer than the window ({W} samples)")
    method.window = W
    method.device = pick_device(settings.device)
    torch.manual_seed(settings.seed)
    mean, std = imu_stats(train)
    return train, mean, std


def slice_batch(b: Batch, a: int, e: int) -> Batch:
    """Windows a..e of a batch (``horizons`` is shared)."""
    return replace(b, **{f.name: getattr(b, f.name)[a:e] for f in fields(b) if f.name != "horizons"})


def train_refiner(
    model: nn.Module,
    train: List[Segment],
    val: List[Segment],
    settings: FitSettings,
    batch_config: BatchConfig,
    loss_fn: LossFn,
    evals: int = 10,
    grad_clip: float = 1.0,
    val_stride: int = 0,
    val_chunk: int = 128,
) -> Dict[str, list]:
    """Adam on ``settings.steps`` batches from the Rust sampler; ``loss_fn(model, batch, device,
    training)`` gives the loss of a batch (``training`` False for the non-augmented validation
    windows). With validation sequences (long enough for a window) the weights of the best
    validation check are loaded back at the end. Returns ``{"train_loss": [per step],
    "val_loss": [...], "val_step": [...], "best_step": [s]}``; leaves the model in eval mode."""
    device = pick_device(settings.device)
    W = batch_config.window
    model.to(device)
    sampler = BatchSampler(train, batch_config)
    val = [s for s in (val or []) if len(s) > W]
    vb = None
    if val:
        vcfg = BatchConfig(window=W, batch_size=1, fractions=batch_config.fractions, gravity=batch_config.gravity)
        vb = BatchSampler(val, vcfg).eval_windows(val_stride or max(1, W // 2))
    opt = torch.optim.Adam(model.parameters(), lr=settings.lr)
    steps = int(settings.steps)
    n_checks = max(1, evals)
    checks = {max(1, round(i * steps / n_checks)) for i in range(1, n_checks + 1)}  # evenly spaced, the last step included
    log: Dict[str, list] = {"train_loss": [], "val_loss": [], "val_step": []}
    best, best_state = float("inf"), None
    for step in fit_steps(steps, settings, "refiner"):
        b = sampler.sample(batch_seed(settings.seed, 0, step))
        model.train()
        loss = loss_fn(model, b, device, True)
        opt.zero_grad()
        loss.backward()
        if grad_clip > 0:
            nn.utils.clip_grad_norm_(model.parameters(), grad_clip)
        opt.step()
        log["train_loss"].append(float(loss.detach()))
        if vb is not None and step + 1 in checks:
            model.eval()
            tot = 0.0
            with torch.no_grad():
                for a in range(0, len(vb.start), val_chunk):
                    part = slice_batch(vb, a, a + val_chunk)
                    tot += float(loss_fn(model, part, device, False)) * len(part.start)
            v = tot / max(1, len(vb.start))
            log["val_loss"].append(v)
            log["val_step"].append(step + 1)
            if v < best:
                best = v
                best_state = {k: t.detach().clone() for k, t in model.state_dict().items()}
    if best_state is not None:
        model.load_state_dict(best_state)
        log["best_step"] = [log["val_step"][int(np.argmin(log["val_loss"]))]]
    model.eval()
    return log


@dataclass
class ProposedConfig:
    model: ModelConfig = field(default_factory=ModelConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    augment: Optional[AugmentConfig] = None  # None: imu_learn.train.trainer's default augmentation
    grad_clip: float = 1.0
    evals: int = 10  # validation checks over the run
    val_stride: int = 0  # validation window step [samples]; 0: window // 2


class Proposed(Method):
    """The paper's refiner (see the module docstring)."""

    name = "proposed"
    rotation_only = False
    save_suffix = ".pt"

    def __init__(self, config: Optional[ProposedConfig] = None, model: Optional[ImuRefiner] = None,
                 window: int = 200, device: str = "cpu") -> None:
        self.config = config or ProposedConfig()
        self.model = model if model is not None else ImuRefiner(self.config.model)
        self.model.eval()
        self.window = int(window)
        self.device = pick_device(device)
        self.model.to(self.device)
        self.run_config: Dict[str, Any] = {}

    @classmethod
    def from_checkpoint(cls, path: Path, device: str = "cpu") -> Proposed:
        """The model of an ``imu_learn.fit`` checkpoint (or of :meth:`save`)."""
        state = load_checkpoint(Path(path), map_location="cpu")
        model = model_from_checkpoint(state)
        cfg = state.get("config") or {}
        window = int(((cfg.get("data") or {}).get("window")) or 200)
        m = cls(ProposedConfig(model=model.cfg), model=model, window=window, device=device)
        m.run_config = cfg
        return m

    def _loss(self, model: nn.Module, b: Batch, device: torch.device, training: bool) -> Tensor:
        imu = torch.as_tensor(b.imu, dtype=torch.float32, device=device)
        refined = model(imu)
        loss, _terms = imu_loss(refined, b.imu, b.dt, b.dq_wxyz, b.dv, b.dp, b.horizons,
                                bias=b.bias if training else None, cfg=self.config.loss)
        return loss

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        c = self.config
        train, mean, std = start_refiner_fit(self, train, settings)
        self.record = training_record(train, None)  # the training IMU's rate, saved with the checkpoint
        W = self.window
        self.model = ImuRefiner(c.model, mean=mean, std=std)
        augment = c.augment if c.augment is not None else default_augment()
        bc = BatchConfig(window=W, batch_size=settings.batch_size, gravity=settings.gravity, augment=augment)
        log = train_refiner(self.model, train, val, settings, bc, self._loss, c.evals, c.grad_clip, c.val_stride)
        self.run_config = {"method": self.name, "data": {"window": W, "gravity": settings.gravity},
                           "fit_settings": settings.record(), "loss": asdict(c.loss), "augment": asdict(augment)}
        self._best = min(log["val_loss"]) if log["val_loss"] else None
        self._steps = int(settings.steps)
        return log

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        gyro, acc, _ = apply(self.model, seq.gyro, seq.acc, Windowing.for_training_window(self.window))
        return gyro, acc

    def save(self, path: Path) -> None:
        cfg = dict(self.run_config)
        cfg.setdefault("data", {})
        cfg["data"] = {**cfg["data"], "window": self.window}
        save_checkpoint(Path(path), self.model, cfg, epoch=0, step=getattr(self, "_steps", 0),
                        best_metric=getattr(self, "_best", None), record=getattr(self, "record", None))

    def load(self, path: Path) -> Proposed:
        m = Proposed.from_checkpoint(path, device=str(self.device))
        self.model, self.window, self.run_config = m.model, m.window, m.run_config
        self.config = replace(self.config, model=m.model.cfg)
        return self
