"""Train the long-context gyro-bias estimator (:mod:`imu_learn.nn.bias_net`) for one device on its
training recordings only (:mod:`imu_learn.train.bias_data`).

Each example: a random window of ``window_s`` from a training segment, the floor applied (the
training mean of the ground-truth biases subtracted), a random constant bias added (uniform in
+-``inject`` rad/s per axis) and the whole window turned by a random rotation (a different mounting:
gyro, accelerometer and target turn together). Target: the injected bias plus that segment's own
residual bias (its ground-truth fit minus the training mean). Loss: mean squared error [(mrad/s)^2].

    python -m imu_learn.train.bias_train --device euroc --out reports/bias/euroc.pt [--steps 1500]
"""
from __future__ import annotations

import argparse
import logging
import os
import time
from typing import List, Tuple

import numpy as np
import torch

from imu_learn.nn.bias_net import BiasNet, BiasNetConfig, block_means, save_bias_net
from imu_learn.train.bias_data import Recording, load_device, training_mean

logger = logging.getLogger(__name__)


def _rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def prepare(recs: List[Recording], mean: np.ndarray, cfg: BiasNetConfig) -> List[Tuple[np.ndarray, np.ndarray]]:
    """(block means (M, 6) of the floor-applied IMU, residual bias (3,)) of every segment at least one
    window long."""
    out = []
    for r in recs:
        x = block_means(r.seg.t_ns, r.seg.gyro - mean[None], r.seg.acc, cfg.rate_hz)
        if len(x) >= cfg.steps:
            out.append((x, r.gyro_bias - mean))
    return out


def batch(data, cfg: BiasNetConfig, size: int, inject: float, rng: np.random.Generator):
    """One batch: windows (size, steps, 6) and targets (size, 3), as float32 tensors."""
    n = cfg.steps
    lens = np.array([len(x) - n + 1 for x, _ in data], dtype=np.float64)
    pick = rng.choice(len(data), size=size, p=lens / lens.sum())
    xs, ys = [], []
    R = _rotations(size, rng)
    for i, k in enumerate(pick):
        x, res = data[k]
        s = rng.integers(0, len(x) - n + 1)
        b = rng.uniform(-inject, inject, 3)
        w = x[s:s + n].copy()
        w[:, :3] += b
        xs.append(np.concatenate([w[:, :3] @ R[i].T, w[:, 3:] @ R[i].T], 1))
        ys.append(R[i] @ (b + res))
    return torch.as_tensor(np.stack(xs), dtype=torch.float32), torch.as_tensor(np.stack(ys), dtype=torch.float32)


def train(device: str, data_root: str, steps: int, seed: int = 0, inject: float = 0.01, lr: float = 1e-3,
          size: int = 32, log_every: int = 100) -> Tuple[BiasNet, dict]:
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    cfg = BiasNetConfig()
    recs = load_device(device, data_root)
    mean = training_mean(recs["train"])
    data = prepare(recs["train"], mean, cfg)
    net = BiasNet(cfg)
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    t0, hist = time.time(), []
    for step in range(1, steps + 1):
        x, y = batch(data, cfg, size, inject, rng)
        loss = torch.mean(((net(x) - y) * 1e3) ** 2)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        hist.append(loss.item())
        if step % log_every == 0:
            logger.info("%s step %d: rms %.3f mrad/s (injected alone %.2f) %.0f s", device, step,
                        np.sqrt(np.mean(hist[-log_every:])), inject / np.sqrt(3) * 1e3, time.time() - t0)
    record = {"device": device, "training_segments": [r.seg.name for r in recs["train"]],
              "training_mean_rad_s": [float(v) for v in mean], "steps": steps, "seed": seed,
              "inject_rad_s": inject, "final_rms_mrad_s": float(np.sqrt(np.mean(hist[-log_every:]))),
              "seconds": round(time.time() - t0, 1)}
    return net, record


def main() -> None:
    ap = argparse.ArgumentParser(description="train the long-context gyro-bias estimator of one device")
    ap.add_argument("--device", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--inject", type=float, default=0.01, help="the random bias's half range per axis [rad/s]")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")  # progress and the result on stderr
    torch.set_num_threads(args.threads)
    net, record = train(args.device, os.environ.get("IMU_LEARN_DATA", "data"), args.steps, args.seed,
                       inject=args.inject)
    save_bias_net(net, args.out, record)
    logger.info("written %s: %s", args.out, record)


if __name__ == "__main__":
    main()
