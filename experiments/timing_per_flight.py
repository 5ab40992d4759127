"""Is the time offset one value per device, or does each flight's reference want its own? The ``offset``
level (linear interpolation at ``t + tau`` samples, :func:`imu_learn.baselines.timing.shifted`) scored on
every EuRoC flight at a grid of tau, with the final table's protocol (start-up bias removed, relative
rotation RMSE over 10 and 200 samples, :func:`imu_learn.calib.select.score`). Nothing is fitted: the grid
is scored as it is.

    IMU_LEARN_DATA=DIR python experiments/timing_per_flight.py [--config configs/euroc_paper.toml]

Writes: one table on stdout (docs/experiments/profile-selection.md, "The offset level: a delay and a
low-pass"). Data: the config's train, val and test recordings under the data root (EuRoC's nine flights
with their ground truth).
"""
from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np

from imu_learn.calib.select import SelectOptions, floor_of, score
from imu_learn.data.splits import make_split, recording_name
from imu_learn.train.config import build_config, read_toml

GRID = (0.0, 0.25, 0.5, 0.75, 1.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=Path("configs/euroc_paper.toml"))
    args = ap.parse_args()
    cfg = build_config(read_toml(args.config), {})
    d = cfg.data
    sp = make_split(d)
    per = defaultdict(list)
    for s in [*sp.train, *sp.val, *sp.test]:
        per[recording_name(s.name)].append(s)
    zero = ((np.zeros(21), None), (np.zeros(12), None))
    hz = tuple(d.eval_horizons)
    print("| flight | " + " | ".join(f"rot n={n} [deg] at tau = " + ", ".join(f"{t:g}" for t in GRID) for n in hz)
          + " | best tau per horizon |")
    print("|---|" + "---|" * (len(hz) + 1))
    for name in sorted(per):
        cells = [score(floor_of(*zero, t), per[name], hz, SelectOptions(), d.gravity) for t in GRID]
        row, best = [], []
        for n in hz:
            v = [c[f"rot_deg n={n}"] for c in cells]
            row.append(" / ".join(f"{x:.4g}" for x in v))
            best.append(f"{GRID[int(np.nanargmin(v))]:g}")
        print(f"| {name} | " + " | ".join(row) + " | " + ", ".join(best) + " |", flush=True)


if __name__ == "__main__":
    main()
