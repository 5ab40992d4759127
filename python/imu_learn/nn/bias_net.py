"""A learned estimator of a recording's constant gyro bias over long context: one bias per window of
tens of seconds of the floor-applied IMU (torch).

The IMU is averaged over blocks to ``rate_hz`` (a constant bias survives the averaging), the gyro
[rad/s] and the accelerometer in units of g go through a stack of strided 1-D convolutions, global
average pooling and a linear head scaled by ``out_scale`` [rad/s]; the head starts at zero, so the
untrained estimator says "no bias left". A recording longer than one window gets the mean over
windows ``window_s`` long, half overlapping (:func:`predict_bias`). Trained by
:mod:`imu_learn.train.bias_train` with a random bias added per window, so the bias has to be read from
the signal.
"""
from __future__ import annotations

import pickle
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from torch import nn

from imu_learn.core.stamps import median_period_ns
from imu_learn.errors import InvalidInputError
from imu_learn.util.atomic import atomic_write_bytes

G = 9.80665


@dataclass(frozen=True)
class BiasNetConfig:
    """``window_s`` of IMU averaged to ``rate_hz``; ``channels`` per conv layer (each stride 2,
    kernel ``kernel``); outputs times ``out_scale`` [rad/s]."""

    window_s: float = 30.0
    rate_hz: float = 20.0
    channels: tuple = (32, 32, 64, 64)
    kernel: int = 5
    out_scale: float = 0.01

    @property
    def steps(self) -> int:
        return int(round(self.window_s * self.rate_hz))


class BiasNet(nn.Module):
    """(batch, steps, 6) gyro [rad/s] and acc [g] at ``rate_hz`` -> (batch, 3) gyro bias [rad/s]."""

    def __init__(self, cfg: BiasNetConfig = BiasNetConfig()):
        super().__init__()
        self.cfg = cfg
        layers, c_in = [], 6
        for c in cfg.channels:
            layers += [nn.Conv1d(c_in, c, cfg.kernel, stride=2, padding=cfg.kernel // 2), nn.GELU()]
            c_in = c
        self.body = nn.Sequential(*layers)
        self.head = nn.Linear(c_in, 3)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.body(x.transpose(1, 2)).mean(-1)
        return self.head(h) * self.cfg.out_scale


def block_means(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, rate_hz: float) -> np.ndarray:
    """(M, 6) gyro [rad/s] and acc [g] averaged over blocks of round(rate / rate_hz) samples."""
    rate = 1e9 / median_period_ns(t_ns)
    k = max(1, int(round(rate / rate_hz)))
    x = np.concatenate([np.asarray(gyro, dtype=np.float64), np.asarray(acc, dtype=np.float64) / G], 1)
    m = len(x) // k
    return x[: m * k].reshape(m, k, 6).mean(1)


def predict_bias(net: BiasNet, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> Optional[np.ndarray]:
    """The recording's gyro bias [rad/s] (3,): the mean over half-overlapping windows; None when the
    recording is shorter than one window."""
    x = block_means(t_ns, gyro, acc, net.cfg.rate_hz)
    n = net.cfg.steps
    if len(x) < n:
        return None
    starts = list(range(0, len(x) - n + 1, max(1, n // 2)))
    if starts[-1] != len(x) - n:
        starts.append(len(x) - n)
    batch = torch.as_tensor(np.stack([x[s:s + n] for s in starts]), dtype=torch.float32)
    with torch.no_grad():
        return net.eval()(batch).mean(0).double().numpy()


def save_bias_net(net: BiasNet, path: Path, record: dict) -> None:
    """The estimator and what it was trained on (``record``), as one small torch file."""
    cfg = asdict(net.cfg)
    atomic_write_bytes(Path(path), lambda f: torch.save({"kind": "bias_net", "config": cfg,
                                                          "state": net.state_dict(), "record": record}, f))


def load_bias_net(path, with_record: bool = False):
    """The estimator saved at ``path`` (and, ``with_record``, what it was trained on); loaded with
    ``weights_only=True`` (tensors, numbers, strings: no code runs from the file)."""
    try:
        state = torch.load(Path(path), map_location="cpu", weights_only=True)
    except (OSError, RuntimeError, EOFError, ValueError, pickle.UnpicklingError) as e:
        first = (str(e).strip().splitlines() or [""])[0][:160]
        raise InvalidInputError(f"--bias-model {path}: cannot be read ({type(e).__name__}: {first})") from e
    if not isinstance(state, dict) or state.get("kind") != "bias_net":
        raise InvalidInputError(f"--bias-model {path}: not a bias estimator (imu_learn.train.bias_train writes one)")
    cfg = dict(state["config"])
    cfg["channels"] = tuple(cfg["channels"])
    net = BiasNet(BiasNetConfig(**cfg))
    net.load_state_dict(state["state"])
    return (net.eval(), dict(state.get("record", {}))) if with_record else net.eval()
