"""The end-to-end baseline: a network that regresses the pose change of a window directly from raw
IMU, with no integration (IONet, Chen et al. AAAI 2018; Silva do Monte Lima et al., "End-to-end
learning framework for IMU-based 6-DOF odometry", Sensors 2019).

Model (:class:`EndToEndNet`): the same recurrent family as the proposed refiner, a stack of
bidirectional LSTMs joined by fully connected layers, over a window of n raw samples (gyro then
acc, normalised per channel with the training split's mean and std, stored as buffers). The final
hidden states of the last LSTM (forward direction after sample n-1, backward after sample 0: both
have seen the whole window) go through an FC head to six numbers::

    φ̂  = μ_φ + σ_φ · head[:3]      Δq̂ = Exp(φ̂)         relative rotation, start body frame
    Δp̂ = μ_p + σ_p · head[3:]                           Δp = R_kᵀ (p_{k+n} − p_k)

(μ, σ: per-component mean and std of the training targets, buffers too; the head starts at zero so
the untrained net predicts the training mean). Rotation is regressed as a rotation vector (so3 log)
so that every output is unconstrained and the identity is the origin.

One regressor per scored horizon: ``fit`` trains a separate net for every n in
``FitSettings.horizons`` (the evaluation passes its table's ``eval.horizons``; empty: the single
``FitSettings.window``) on windows of exactly n samples, so the row for n = 10 comes from a net
trained on 10-sample windows, not from a 200-sample net fed 10 samples. Each net gets the full
budget (``FitSettings.steps``), so the fit time grows with the number of horizons (and with n).

Training (per horizon n): windows from the Rust :class:`~imu_learn.core.batches.BatchSampler` (n
samples, no augmentation by default), targets from the ground truth of the training sequences
looked up by each window's ``seq_index``/``start``: Δq = q_k⁻¹ ⊗ q_{k+n}, Δp = R_kᵀ(p_{k+n} − p_k).
Loss: ``w_q`` Huber(|Log(Δq ⊗ Δq̂⁻¹)|, δ_q) + ``w_p`` Huber(|Δp − Δp̂|, δ_p), Huber on the norm of
each 3-vector residual (:func:`imu_learn.nn.losses.huber_norm`), batch mean. Adam at
``FitSettings.lr`` for ``FitSettings.steps`` steps; with validation sequences the weights with the
lowest loss on fixed validation windows (checked ``evals`` times) are kept.

``multi_length`` (off by default): each step trains on a random prefix of the window, one of the
label horizons (the paper's 20/40/60/80/100 % of it), so the net sees several lengths.

Prediction (:meth:`EndToEnd.predict`): from the ground-truth state at each start k,
q_end = q_k ⊗ Δq̂, p_end = p_k + R_k Δp̂ (no velocity). A horizon n that a net was trained for
uses that net. Other n (the evaluation's seconds-based horizons and curve) use the net trained
for the nearest horizon h (by ratio, :meth:`EndToEnd.horizon_for`):

- ``long_horizon="direct"`` (default): the n samples are fed as one sequence (an LSTM takes any
  length). Away from the training length this extrapolates (an IONet-style regressor has no notion
  of elapsed time beyond what it learned), which is part of what the comparison shows;
- ``long_horizon="chain"``: for n above h the n samples are cut into consecutive h-sample segments
  (and a shorter remainder), each regressed on its own (by the net for its length) and composed,
  as IONet chains its windows; n at or below h is fed directly.
"""
from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np
import torch
from torch import nn

from imu_learn.baselines.base import FitSettings, Method, PosePrediction, fit_steps
from imu_learn.core.batches import AugmentConfig, BatchConfig, BatchSampler, batch_seed
from imu_learn.core.quat import quat_mul, quat_rotate
from imu_learn.data.types import Segment
from imu_learn.nn.device import pick_device
from imu_learn.nn.losses import huber_norm
from imu_learn.nn.so3 import quat_conj, so3_exp, so3_log
from imu_learn.nn.so3 import quat_mul as tquat_mul

