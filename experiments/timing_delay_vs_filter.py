"""Is the ``timing`` floor's half-sample "time offset" a delay or a low-pass? A diagnostic of the default
run's test split, not a selection (nothing here is chosen on it).

The ``timing`` floor resamples the IMU by linear interpolation at ``t + tau`` samples
(:func:`imu_learn.baselines.timing.resample`). At tau = 0.5 that is the mean of two neighbours: a delay
*and* a 2-tap low-pass (gain cos(pi f / fs)). This script scores, with the final table's protocol (start-up
bias removed, relative rotation and translation RMSE over n samples), the raw IMU against a pure
fractional delay (an FFT phase shift: magnitude kept), a centred [1 2 1]/4 filter (no delay), both, and
the interpolation itself.

    python experiments/timing_delay_vs_filter.py [--config configs/default.toml]

Writes: one table on stdout (docs/experiments/profile-selection.md, "The offset level: a delay and a
low-pass"). Data: the config's test split (the default: the shipped crops in ``datasets/``, V1_01_easy).
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Callable

import numpy as np

from imu_learn.baselines.timing import shifted
from imu_learn.data.splits import make_split
from imu_learn.data.types import Segment
from imu_learn.score.metrics import variant_table, without_fitted_bias
from imu_learn.train.config import build_config, read_toml


def fft_delay(x: np.ndarray, tau: float) -> np.ndarray:
    """x(t + tau samples) with its magnitude spectrum kept (mirrored to avoid a wrap at the ends)."""
    n = len(x)
    f = np.fft.rfftfreq(2 * n)
    spec = np.fft.rfft(np.r_[x, x[::-1]], axis=0)
    return np.fft.irfft(spec * np.exp(2j * np.pi * f * tau)[:, None], 2 * n, axis=0)[:n]


def centred_121(x: np.ndarray) -> np.ndarray:
    """(x[i-1] + 2 x[i] + x[i+1]) / 4: the low-pass of two 2-tap means, with no delay."""
    y = x.copy()
    y[1:-1] = 0.25 * x[:-2] + 0.5 * x[1:-1] + 0.25 * x[2:]
    return y


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=Path("configs/default.toml"))
    args = ap.parse_args()
    cfg = build_config(read_toml(args.config), {})
    d = cfg.data
    test = make_split(d).test

    def score(name: str, seqs) -> None:
        fixed, _ = without_fitted_bias(seqs, d.startup_bias_s, d.gravity)
        br = variant_table(seqs, fixed, d.eval_horizons, d.eval_stride, d.startup_bias_s, d.gravity)["bias_removed"]
        cells = " | ".join(f"{br[str(n)]['rot_deg']:.4f} / {br[str(n)]['trans_m']:.5f}" for n in d.eval_horizons)
        print(f"| {name} | {cells} |")

    def each(fn: Callable[[np.ndarray], np.ndarray]):
        return [Segment(s.name, s.t_ns, fn(s.gyro), fn(s.acc), s.p, s.v, s.q_wxyz) for s in test]

    print("| input | " + " | ".join(f"n={n}: rot [deg] / trans [m]" for n in d.eval_horizons) + " |")
    print("|---|" + "---|" * len(d.eval_horizons))
    score("raw", list(test))
    for tau in (0.25, 0.5, 0.75, 1.0):
        score(f"linear interpolation at tau = {tau} (the timing floor)", [shifted(s, tau) for s in test])
    for tau in (-0.25, 0.25, 0.5):
        score(f"pure delay {tau:+}", each(lambda x, t=tau: fft_delay(x, t)))
    score("[1 2 1]/4, no delay", each(centred_121))
    score("[1 2 1]/4 and pure delay +0.25", each(lambda x: fft_delay(centred_121(x), 0.25)))


if __name__ == "__main__":
    main()
