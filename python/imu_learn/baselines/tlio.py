"""A TLIO-style displacement baseline (Liu et al., "TLIO: Tight Learned Inertial Odometry", RA-L 2020).

What the network does (:class:`TlioNet`): from the IMU samples of a window of ``window_s`` seconds
(1 s: 200 samples on EuRoC; W is taken from the training recordings' median sample rate), each
rotated by its orientation R_i into a gravity-aligned frame, regress the displacement of the window,
p(t + 1 s) - p(t), in the same frame, with a diagonal covariance (3 log-variances)::

    x_i = R_γᵀ R_i [ω_i, a_i]          i = k .. k+W-1 (raw gyro [rad/s] and specific force [m/s²])
    d̂, log σ̂² = net(x)                  d = R_γᵀ (p_{k+W} - p_k)

R_γ = R_z(γ) is the *local gravity-aligned frame*: the world frame (gravity along z) turned about z
by γ = the yaw of the orientation at the window's last sample (TLIO's local frame: gravity-aligned,
yaw taken out). Because γ follows the orientations, rotating the whole trajectory by a yaw ψ turns
the world-frame output R_γ d̂ by exactly ψ (tests/test_baseline_tlio.py checks this). During
training a random yaw (uniform in [-π, π)) is added to γ for input and target together (TLIO's yaw
augmentation), so the net learns to be yaw-equivariant rather than memorising the training rooms'
headings.

Network (:class:`TlioNet`): TLIO uses a 1D ResNet; here a small one that trains on one CPU core in
seconds per hundred steps: a 7-tap stem convolution to 32 channels, four basic residual blocks
(two 3-tap convolutions with batch norm each) of 32, 64, 64, 128 channels, the last three with
stride 2 (200 -> 25 samples), adaptive average pooling to 8 steps, and two fully connected heads
(1024 -> 64 -> 3) for d̂ and for log σ̂². Inputs are normalised with the training split's
statistics (x/y channels pooled, mean zero, so the normalisation is yaw-invariant); the outputs are
scaled by the training targets' RMS (x/y pooled), and the heads start at zero, so the untrained net
predicts d̂ = 0 with the targets' variance. log σ̂² is clamped to [``logvar_min``, ``logvar_max``]
= [-12, 4] by default (σ from 2.5 mm to 7.4 m per axis).

Training (TLIO's recipe, two phases within the shared budget ``FitSettings.steps``): the first
``mse_fraction`` (half by default: 150 of evaluate's 300 steps) with the MSE loss on d̂ alone
(Σ_axes (d - d̂)², batch mean), the rest with the Gaussian negative log-likelihood
½ Σ_axes [(d - d̂)² e^{-log σ̂²} + log σ̂²] (batch mean), Adam at ``FitSettings.lr``, gradient norm
clipped at 1. Windows are drawn by the same Rust :class:`~imu_learn.core.batches.BatchSampler` as the
other learned baselines (no IMU noise or bias augmentation: only the yaw augmentation), the
orientation R_i and the target from the training sequences' **ground truth** (as TLIO trains).
With validation sequences, ``evals`` checks on fixed validation windows (every W/2 samples, no
random yaw) pick the kept weights: the lowest validation NLL among the checks of the NLL phase
(the covariance is what fusion uses), or the lowest validation MSE when there is no NLL phase.

Evaluation (:meth:`TlioStyle.predict`, the evaluate protocol's regressor path). The orientation
that rotates the IMU into the gravity-aligned frame is the **ground-truth orientation of every
window sample** (TLIO's own network-only evaluation does the same); no other ground truth after
the start is used. So this row is NOT under the same protocol as the others: those see only the
start state. The rotation is the raw gyro (as evaluate passes it: raw, or with the start-up bias
removed) integrated from the ground-truth start orientation (TLIO has no rotation output); no
velocity. The position for a window of n samples from start k (W = the net's window):

- n = W: p̂ = p_k + R_γ d̂(k .. k+W-1), the network's own displacement;
- n = m·W + r (m >= 1): m consecutive network windows chained from k, plus for a remainder r > 0
  the rule below for the last r samples;
- n < W (and a remainder r): (r / W) · R_γ d̂ of the window that ENDS at k + n, i.e. its mean
  velocity times the interval: the displacement estimate a live TLIO holds at time k + n (its last
  complete window). It reads IMU samples before k (up to W - r of them), which the other methods
  never see; where k + n < W the first window of the recording is used. At n = 10 (the paper's
  Table II) this is an average-velocity estimate, not an integration, and is scored as such.

Fusion (:mod:`imu_learn.fuse.factors.displacement`): the same network on the graph's causal orientation
estimate, its displacement and covariance as relative-position factors between keyframes
(:meth:`TlioStyle.regress_window`).

Saved as a weights_only-loadable torch file (format ``imu_learn.baselines.tlio.v1``) with the
config, the window and the sample rate.
"""
from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np
import torch
from torch import nn

