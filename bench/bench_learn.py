"""Throughput of the learning side, measured now on this machine and printed as a markdown table:

- refine: IMU samples/s of ``imu_learn.refine.refine_arrays`` with the bidirectional model of the
  default size (``ModelConfig()``), window 1000, overlap 200, on the shipped V1_01_easy crop;
- causal step: per-sample latency of ``ImuRefiner.step`` (causal variant, batch 1), median and p99;
- training: windows/s of one optimiser step = Rust batch (``BatchSampler``, B=32, W=200, with
  augmentation) + model forward + ``torch_integration.integrate`` + Huber loss on Δq/Δv/Δp +
  backward + Adam step.

    python bench/bench_learn.py [--threads N] [--device cpu|cuda] [--quick]

Weights are random (throughput does not depend on them). Nothing is hard-coded: every figure
printed is measured by this run.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

from imu_learn.util.machine import cpu_name

REPO = Path(__file__).resolve().parent.parent
CROP = REPO / "datasets" / "euroc" / "V1_01_easy"


def sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def random_head(model):
    with torch.no_grad():
        torch.nn.init.normal_(model.head.weight, std=0.1)
    return model


def bench_refine(device: torch.device, reps: int):
    from imu_learn import _imu_core as core
    from imu_learn.infer.refiner import refine_arrays
    from imu_learn.nn.model import ImuRefiner, ModelConfig

    _t, g, a = core.read_asl_imu(str(CROP / "mav0" / "imu0" / "data.csv"))
    raw = np.c_[g, a]
    model = ImuRefiner(ModelConfig(), torch.tensor(raw.mean(0)), torch.tensor(raw.std(0)))
    model = random_head(model).to(device).eval()
    refine_arrays(model, g, a, window=1000, overlap=200)  # warm-up
    times = []
    for _ in range(reps):
        sync(device)
        t0 = time.perf_counter()
        refine_arrays(model, g, a, window=1000, overlap=200)
        sync(device)
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    return len(g), med, len(g) / med


def bench_step(device: torch.device, steps: int):
    from imu_learn.nn.model import ImuRefiner, ModelConfig

    model = random_head(ImuRefiner(ModelConfig(causal=True))).to(device).eval()
    xs = torch.randn(steps + 100, 1, 6, device=device)
    state = None
    lat = []
    for i in range(len(xs)):
        sync(device)
        t0 = time.perf_counter_ns()
        _y, state = model.step(xs[i], state)
        sync(device)
        if i >= 100:  # the first 100 are warm-up
            lat.append(time.perf_counter_ns() - t0)
    us = np.asarray(lat) / 1e3
    return float(np.median(us)), float(np.percentile(us, 99)), len(us)


def bench_train(device: torch.device, iters: int):
    from imu_learn.core.batches import AugmentConfig, BatchConfig, BatchSampler
    from imu_learn.data.loading import load_sequence
    from imu_learn.nn.integration import integrate
    from imu_learn.nn.model import ImuRefiner, ModelConfig
    from imu_learn.nn.so3 import quat_conj, quat_mul, so3_log

    seqs = load_sequence(CROP)
    aug = AugmentConfig(gyro_noise_density=1.7e-4, acc_noise_density=2e-3, gyro_bias_max=0.01, acc_bias_max=0.1)
    sampler = BatchSampler(seqs, BatchConfig(window=200, batch_size=32, augment=aug))
    raw = np.concatenate([np.c_[s.gyro, s.acc] for s in seqs])
    model = ImuRefiner(ModelConfig(), torch.tensor(raw.mean(0)), torch.tensor(raw.std(0))).to(device).train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    huber = torch.nn.HuberLoss(delta=1.0)

    def f32(a):
        return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).to(device)

    def one(seed: int) -> float:
        t0 = time.perf_counter()
        b = sampler.sample(seed)
        t_batch = time.perf_counter() - t0
        imu, dt = f32(b.imu), f32(b.dt)
        refined = model(imu)
        inc = integrate(refined[..., :3], refined[..., 3:], dt, [int(h) for h in b.horizons])
        rot = so3_log(quat_mul(quat_conj(f32(b.dq_wxyz)), inc.dq_wxyz))
        loss = huber(rot, torch.zeros_like(rot)) + huber(inc.dv, f32(b.dv)) + huber(inc.dp, f32(b.dp))
        if not torch.isfinite(loss):
            raise RuntimeError(f"training loss is not finite: {loss.item()}")
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sync(device)
        return t_batch

    for s in range(3):  # warm-up
        one(s)
    t0 = time.perf_counter()
    t_batches = [one(100 + s) for s in range(iters)]
    total = time.perf_counter() - t0
    return iters * 32 / total, total / iters, sum(t_batches) / iters


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--threads", type=int, default=None, help="torch intra-op threads (default: torch's own)")
    p.add_argument("--device", default="cpu", help="cpu (default) or cuda")
    p.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = p.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        print("error: --device cuda but CUDA is not available", file=sys.stderr)
        return 2
    reps, steps, iters = (3, 500, 5) if args.quick else (7, 3000, 20)

    n, t_ref, sps = bench_refine(device, reps)
    med, p99, nsteps = bench_step(device, steps)
    wps, t_it, t_b = bench_train(device, iters)

    dev = torch.cuda.get_device_name(device) if device.type == "cuda" else cpu_name()
    print(f"torch {torch.__version__}, threads {torch.get_num_threads()} (of {os.cpu_count()} CPUs), "
          f"device {device.type}: {dev}, RAYON_NUM_THREADS={os.environ.get('RAYON_NUM_THREADS', 'unset')}, "
          f"python {platform.python_version()}")
    print()
    print("| benchmark | setting | result |")
    print("|---|---|---|")
    print(f"| refine (bidirectional, ModelConfig()) | V1_01 crop, {n} samples, window 1000 overlap 200, "
          f"median of {reps} | {sps:,.0f} IMU samples/s ({t_ref * 1e3:.1f} ms per pass) |")
    print(f"| causal `step()` latency | batch 1, {nsteps} steps | median {med:.0f} µs, p99 {p99:.0f} µs |")
    print(f"| training step | B=32, W=200, Rust batch + forward + integrate + Huber + backward + Adam, "
          f"{iters} steps | {wps:,.0f} windows/s ({t_it * 1e3:.0f} ms/step, of which Rust batch "
          f"{t_b * 1e3:.1f} ms) |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
