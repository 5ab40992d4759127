"""The paper's IMU model: stacked bidirectional LSTM joined by fully connected layers, mapping raw
6-axis IMU windows to refined 6-axis measurements as a residual on the raw input.

Input normalisation (per-channel mean and std of the training data) is stored in the model as
buffers, so a checkpoint or an exported model needs nothing else to run. A causal variant
(unidirectional LSTM) runs window by window or sample by sample with carried state, for online use.
"""
from __future__ import annotations

import math
from dataclasses import asdict
from typing import List, Optional, Tuple

import torch
from torch import nn

from imu_learn.nn.config import MODEL_STARTS, REFINE_CHANNELS, ModelConfig

Tensor = torch.Tensor
State = List[Tuple[Tensor, Tensor]]


# The FIR branch's output is its taps times this: Adam moves a weight by about lr per step, and
# the taps that matter are O(1/2) (preconditioning, so they are reached in hundreds of steps).
FIR_GAIN = 10.0

def shift_taps(tau: float, taps: int) -> Tensor:
    """FIR taps (taps,) whose zero-DC branch (``ImuRefiner._fir``) adds x(k + tau) - x(k), x(k + tau)
    linearly interpolated between its two nearest samples: the time shift of the `timing` floor
    (:func:`imu_learn.baselines.timing.resample`) as the FIR's starting point."""
    k = taps // 2
    if not abs(tau) <= k:
        raise ValueError(f"model.fir_init_tau: a shift of {tau} samples needs fir_taps >= {2 * math.ceil(abs(tau)) + 1}, "
                         f"got {taps}")
    w = torch.zeros(taps, dtype=torch.float64)
    lo = math.floor(tau)
    frac = tau - lo
    w[k + lo] += 1.0 - frac
    if frac:
        w[k + lo + 1] += frac
    w[k] -= 1.0
    return (w / FIR_GAIN).to(torch.float32)