logger = logging.getLogger(__name__)
Tensor = torch.Tensor
FORMAT = "imu_learn.baselines.end_to_end.v2"  # one net per horizon
FORMAT_V1 = "imu_learn.baselines.end_to_end.v1"  # one net (still read)


@dataclass
class EndToEndConfig:
    hidden: int = 64  # LSTM hidden size per direction
    layers: int = 2  # stacked bidirectional LSTMs, each followed by an FC layer
    fc: int = 64  # width of the FC layers
    dropout: float = 0.0
    w_q: float = 1.0  # weight of the rotation term
    w_p: float = 1.0  # weight of the translation term
    huber_q: float = 0.05  # Huber delta on |Log(Δq Δq̂⁻¹)| [rad]
    huber_p: float = 0.1  # Huber delta on |Δp − Δp̂| [m]
    grad_clip: float = 1.0  # max gradient norm (0: none)
    evals: int = 10  # validation checks over the run (best weights kept)
    val_stride: int = 0  # validation window step [samples]; 0: window // 2
    multi_length: bool = False  # train on random label-horizon prefixes of each window
    long_horizon: str = "direct"  # "direct" or "chain" (see the module docstring)
    predict_batch: int = 256  # windows per forward pass in predict
    augment: AugmentConfig = field(default_factory=AugmentConfig)  # none by default


class EndToEndNet(nn.Module):
    """imu (B, n, 6) raw gyro then acc -> (φ̂ (B, 3) rotation vector, Δp̂ (B, 3) [m]), start body frame."""

    def __init__(self, hidden: int = 64, layers: int = 2, fc: int = 64, dropout: float = 0.0) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(6))
        self.register_buffer("std", torch.ones(6))
        self.register_buffer("out_mean", torch.zeros(6))
        self.register_buffer("out_std", torch.ones(6))
        self.lstms = nn.ModuleList()
        self.fcs = nn.ModuleList()
        width = 6
        for i in range(layers):
            self.lstms.append(nn.LSTM(width, hidden, batch_first=True, bidirectional=True))
            if i + 1 < layers:  # FC layers join consecutive LSTMs; the head reads the last one's states
                self.fcs.append(nn.Sequential(nn.Linear(2 * hidden, fc), nn.GELU(), nn.Dropout(dropout)))
            width = fc
        self.head = nn.Sequential(nn.Linear(2 * hidden, fc), nn.GELU(), nn.Linear(fc, 6))
        nn.init.zeros_(self.head[-1].weight)
        nn.init.zeros_(self.head[-1].bias)

    def forward(self, imu: Tensor) -> Tuple[Tensor, Tensor]:
        x = (imu - self.mean.to(imu.dtype)) / self.std.to(imu.dtype)
        h_n = None
        for i, lstm in enumerate(self.lstms):
            x, (h_n, _c) = lstm(x)
            if i < len(self.fcs):
                x = self.fcs[i](x)
        feat = torch.cat((h_n[-2], h_n[-1]), dim=-1)  # forward after the last sample, backward after the first
        out = self.out_mean.to(imu.dtype) + self.out_std.to(imu.dtype) * self.head(feat)
        return out[:, :3], out[:, 3:]


def window_targets(seqs: List[Segment], seq_index: np.ndarray, start: np.ndarray, n) -> Tuple[np.ndarray, np.ndarray]:
    """Ground-truth (φ = Log(q_k⁻¹ q_{k+n}) (B, 3), Δp = R_kᵀ(p_{k+n} − p_k) (B, 3)); ``n`` int or (B,)."""
    idx = np.asarray(seq_index, dtype=np.int64)
    k = np.asarray(start, dtype=np.int64)
    e = k + np.broadcast_to(np.asarray(n, dtype=np.int64), k.shape)
    qk = np.stack([seqs[i].q_wxyz[j] for i, j in zip(idx, k)])
    qe = np.stack([seqs[i].q_wxyz[j] for i, j in zip(idx, e)])
    pk = np.stack([seqs[i].p[j] for i, j in zip(idx, k)])
    pe = np.stack([seqs[i].p[j] for i, j in zip(idx, e)])
    qk_inv = qk * np.array([1.0, -1.0, -1.0, -1.0])
    dq = quat_mul(qk_inv, qe)
    phi = so3_log(torch.from_numpy(dq)).numpy()
    dp = quat_rotate(qk_inv, pe - pk)
    return phi, dp


