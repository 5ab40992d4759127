"""Overlapping Allan deviation of a 10-hour 200 Hz six-axis recording: the Rust core
(imu_learn.core.allan) against allantools.oadev, on the same samples and the same taus.

    python bench/bench_allan.py [--hours 10] [--rate 200] [--per-decade 20] [--repeats 3] [--no-library]

The recording is synthetic (seeded): each axis white noise plus a rate random walk of EuRoC's
ADIS16448 figures (Kalibr's sensor.yaml), plus a constant bias (gravity on acc z). Everything printed
is measured now on this machine (median of --repeats runs, time.perf_counter); the core uses
RAYON_NUM_THREADS threads (all cores unless set), allantools is numpy, single-threaded. allantools
is timed on the same taus (ours stop at m = N/2, allantools one short of it) and on its own
default 'octave' taus; the largest relative difference of the two deviations is printed too.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from typing import Callable, List

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from imu_learn.core.allan import allan_deviation, fit_noise  # noqa: E402
from imu_learn.util.machine import cpu_name  # noqa: E402

# EuRoC's ADIS16448 (Kalibr sensor.yaml): white noise densities and random walks.
GYRO_N, GYRO_K = 1.6968e-04, 1.9393e-05  # rad/s/sqrt(Hz), rad/s^2/sqrt(Hz)
ACC_N, ACC_K = 2.0000e-3, 3.0000e-3  # m/s^2/sqrt(Hz), m/s^3/sqrt(Hz)


def recording(n: int, period: float, seed: int = 0) -> np.ndarray:
    """(n, 6) gyro then acc: white noise + rate random walk + a constant bias."""
    rng = np.random.default_rng(seed)
    out = np.empty((n, 6))
    dens = [GYRO_N] * 3 + [ACC_N] * 3
    walks = [GYRO_K] * 3 + [ACC_K] * 3
    bias = [0.01, -0.02, 0.005, 0.1, -0.2, 9.81]
    for j in range(6):
        out[:, j] = dens[j] / np.sqrt(period) * rng.standard_normal(n)
        out[:, j] += np.cumsum(walks[j] * np.sqrt(period) * rng.standard_normal(n)) + bias[j]
    return out


def timed(fn: Callable[[], object], repeats: int) -> tuple:
    times: List[float] = []
    result = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--per-decade", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-library", action="store_true", help="time the core only")
    a = ap.parse_args(argv)

    period = 1.0 / a.rate
    n = int(round(a.hours * 3600 * a.rate))
    print(f"machine: {cpu_name()}, {os.cpu_count()} cores; Python {platform.python_version()}; "
          f"RAYON_NUM_THREADS={os.environ.get('RAYON_NUM_THREADS', 'all')}")
    t0 = time.perf_counter()
    x = recording(n, period)
    print(f"recording: {n} samples x 6 axes ({a.hours:g} h at {a.rate:g} Hz), made in {time.perf_counter() - t0:.1f} s")

    t_ours, dev = timed(lambda: allan_deviation(x, period, a.per_decade), a.repeats)
    t_fit, fit = timed(lambda: fit_noise(dev), a.repeats)
    print(f"imu_learn (Rust core): {len(dev.tau_s)} taus x 6 axes in {t_ours:.2f} s; slope fits {t_fit * 1e3:.1f} ms")
    for name, j, nn, kk in [("gyro x", 0, GYRO_N, GYRO_K), ("acc x", 3, ACC_N, ACC_K)]:
        print(f"  {name}: N {fit.white.value[j]:.4g} (true {nn:.4g}), K {fit.random_walk.value[j]:.4g} "
              f"(true {kk:.4g}), B {fit.bias_instability[j]:.4g} at {fit.tau_bias[j]:.3g} s")
    if a.no_library:
        return
    try:
        import allantools
    except ImportError:
        print("allantools: not installed (pip install allantools)")
        return
    version = getattr(allantools, "__version__", "?")

    def library(taus) -> list:
        return [allantools.oadev(x[:, j], rate=a.rate, data_type="freq", taus=taus) for j in range(6)]

    t_lib, res = timed(lambda: library(dev.tau_s), 1)
    k = len(res[0][0])
    diff = max(float(np.max(np.abs(res[j][1] / dev.adev[:k, j] - 1))) for j in range(6))
    print(f"allantools {version} oadev: the same {k} taus x 6 axes in {t_lib:.2f} s "
          f"({t_lib / t_ours:.0f}x the core); largest relative difference {diff:.1e}")
    t_oct, res = timed(lambda: library("octave"), 1)
    print(f"allantools {version} oadev: its 'octave' taus ({len(res[0][0])}) x 6 axes in {t_oct:.2f} s")


if __name__ == "__main__":
    main()