class ImuRefiner(nn.Module):
    """refined = raw + correction(normalised raw); correction is scaled per channel by the input's
    std so that gyro and accelerometer corrections start on their own scales."""

    def __init__(self, cfg: ModelConfig, mean: Optional[Tensor] = None, std: Optional[Tensor] = None) -> None:
        super().__init__()
        self.cfg = cfg
        self.register_buffer("mean", torch.zeros(6) if mean is None else torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.ones(6) if std is None else torch.as_tensor(std, dtype=torch.float32))
        if cfg.calib:  # identity until set_calibration (fit) or a checkpoint's state_dict fills it
            self.register_buffer("calib_A", torch.eye(6))
            self.register_buffer("calib_c", torch.zeros(6))
        dirs = 1 if cfg.causal else 2
        self.lstms = nn.ModuleList()
        self.fcs = nn.ModuleList()
        width = 6
        for _ in range(cfg.layers):
            self.lstms.append(nn.LSTM(width, cfg.hidden, batch_first=True, bidirectional=not cfg.causal))
            self.fcs.append(nn.Sequential(nn.Linear(dirs * cfg.hidden, cfg.fc), nn.GELU(), nn.Dropout(cfg.dropout)))
            width = cfg.fc
        self.head = nn.Linear(width, 6)
        if cfg.start not in MODEL_STARTS:
            raise ValueError(f"model.start: one of {', '.join(MODEL_STARTS)}, got {cfg.start!r}")
        if cfg.fir_init_tau and not cfg.fir_taps:
            raise ValueError("model.fir_init_tau needs the FIR branch (model.fir_taps >= 3)")
        if cfg.fir_taps:
            if cfg.causal or cfg.fir_taps < 0 or cfg.fir_taps % 2 == 0:
                raise ValueError(f"model.fir_taps: an odd number of taps for the bidirectional model, got {cfg.fir_taps}"
                                 + (" with model.causal = true" if cfg.causal else ""))
            # One filter per channel on its own input (no cross-axis terms) with zero DC gain (the
            # taps' mean is taken out in _fir): it can shape and shift a signal in time but cannot
            # scale it or mix axes. A full 6x6 filter with DC gain was measured to learn scale and
            # misalignment of the training flights that made the validation flights' rotation over
            # 1 s worse (docs/experiments/learning.md).
            self.fir = nn.Conv1d(6, 6, cfg.fir_taps, groups=6, bias=False)
            nn.init.zeros_(self.fir.weight)
            if cfg.fir_init_tau:
                with torch.no_grad():
                    self.fir.weight.copy_(shift_taps(cfg.fir_init_tau, cfg.fir_taps).expand(6, 1, -1))
            # A device profile's floor (start = "profile": its shift and low-pass, set_fir_filter) stays
            # fixed: the network learns what the floor leaves. Trained, 53 taps moved by Adam's ~lr each
            # step made the validation pose error 23 times the floor's after one epoch on the MH_01 crop.
            self.fir.weight.requires_grad_(cfg.start != "profile")
        else:
            self.fir = None
        if cfg.covariance:
            lo = torch.tensor([cfg.sigma_gyro_min] * 3 + [cfg.sigma_acc_min] * 3)
            hi = torch.tensor([cfg.sigma_gyro_max] * 3 + [cfg.sigma_acc_max] * 3)
            if not bool(((lo > 0) & (hi > lo)).all()):
                raise ValueError("model.sigma_*: need 0 < min < max for the gyro and accelerometer sigmas")
            self.register_buffer("log_var_min", 2 * torch.log(lo), persistent=False)
            self.register_buffer("log_var_max", 2 * torch.log(hi), persistent=False)
            # Own two layers on the refiner's features: the noise of a sample depends on the motion
            # (vibration, saturation) in ways the correction does not need to encode linearly.
            self.cov_head: Optional[nn.Module] = nn.Sequential(nn.Linear(width, cfg.fc), nn.GELU(), nn.Linear(cfg.fc, 6))
        else:
            self.cov_head = None
        if cfg.refine not in REFINE_CHANNELS:
            raise ValueError(f"model.refine: must be one of {', '.join(REFINE_CHANNELS)}, got {cfg.refine!r}")
        # Not persistent: derived from the config, so older checkpoints load unchanged.
        self.register_buffer("channels", torch.tensor(REFINE_CHANNELS[cfg.refine], dtype=torch.float32), persistent=False)
        # the FIR branch's channels: every one where the model holds a floor (model.calib: a profile's or a fitted
        # calibration, whose shift it carries), so a gyro-only refiner passes the accelerometer through that floor;
        # otherwise the refined ones (a gyro-only model from raw passes the accelerometer through as read)
        self.register_buffer("fir_channels", torch.ones(6) if cfg.calib else self.channels.clone(), persistent=False)
        # Start as the identity map: the regulariser and the paper both want training to begin
        # from the raw IMU's quality, not from noise.
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def forward(self, imu: Tensor, state: Optional[State] = None, with_variance: bool = False):
        """imu (B, W, 6) gyro then acc -> refined (B, W, 6), same dtype; with ``with_variance`` the
        pair (refined, variances or None) (through forward so that a DDP wrapper sees the call)."""
        out, var, _ = self.forward_full(imu, state)
        return (out, var) if with_variance else out

    def load_refiner(self, state_dict: dict) -> None:
        """Weights of a trained refiner into this model; only the covariance head may be missing
        from them (it keeps its fresh initialisation)."""
        missing, unexpected = self.load_state_dict(state_dict, strict=False)
        bad = [k for k in missing if not k.startswith("cov_head.")] + list(unexpected)
        if bad:
            raise ValueError(f"weights do not fit this model: {', '.join(bad[:6])}")

    def freeze_refiner(self) -> None:
        """Only the covariance head keeps gradients (and dropout off elsewhere is the caller's eval())."""
        for name, p in self.named_parameters():
            p.requires_grad_(name.startswith("cov_head."))

    def forward_with_state(self, imu: Tensor, state: Optional[State] = None) -> Tuple[Tensor, State]:
        refined, _, new_state = self.forward_full(imu, state)
        return refined, new_state

    def forward_with_variance(self, imu: Tensor) -> Tuple[Tensor, Tensor]:
        """imu (B, W, 6) -> refined (B, W, 6) and its per-sample noise variances (B, W, 6)."""
        refined, var, _ = self.forward_full(imu)
        if var is None:
            raise ValueError("this model has no covariance head (model.covariance = false)")
        return refined, var

    def variance(self, features: Tensor) -> Tensor:
        """Per-sample discrete-time noise variances from the last layer's features."""
        assert self.cov_head is not None
        z = torch.sigmoid(self.cov_head(features))
        lo = self.log_var_min.to(features.dtype)
        return torch.exp(lo + (self.log_var_max.to(features.dtype) - lo) * z)

    def forward_full(self, imu: Tensor, state: Optional[State] = None) -> Tuple[Tensor, Optional[Tensor], State]:
        """Refined samples, their variances (None without a covariance head) and the LSTM state."""
        if state is not None and not self.cfg.causal:
            raise ValueError("carried state needs the causal model (bidirectional LSTMs see the future)")
        mean = self.mean.to(imu.dtype)
        std = self.std.to(imu.dtype)
        if self.cfg.calib:  # the fixed calibration on every channel: it is the floor (a profile's), and a
            # model refining the gyro alone passes the accelerometer through its floor, not raw
            imu = imu @ self.calib_A.to(imu.dtype).T + self.calib_c.to(imu.dtype)
        x = (imu - mean) / std
        linear = self._fir(x)
        new_state: State = []
        for i, (lstm, fc) in enumerate(zip(self.lstms, self.fcs)):
            s = None if state is None else state[i]
            x, (h, c) = lstm(x, s)
            new_state.append((h, c))
            x = fc(x)
        corr = self.channels.to(imu.dtype) * self.cfg.output_scale * self.head(x)  # the network: its channels
        if linear is not None:  # the FIR branch (a floor's shift and low-pass)
            corr = corr + self.fir_channels.to(imu.dtype) * linear
        var = self.variance(x) if self.cov_head is not None else None
        return imu + std * corr, var, new_state

    @torch.no_grad()
    def floor(self, imu: Tensor) -> Tensor:
        """What the model starts from: the fixed calibration and the FIR branch alone (no network),
        (B, W, 6) -> (B, W, 6). For start = "profile" that is the profile's floor, fixed in training,
        and the loss regularises the network's residual on top of it (not the floor's own correction)."""
        if self.cfg.calib:
            imu = imu @ self.calib_A.to(imu.dtype).T + self.calib_c.to(imu.dtype)
        linear = self._fir((imu - self.mean.to(imu.dtype)) / self.std.to(imu.dtype))
        if linear is None:
            return imu
        return imu + self.std.to(imu.dtype) * self.fir_channels.to(imu.dtype) * linear

    def _fir(self, x: Tensor) -> Optional[Tensor]:
        """The FIR branch on normalised input (B, W, 6) -> (B, W, 6), or None when off. Not scaled
        by output_scale: its response is O(1) (a half-sample shift is ±1/2)."""
        if self.fir is None:
            return None
        k = self.cfg.fir_taps // 2
        padded = nn.functional.pad(x.transpose(1, 2), (k, k), mode="replicate")
        w = self.fir.weight - self.fir.weight.mean(dim=-1, keepdim=True)
        return FIR_GAIN * nn.functional.conv1d(padded, w, groups=6).transpose(1, 2)

    @torch.no_grad()
    def set_calibration(self, A: Tensor, c: Tensor) -> None:
        """The fixed affine calibration: refined input = A @ [gyro, acc] + c (needs model.calib)."""
        if not self.cfg.calib:
            raise ValueError("set_calibration needs model.calib = true")
        self.calib_A.copy_(torch.as_tensor(A, dtype=torch.float32))
        self.calib_c.copy_(torch.as_tensor(c, dtype=torch.float32))

    @torch.no_grad()
    def set_fir_filter(self, filters: Tensor) -> None:
        """The FIR branch as linear filters of unit DC gain, (6, fir_taps), one per channel, centred:
        the untrained model's output is then ``sum_i filters[c, i] x[k + i - fir_taps // 2]`` per
        channel c (after the fixed calibration); a device profile's time shift and low-pass
        (:func:`imu_learn.train.trainer.profile_start`)."""
        if self.fir is None:
            raise ValueError("set_fir_filter needs the FIR branch (model.fir_taps >= 3)")
        f = torch.as_tensor(filters, dtype=torch.float64)
        k = self.cfg.fir_taps // 2
        if f.shape != (6, self.cfg.fir_taps) or not bool(torch.allclose(f.sum(-1), torch.ones(6, dtype=f.dtype))):
            raise ValueError(f"FIR filters: expected (6, {self.cfg.fir_taps}) of unit sum, got {tuple(f.shape)}")
        f[:, k] -= 1.0  # the branch adds to its input: a residual of zero sum
        self.fir.weight.copy_((f / FIR_GAIN).to(self.fir.weight.dtype)[:, None, :])

    @torch.no_grad()
    def step(self, sample: Tensor, state: Optional[State] = None) -> Tuple[Tensor, State]:
        """One sample (B, 6) -> refined (B, 6) and the state to pass to the next call (causal only)."""
        if not self.cfg.causal:
            raise ValueError("step() needs the causal model")
        out, state = self.forward_with_state(sample[:, None, :], state)
        return out[:, 0], state

    def model_args(self) -> dict:
        return asdict(self.cfg)