class EndToEnd(Method):
    """IONet-style direct regression of (Δq, Δp) per window (see the module docstring)."""

    name = "end-to-end"
    rotation_only = False
    save_suffix = ".pt"

    def __init__(self, config: Optional[EndToEndConfig] = None) -> None:
        self.config = config or EndToEndConfig()
        c = self.config
        self.window = 200  # FitSettings.window of the fit (set by fit / load)
        # horizon n [samples] -> the net trained on n-sample windows (set by fit / load)
        self.nets: Dict[int, EndToEndNet] = {self.window: EndToEndNet(c.hidden, c.layers, c.fc, c.dropout)}
        self.device = torch.device("cpu")

    @property
    def horizons(self) -> List[int]:
        """The window lengths [samples] the nets were trained on."""
        return sorted(self.nets)

    @property
    def net(self) -> EndToEndNet:
        """The net trained on ``window``-sample windows, else the one for the longest horizon."""
        return self.nets.get(self.window) or self.nets[max(self.nets)]

    def horizon_for(self, n: int) -> int:
        """The trained horizon whose net regresses n samples: n itself when trained, else the
        nearest by ratio (|log(n / h)|; a tie goes to the shorter)."""
        n = int(n)
        if n in self.nets:
            return n
        return min(self.nets, key=lambda h: (abs(np.log(n / h)), h))

    # ------------------------------------------------------------------ training

    def _loss(self, net: EndToEndNet, imu: Tensor, phi: Tensor, dp: Tensor) -> Tensor:
        c = self.config
        phi_hat, dp_hat = net(imu)
        r_q = so3_log(tquat_mul(so3_exp(phi), quat_conj(so3_exp(phi_hat))))
        return c.w_q * huber_norm(r_q, c.huber_q).mean() + c.w_p * huber_norm(dp - dp_hat, c.huber_p).mean()

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        """One net per horizon of ``settings.horizons`` (else ``settings.window``), each trained on
        windows of exactly that many samples for ``settings.steps`` steps. Log keys: with one
        horizon ``train_loss``, ``val_loss``, ``val_step``, ``best_step``; with several the same
        prefixed ``n<h>.`` per horizon; ``horizons`` lists the trained ones."""
        self.window = int(settings.window)
        self.device = pick_device(settings.device)
        wanted = sorted({int(h) for h in settings.horizons}) or [self.window]
        usable = [h for h in wanted if any(len(s) > h for s in train)]
        if not usable:
            raise ValueError(f"end-to-end: no training sequence longer than the window ({max(wanted)} samples)")
        skipped = [h for h in wanted if h not in usable]
        if skipped:
            logger.warning("end-to-end: no training sequence longer than %s samples: those horizons use the net "
                           "of the nearest trained one", skipped)
        nets: Dict[int, EndToEndNet] = {}
        log: Dict[str, list] = {"horizons": list(usable)}
        if skipped:
            log["skipped_horizons"] = list(skipped)
        for h in usable:
            nets[h], one = self._fit_one(train, val, settings, h)
            for k, v in one.items():
                log[k if len(usable) == 1 else f"n{h}.{k}"] = v
        self.nets = nets
        return log

    def _fit_one(self, train: List[Segment], val: List[Segment], settings: FitSettings,
                 W: int) -> Tuple[EndToEndNet, Dict[str, list]]:
        """A net trained on windows of W samples, and its log."""
        c = self.config
        train = [s for s in train if len(s) > W]
        val = [s for s in (val or []) if len(s) > W]
        torch.manual_seed(settings.seed)
        net = EndToEndNet(c.hidden, c.layers, c.fc, c.dropout)
        raw = np.concatenate([np.c_[s.gyro, s.acc] for s in train])
        net.mean.copy_(torch.as_tensor(raw.mean(0), dtype=torch.float32))
        net.std.copy_(torch.as_tensor(np.maximum(raw.std(0), 1e-6), dtype=torch.float32))
        bc = BatchConfig(window=W, batch_size=settings.batch_size, gravity=settings.gravity, augment=c.augment)
        sampler = BatchSampler(train, bc)
        # target statistics (output scaling) from every training window at a quarter-window step
        ev = sampler.eval_windows(max(1, W // 4))
        phi_all, dp_all = window_targets(train, ev.seq_index, ev.start, W)
        tgt = np.c_[phi_all, dp_all]
        net.out_mean.copy_(torch.as_tensor(tgt.mean(0), dtype=torch.float32))
        net.out_std.copy_(torch.as_tensor(np.maximum(tgt.std(0), 1e-4), dtype=torch.float32))
        net.to(self.device)

        val_data = None
        if val:
            vb = BatchSampler(val, BatchConfig(window=W, batch_size=1, gravity=settings.gravity)).eval_windows(
                c.val_stride or max(1, W // 2))
            vphi, vdp = window_targets(val, vb.seq_index, vb.start, W)
            val_data = tuple(torch.as_tensor(a, dtype=torch.float32, device=self.device) for a in (vb.imu, vphi, vdp))

        opt = torch.optim.Adam(net.parameters(), lr=settings.lr)
        rng = np.random.default_rng(settings.seed)
        steps = int(settings.steps)
        n_checks = max(1, c.evals)
        checks = {max(1, round(i * steps / n_checks)) for i in range(1, n_checks + 1)}  # evenly spaced, the last step included
        log: Dict[str, list] = {"train_loss": [], "val_loss": [], "val_step": []}
        best, best_state = float("inf"), None
        for step in fit_steps(steps, settings, "end-to-end"):
            b = sampler.sample(batch_seed(settings.seed, 0, step))
            n = W
            if c.multi_length:
                n = int(rng.choice(b.horizons))
            phi, dp = window_targets(train, b.seq_index, b.start, n)
            imu = torch.as_tensor(b.imu[:, :n], dtype=torch.float32, device=self.device)
            net.train()
            loss = self._loss(net, imu, torch.as_tensor(phi, dtype=torch.float32, device=self.device),
                              torch.as_tensor(dp, dtype=torch.float32, device=self.device))
            opt.zero_grad()
            loss.backward()
            if c.grad_clip > 0:
                nn.utils.clip_grad_norm_(net.parameters(), c.grad_clip)
            opt.step()
            log["train_loss"].append(float(loss.detach()))
            if val_data is not None and step + 1 in checks:
                v = self._val_loss(net, *val_data)
                log["val_loss"].append(v)
                log["val_step"].append(step + 1)
                if v < best:
                    best = v
                    best_state = {k: t.detach().clone() for k, t in net.state_dict().items()}
        if best_state is not None:
            net.load_state_dict(best_state)
            log["best_step"] = [log["val_step"][int(np.argmin(log["val_loss"]))]]
        net.eval()
        return net, log

    @torch.no_grad()
    def _val_loss(self, net: EndToEndNet, imu: Tensor, phi: Tensor, dp: Tensor, chunk: int = 256) -> float:
        net.eval()
        tot = 0.0
        for a in range(0, len(imu), chunk):
            tot += float(self._loss(net, imu[a:a + chunk], phi[a:a + chunk], dp[a:a + chunk])) * len(imu[a:a + chunk])
        return tot / max(1, len(imu))

    # ------------------------------------------------------------------ inference

    @torch.no_grad()
    def regress(self, seq: Segment, starts: np.ndarray, n: int) -> Tuple[np.ndarray, np.ndarray]:
        """(Δq̂ (S, 4) wxyz, Δp̂ (S, 3)) for the n samples from each start (start body frame), by the
        net of :meth:`horizon_for` (n); composed from segments of that net's length h when
        ``long_horizon == "chain"`` and n > h."""
        starts = np.asarray(starts, dtype=np.int64)
        n = int(n)
        h = self.horizon_for(n)
        if self.config.long_horizon == "chain" and n > h:
            segs = [(o, min(h, n - o)) for o in range(0, n, h)]
        elif self.config.long_horizon in ("chain", "direct"):
            segs = [(0, n)]
        else:
            raise ValueError(f"end-to-end: long_horizon must be 'direct' or 'chain', got {self.config.long_horizon!r}")
        dq = np.zeros((len(starts), 4))
        dq[:, 0] = 1.0
        dp = np.zeros((len(starts), 3))
        for off, length in segs:
            q_s, p_s = self._regress_direct(seq, starts + off, length)
            dp = dp + quat_rotate(dq, p_s)
            dq = quat_mul(dq, q_s)
        return dq, dp

    @torch.no_grad()
    def _regress_direct(self, seq: Segment, starts: np.ndarray, n: int,
                        horizon: Optional[int] = None) -> Tuple[np.ndarray, np.ndarray]:
        """n samples from each start fed to the net of ``horizon`` (default :meth:`horizon_for` (n))."""
        if len(starts) and (starts.min() < 0 or starts.max() + n > len(seq)):
            raise ValueError(f"end-to-end: windows of {n} samples from the given starts leave the sequence ({len(seq)} samples)")
        net = self.nets[self.horizon_for(n) if horizon is None else int(horizon)]
        net.eval()
        raw = np.c_[seq.gyro, seq.acc].astype(np.float32)
        x_all = torch.from_numpy(raw).to(self.device)
        cols = torch.arange(n, device=self.device)
        qs, ps = [], []
        bs = max(1, self.config.predict_batch)
        for a in range(0, len(starts), bs):
            st = torch.as_tensor(starts[a:a + bs], device=self.device)
            x = x_all[st[:, None] + cols[None, :]]  # (b, n, 6)
            phi, dp = net(x)
            qs.append(so3_exp(phi.double()).cpu().numpy())
            ps.append(dp.double().cpu().numpy())
        if not qs:
            return np.zeros((0, 4)), np.zeros((0, 3))
        return np.concatenate(qs), np.concatenate(ps)

    def predict(self, seq: Segment, starts: np.ndarray, n: int, gravity: float = 9.81) -> PosePrediction:
        k = np.asarray(starts, dtype=np.int64)
        dq, dp = self.regress(seq, k, n)
        qk = seq.q_wxyz[k]
        q_end = quat_mul(qk, dq)
        q_end = q_end / np.linalg.norm(q_end, axis=-1, keepdims=True)
        p_end = seq.p[k] + quat_rotate(qk, dp)
        return PosePrediction(q_wxyz=q_end, p=p_end, v=None)

    # ------------------------------------------------------------------ persistence

    def save(self, path: Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        cfg = asdict(self.config)
        torch.save({"format": FORMAT, "config": cfg, "window": int(self.window),
                    "nets": {int(h): {k: v.detach().cpu() for k, v in net.state_dict().items()}
                             for h, net in self.nets.items()}}, path)

    def load(self, path: Path) -> EndToEnd:
        d = torch.load(Path(path), map_location="cpu", weights_only=True)
        if not isinstance(d, dict) or d.get("format") not in (FORMAT, FORMAT_V1):
            raise ValueError(f"{path}: not an end-to-end baseline file ({FORMAT})")
        cfg = dict(d["config"])
        cfg["augment"] = AugmentConfig(**cfg.get("augment", {}))
        self.config = EndToEndConfig(**cfg)
        c = self.config
        self.window = int(d["window"])
        states = d["nets"] if d["format"] == FORMAT else {self.window: d["state"]}
        self.nets = {}
        for h, state in states.items():
            net = EndToEndNet(c.hidden, c.layers, c.fc, c.dropout)
            net.load_state_dict(state)
            self.nets[int(h)] = net.to(self.device).eval()
        return self