from imu_learn.baselines.base import FitSettings, Method, PosePrediction, fit_steps, poses_from_imu
from imu_learn.core.batches import BatchConfig, BatchSampler, batch_seed
from imu_learn.core.quat import quat_rotate
from imu_learn.data.types import Segment, sample_rate_hz
from imu_learn.nn.device import pick_device

Tensor = torch.Tensor
FORMAT = "imu_learn.baselines.tlio.v1"


@dataclass
class TlioConfig:
    window_s: float = 1.0  # window [s]; W = round(window_s * the training recordings' sample rate)
    width: int = 32  # channels of the stem; the blocks have width, 2*width, 2*width, 4*width
    fc: int = 64  # hidden width of the two heads
    mse_fraction: float = 0.5  # share of the steps trained with MSE before the NLL phase (TLIO's recipe)
    logvar_min: float = -12.0  # clamp of log σ² [log m²]: σ >= 2.5 mm ...
    logvar_max: float = 4.0  # ... and <= 7.4 m per axis
    yaw_augment: bool = True  # random yaw about gravity added to each training window (input and target)
    grad_clip: float = 1.0  # max gradient norm (0: none)
    evals: int = 10  # validation checks over the run
    val_stride: int = 0  # validation window step [samples]; 0: W // 2
    predict_batch: int = 512  # windows per forward pass in predict


# ---------------------------------------------------------------------------------------------
# frames


def yaw_of_quat(q_wxyz: np.ndarray) -> np.ndarray:
    """Yaw [rad] of body->world quaternions (..., 4): the heading of the body x axis about world z,
    atan2(R[1,0], R[0,0])."""
    w, x, y, z = np.moveaxis(np.asarray(q_wxyz, dtype=np.float64), -1, 0)
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def yaw_of_matrix(R: np.ndarray) -> np.ndarray:
    """Yaw [rad] of rotation matrices (..., 3, 3), as :func:`yaw_of_quat`."""
    R = np.asarray(R, dtype=np.float64)
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


def rot_z(yaw: np.ndarray) -> np.ndarray:
    """R_z(yaw) (..., 3, 3)."""
    c, s = np.cos(yaw), np.sin(yaw)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def world_imu(gyro: np.ndarray, acc: np.ndarray, orientation: np.ndarray) -> np.ndarray:
    """(N, 6): each sample's gyro and specific force rotated into the world frame by its orientation,
    quaternions (N, 4) w,x,y,z or matrices (N, 3, 3) body -> world."""
    o = np.asarray(orientation, dtype=np.float64)
    if o.shape[-1] == 4:
        return np.concatenate([quat_rotate(o, gyro), quat_rotate(o, acc)], axis=-1)
    return np.concatenate([np.einsum("nij,nj->ni", o, gyro), np.einsum("nij,nj->ni", o, acc)], axis=-1)


