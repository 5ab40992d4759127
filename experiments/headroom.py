"""How much of the test error is left for any model once the start-up bias is removed?

For every test recording of a config, the relative pose RMSE of the final table's second protocol
(start-up bias fitted on the first ``data.startup_bias_s`` seconds and removed; windows from then
on) for inputs that no learned model can beat by much, because each is given something a model
never gets:

* ``raw``: the recorded IMU (the protocol's reference row);
* ``oracle bias``: one constant bias per sensor fitted on the WHOLE test recording instead of its
  first seconds (what is left is everything but a constant bias: noise, bias drift, scale and
  misalignment, timing, ground-truth noise);
* ``oracle calibration``: the traditional intrinsic model (scale, misalignment, g-sensitivity,
  bias, low-pass) fitted on the test recording ITSELF, then the start-up bias removed: an upper
  bound for any constant linear calibration;
* ``midpoint timing``: every sample replaced by the mean of it and the next, i.e. moved half a
  sample earlier: the integration holds sample k over [t_k, t_k+1] (zero-order hold), so this is
  the part of the error that is the hold convention's half-sample delay (a bidirectional refiner
  can learn this shift);
* ``ground truth (noise floor)`` where the ground truth has no velocity: an IMU synthesised from
  the ground truth itself; what remains is label noise.

    python experiments/headroom.py --config configs/euroc_paper.toml      # IMU_LEARN_DATA sets the data root

Writes: docs/experiments/headroom_euroc.md (--config configs/euroc_paper.toml) and
docs/experiments/headroom_tumvi.md (--config configs/tumvi.toml). Data: the config's test
recordings under the data root ($IMU_LEARN_DATA).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Callable, Dict, List

import numpy as np
import torch

from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.noise_floor import synthesize_imu
from imu_learn.baselines.traditional import Traditional
from imu_learn.data.splits import make_split
from imu_learn.data.types import Segment
from imu_learn.score.metrics import relative_pose_rmse_many, with_imu, without_fitted_bias
from imu_learn.train.config import load_config
from imu_learn.train.trainer import recording_of


def startup_removed(seqs: List[Segment], cfg, seconds: float) -> List[Segment]:
    return without_fitted_bias(seqs, seconds, cfg.data.gravity)[0]


def oracle_bias(seqs: List[Segment], cfg) -> List[Segment]:
    return without_fitted_bias(seqs, None, cfg.data.gravity)[0]


def midpoint(s: Segment) -> Segment:
    g, a = s.gyro.copy(), s.acc.copy()
    g[:-1] = 0.5 * (s.gyro[:-1] + s.gyro[1:])
    a[:-1] = 0.5 * (s.acc[:-1] + s.acc[1:])
    return with_imu(s, g, a)


def oracle_calibration(seqs: List[Segment], cfg) -> List[Segment]:
    method = Traditional()
    method.fit(list(seqs), list(seqs), FitSettings(window=cfg.data.window, gravity=cfg.data.gravity))
    return [with_imu(s, *method.refine(s)) for s in seqs]


def noise_floor(seqs: List[Segment], cfg) -> List[Segment]:
    return [with_imu(s, *synthesize_imu(s, gravity=cfg.data.gravity)) for s in seqs]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", required=True, type=Path)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    cfg = load_config(args.config)
    d = cfg.data
    test = make_split(d).test
    recs: Dict[str, List[Segment]] = {}
    for s in test:
        recs.setdefault(recording_of(s.name), []).append(s)
    rows: Dict[str, Callable[[List[Segment]], List[Segment]]] = {
        "raw": lambda ss: startup_removed(ss, cfg, d.startup_bias_s),
        "oracle bias (whole recording)": lambda ss: oracle_bias(ss, cfg),
        "oracle calibration (fitted on the test recording)": lambda ss: startup_removed(oracle_calibration(ss, cfg), cfg, d.startup_bias_s),
        "midpoint timing (half a sample earlier)": lambda ss: startup_removed([midpoint(s) for s in ss], cfg, d.startup_bias_s),
        "ground truth (noise floor)": lambda ss: startup_removed(noise_floor(ss, cfg), cfg, d.startup_bias_s),
    }
    hs = list(d.eval_horizons)
    head = "| recording | input | " + " | ".join(f"n={n} rot [deg] (ratio) | n={n} trans [m] (ratio)" for n in hs) + " |"
    print(head)
    print("|" + "---|" * (2 + 2 * len(hs)))
    for rec, ss in recs.items():
        base = None
        for label, make in rows.items():
            t0 = time.time()
            fixed = make(ss)
            cells = []
            res = {n: relative_pose_rmse_many(fixed, n, d.eval_stride, d.gravity, first_s=d.startup_bias_s) for n in hs}
            if base is None:
                base = res
            for n in hs:
                for key in ("rot_deg", "trans_m"):
                    v, b = res[n][key], base[n][key]
                    cells.append(f"{v:.4g} ({v / b:.2f})" if np.isfinite(v) else "–")
            print(f"| {rec} | {label} | " + " | ".join(cells) + " |", flush=True)
            print(f"  {rec} {label}: {time.time() - t0:.1f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