def to_local(imu_world: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """World-frame IMU windows (B, L, 6) in the local gravity-aligned frame R_z(yaw)ᵀ, yaw (B,)."""
    Rt = np.swapaxes(rot_z(np.asarray(yaw, dtype=np.float64)), -1, -2)  # (B, 3, 3)
    g = np.einsum("bij,blj->bli", Rt, imu_world[..., :3])
    a = np.einsum("bij,blj->bli", Rt, imu_world[..., 3:])
    return np.concatenate([g, a], axis=-1)


def nll_loss(d: Tensor, d_hat: Tensor, logvar: Tensor) -> Tensor:
    """Gaussian negative log-likelihood with diagonal covariance, without the constant:
    ½ Σ_axes [(d - d̂)² e^{-log σ²} + log σ²], batch mean."""
    return (0.5 * ((d - d_hat) ** 2 * torch.exp(-logvar) + logvar)).sum(-1).mean()


def mse_loss(d: Tensor, d_hat: Tensor) -> Tensor:
    """Σ_axes (d - d̂)², batch mean."""
    return ((d - d_hat) ** 2).sum(-1).mean()


# ---------------------------------------------------------------------------------------------
# network


class _Block(nn.Module):
    def __init__(self, cin: int, cout: int, stride: int) -> None:
        super().__init__()
        self.c1 = nn.Conv1d(cin, cout, 3, stride, 1, bias=False)
        self.b1 = nn.BatchNorm1d(cout)
        self.c2 = nn.Conv1d(cout, cout, 3, 1, 1, bias=False)
        self.b2 = nn.BatchNorm1d(cout)
        self.skip = (nn.Identity() if cin == cout and stride == 1 else
                     nn.Sequential(nn.Conv1d(cin, cout, 1, stride, bias=False), nn.BatchNorm1d(cout)))

    def forward(self, x: Tensor) -> Tensor:
        y = torch.relu(self.b1(self.c1(x)))
        return torch.relu(self.b2(self.c2(y)) + self.skip(x))


class TlioNet(nn.Module):
    """x (B, L, 6) gravity-aligned gyro then acc -> (d̂ (B, 3) [m], log σ̂² (B, 3) clamped), same frame."""

    def __init__(self, width: int = 32, fc: int = 64, logvar_min: float = -12.0, logvar_max: float = 4.0) -> None:
        super().__init__()
        self.logvar_min, self.logvar_max = float(logvar_min), float(logvar_max)
        self.register_buffer("in_mean", torch.zeros(6))
        self.register_buffer("in_std", torch.ones(6))
        self.register_buffer("out_scale", torch.ones(3))
        w = int(width)
        self.stem = nn.Sequential(nn.Conv1d(6, w, 7, 1, 3, bias=False), nn.BatchNorm1d(w), nn.ReLU())
        self.blocks = nn.Sequential(_Block(w, w, 1), _Block(w, 2 * w, 2), _Block(2 * w, 2 * w, 2), _Block(2 * w, 4 * w, 2))
        self.pool = nn.AdaptiveAvgPool1d(8)
        feat = 4 * w * 8
        self.head_d = nn.Sequential(nn.Linear(feat, fc), nn.ReLU(), nn.Linear(fc, 3))
        self.head_v = nn.Sequential(nn.Linear(feat, fc), nn.ReLU(), nn.Linear(fc, 3))
        for head in (self.head_d, self.head_v):
            nn.init.zeros_(head[-1].weight)
            nn.init.zeros_(head[-1].bias)

    def forward(self, x: Tensor) -> Tuple[Tensor, Tensor]:
        x = (x - self.in_mean.to(x.dtype)) / self.in_std.to(x.dtype)
        f = self.pool(self.blocks(self.stem(x.transpose(1, 2)))).flatten(1)
        scale = self.out_scale.to(x.dtype)
        d = scale * self.head_d(f)
        logvar = self.head_v(f) + 2.0 * torch.log(scale)
        return d, torch.clamp(logvar, self.logvar_min, self.logvar_max)


# ---------------------------------------------------------------------------------------------
# the method


class TlioStyle(Method):
    """TLIO-style displacement regression over 1 s windows (see the module docstring)."""

    name = "tlio-style"
    rotation_only = False
    save_suffix = ".pt"

    def __init__(self, config: Optional[TlioConfig] = None) -> None:
        self.config = config or TlioConfig()
        c = self.config
        self.window = 200  # W [samples] (set by fit / load)
        self.rate_hz = 200.0
        self.net = TlioNet(c.width, c.fc, c.logvar_min, c.logvar_max)
        self.device = torch.device("cpu")
        self._cache: Dict[tuple, dict] = {}

    # ------------------------------------------------------------------ training

    def _windows(self, world: List[np.ndarray], seqs: List[Segment], seq_index: np.ndarray, start: np.ndarray,
                 rng: Optional[np.random.Generator]) -> Tuple[np.ndarray, np.ndarray]:
        """Inputs (B, W, 6) and targets (B, 3) in the local frame (plus a random yaw when ``rng``)."""
        W = self.window
        idx = np.asarray(seq_index, dtype=np.int64)
        k = np.asarray(start, dtype=np.int64)
        x = np.stack([world[i][j:j + W] for i, j in zip(idx, k)])
        d = np.stack([seqs[i].p[j + W] - seqs[i].p[j] for i, j in zip(idx, k)])
        yaw = np.array([yaw_of_quat(seqs[i].q_wxyz[j + W - 1]) for i, j in zip(idx, k)])
        if rng is not None:
            yaw = yaw + rng.uniform(-np.pi, np.pi, size=len(yaw))
        Rt = np.swapaxes(rot_z(yaw), -1, -2)
        return to_local(x, yaw), np.einsum("bij,bj->bi", Rt, d)

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        """Train on windows of W = round(window_s · rate) samples for ``settings.steps`` steps: the
        first ``mse_fraction`` with MSE, the rest with the NLL. Log keys: ``train_loss`` (each step's
        loss, of its phase), ``phase`` ("mse"/"nll" per step), ``val_mse``, ``val_nll``, ``val_step``,
        ``best_step``, ``window``, ``mse_steps``, ``nll_steps``."""
        c = self.config
        self.device = pick_device(settings.device)
        self.rate_hz = sample_rate_hz(*(s.t_ns for s in train))
        W = self.window = max(2, int(round(c.window_s * self.rate_hz)))
        train = [s for s in train if len(s) > W]
        val = [s for s in (val or []) if len(s) > W]
        if not train:
            raise ValueError(f"tlio-style: no training sequence longer than the window ({W} samples)")
        torch.manual_seed(settings.seed)
        net = TlioNet(c.width, c.fc, c.logvar_min, c.logvar_max)
        world = [world_imu(s.gyro, s.acc, s.q_wxyz) for s in train]
        allw = np.concatenate(world)
        mean = np.zeros(6)
        std = np.ones(6)
        for o in (0, 3):  # gyro, acc: x/y pooled about zero (yaw-invariant), z its own mean and std
            mean[o + 2] = allw[:, o + 2].mean()
            std[o:o + 2] = max(1e-6, float(np.sqrt(np.mean(allw[:, o:o + 2] ** 2))))
            std[o + 2] = max(1e-6, float(allw[:, o + 2].std()))
        net.in_mean.copy_(torch.as_tensor(mean, dtype=torch.float32))
        net.in_std.copy_(torch.as_tensor(std, dtype=torch.float32))
        sampler = BatchSampler(train, BatchConfig(window=W, batch_size=settings.batch_size, gravity=settings.gravity))
        ev = sampler.eval_windows(max(1, W // 4))
        dall = np.stack([train[i].p[j + W] - train[i].p[j] for i, j in zip(ev.seq_index.astype(int), ev.start.astype(int))])
        scale = np.array([np.sqrt(np.mean(dall[:, :2] ** 2))] * 2 + [np.sqrt(np.mean(dall[:, 2] ** 2))])
        net.out_scale.copy_(torch.as_tensor(np.maximum(scale, 1e-3), dtype=torch.float32))
        net.to(self.device)

        val_data = None
        if val:
            vb = BatchSampler(val, BatchConfig(window=W, batch_size=1, gravity=settings.gravity)).eval_windows(
                c.val_stride or max(1, W // 2))
            vworld = [world_imu(s.gyro, s.acc, s.q_wxyz) for s in val]
            vx, vd = self._windows(vworld, val, vb.seq_index, vb.start, None)
            val_data = (torch.as_tensor(vx, dtype=torch.float32, device=self.device),
                        torch.as_tensor(vd, dtype=torch.float32, device=self.device))

        opt = torch.optim.Adam(net.parameters(), lr=settings.lr)
        rng = np.random.default_rng(settings.seed)
        steps = int(settings.steps)
        n_mse = int(round(min(1.0, max(0.0, c.mse_fraction)) * steps))
        n_checks = max(1, c.evals)
        checks = {max(1, round(i * steps / n_checks)) for i in range(1, n_checks + 1)}
        log: Dict[str, list] = {"train_loss": [], "phase": [], "val_mse": [], "val_nll": [], "val_step": [],
                                "window": [W], "mse_steps": [n_mse], "nll_steps": [steps - n_mse]}
        best, best_state = float("inf"), None
        for step in fit_steps(steps, settings, "tlio-style"):
            b = sampler.sample(batch_seed(settings.seed, 0, step))
            x, d = self._windows(world, train, b.seq_index, b.start, rng if c.yaw_augment else None)
            xt = torch.as_tensor(x, dtype=torch.float32, device=self.device)
            dt = torch.as_tensor(d, dtype=torch.float32, device=self.device)
            net.train()
            d_hat, logvar = net(xt)
            nll_phase = step >= n_mse
            loss = nll_loss(dt, d_hat, logvar) if nll_phase else mse_loss(dt, d_hat)
            opt.zero_grad()
            loss.backward()
            if c.grad_clip > 0:
                nn.utils.clip_grad_norm_(net.parameters(), c.grad_clip)
            opt.step()
            log["train_loss"].append(float(loss.detach()))
            log["phase"].append("nll" if nll_phase else "mse")
            if val_data is not None and step + 1 in checks:
                v_mse, v_nll = self._val_losses(net, *val_data)
                log["val_mse"].append(v_mse)
                log["val_nll"].append(v_nll)
                log["val_step"].append(step + 1)
                # the kept weights: best NLL inside the NLL phase (best MSE when there is none)
                score = v_nll if n_mse < steps else v_mse
                if (n_mse == steps or step + 1 > n_mse) and score < best:
                    best = score
                    best_state = {k: t.detach().clone() for k, t in net.state_dict().items()}
                    log["best_step"] = [step + 1]
        if best_state is not None:
            net.load_state_dict(best_state)
        net.eval()
        self.net = net
        self._cache.clear()
        return log

    @torch.no_grad()
    def _val_losses(self, net: TlioNet, x: Tensor, d: Tensor, chunk: int = 512) -> Tuple[float, float]:
        net.eval()
        mse = nll = 0.0
        for a in range(0, len(x), chunk):
            d_hat, logvar = net(x[a:a + chunk])
            m = len(d_hat)
            mse += float(mse_loss(d[a:a + chunk], d_hat)) * m
            nll += float(nll_loss(d[a:a + chunk], d_hat, logvar)) * m
        return mse / max(1, len(x)), nll / max(1, len(x))

    # ------------------------------------------------------------------ inference

    @torch.no_grad()
    def regress_local(self, x_local: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """The net on windows already in the local frame: (d̂ (B, 3), log σ̂² (B, 3)), float64."""
        self.net.eval()
        ds, vs = [], []
        bs = max(1, self.config.predict_batch)
        for a in range(0, len(x_local), bs):
            d, v = self.net(torch.as_tensor(x_local[a:a + bs], dtype=torch.float32, device=self.device))
            ds.append(d.double().cpu().numpy())
            vs.append(v.double().cpu().numpy())
        if not ds:
            return np.zeros((0, 3)), np.zeros((0, 3))
        return np.concatenate(ds), np.concatenate(vs)

    def regress_window(self, imu_world: np.ndarray, R_last: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """One window for fusion: world-frame IMU samples (L, 6) (each rotated by its estimated
        orientation) and the estimated orientation of its last sample (3, 3) -> (d̂ (3,) world frame,
        covariance (3, 3) world frame = R_γ diag(σ̂²) R_γᵀ)."""
        yaw = np.array([yaw_of_matrix(R_last)])
        d, lv = self.regress_local(to_local(np.asarray(imu_world, dtype=np.float64)[None], yaw))
        Rg = rot_z(yaw[0])
        return Rg @ d[0], Rg @ np.diag(np.exp(lv[0])) @ Rg.T

    def _seq_state(self, seq: Segment) -> dict:
        """Per-sequence cache: world-frame IMU (ground-truth orientation), each window-end yaw, and
        the world-frame displacement of every window start computed so far (NaN: not yet)."""
        h = hashlib.blake2b(digest_size=16)
        for a in (seq.gyro, seq.acc, seq.q_wxyz):
            h.update(np.ascontiguousarray(a).tobytes())
        key = (seq.name, len(seq), h.hexdigest(), self.window, id(self.net))
        if key not in self._cache:
            if len(self._cache) >= 4:
                self._cache.pop(next(iter(self._cache)))
            n_win = max(0, len(seq) - self.window + 1)
            self._cache[key] = {"world": world_imu(seq.gyro, seq.acc, seq.q_wxyz),
                                "yaw": yaw_of_quat(seq.q_wxyz), "d": np.full((n_win, 3), np.nan)}
        return self._cache[key]

    def window_displacements(self, seq: Segment, starts: np.ndarray) -> np.ndarray:
        """World-frame displacement estimates (S, 3) of the W-sample windows starting at ``starts``
        (samples s .. s+W-1, i.e. p_{s+W} - p_s), orientation from the sequence's ground truth."""
        W = self.window
        st = self._seq_state(seq)
        s = np.asarray(starts, dtype=np.int64)
        if len(s) and (s.min() < 0 or s.max() >= len(st["d"])):
            raise ValueError(f"tlio-style: windows of {W} samples from the given starts leave the sequence ({len(seq)} samples)")
        need = np.unique(s[np.isnan(st["d"][s, 0])])
        if len(need):
            x = st["world"][need[:, None] + np.arange(W)[None]]  # (M, W, 6)
            yaw = st["yaw"][need + W - 1]
            d, _ = self.regress_local(to_local(x, yaw))
            st["d"][need] = np.einsum("bij,bj->bi", rot_z(yaw), d)
        return st["d"][s]

    def predict(self, seq: Segment, starts: np.ndarray, n: int, gravity: float = 9.81) -> PosePrediction:
        """Rotation: the gyro integrated from the ground-truth start; position: chained network
        windows (see the module docstring for n ≠ W); no velocity."""
        k = np.asarray(starts, dtype=np.int64)
        n = int(n)
        W = self.window
        q = poses_from_imu(seq, seq.gyro, seq.acc, k.astype(np.uint64), n, gravity).q_wxyz
        m, r = divmod(n, W)
        d = np.zeros((len(k), 3))
        for i in range(m):
            d += self.window_displacements(seq, k + i * W)
        if r:
            last = np.clip(k + n - W, 0, max(0, len(seq) - W))
            d += (r / W) * self.window_displacements(seq, last)
        return PosePrediction(q_wxyz=q, p=seq.p[k] + d, v=None)

    # ------------------------------------------------------------------ persistence

    def save(self, path: Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        torch.save({"format": FORMAT, "config": asdict(self.config), "window": int(self.window),
                    "rate_hz": float(self.rate_hz),
                    "state": {k: v.detach().cpu() for k, v in self.net.state_dict().items()}}, path)

    def load(self, path: Path) -> TlioStyle:
        d = torch.load(Path(path), map_location="cpu", weights_only=True)
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise ValueError(f"{path}: not a tlio-style baseline file ({FORMAT})")
        self.config = TlioConfig(**d["config"])
        c = self.config
        self.window = int(d["window"])
        self.rate_hz = float(d["rate_hz"])
        self.net = TlioNet(c.width, c.fc, c.logvar_min, c.logvar_max)
        self.net.load_state_dict(d["state"])
        self.net.to(self.device).eval()
        self._cache.clear()
        return self
