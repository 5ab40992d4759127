"""Is the time offset one value per device, or does each flight's reference want its own? The ``offset``
level (linear interpolation at ``t + tau`` samples, :func:`imu_learn.baselines.timing.shifted`) scored on
every EuRoC flight at a grid of tau, with the final table's protocol (start-up bias removed, relative
rotation RMSE over 10 and 200 samples, :func:`imu_learn.calib.select.score`). Nothing is fitted: the grid
is scored as it is.

    IMU_LEARN_DATA=DIR python experiments/timing_per_flight.py [--config configs/euroc_paper.toml]
    python experiments/timing_per_flight.py --input DIR/euroc/V1_01_easy \
        --groundtruth DIR/euroc/V1_01_easy/groundtruth_state_20hz.csv --groundtruth DIR/euroc/V1_01_easy/groundtruth_pose.tum

The second form scores one recording against each reference given, as is and with the reference's body
frame turned onto the IMU's (R_off, fitted on the angular rates as ``imu-learn groundtruth`` fits it).

Writes: one table on stdout (docs/experiments/profile-selection.md, "The offset level: a delay and a
low-pass"). Data: the config's train, val and test recordings under the data root (EuRoC's nine flights
with their ground truth); the second form, V1_01_easy's two references (the 20 Hz OpenVINS state and
EuRoC's original 200 Hz estimate).
"""
from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np

from imu_learn.calib.frames import default_gap_s, fit_offset, segments
from imu_learn.calib.select import SelectOptions, floor_of, score
from imu_learn.data.splits import make_split, recording_name
from imu_learn.eval import groundtruth as gt_check
from imu_learn.train.config import build_config, read_toml

GRID = (0.0, 0.25, 0.5, 0.75, 1.0)
ZERO = ((np.zeros(21), None), (np.zeros(12), None))  # no floor terms: the offset level alone


def cells(segs, horizons, gravity: float) -> str:
    """The grid's rotation cells on ``segs`` per horizon, and the best tau of each."""
    by = [score(floor_of(*ZERO, t), segs, horizons, SelectOptions(), gravity) for t in GRID]
    row, best = [], []
    for n in horizons:
        v = [c[f"rot_deg n={n}"] for c in by]
        row.append(" / ".join(f"{x:.4g}" for x in v))
        best.append(f"{GRID[int(np.nanargmin(v))]:g}")
    return " | ".join(row) + " | " + ", ".join(best)


def references(rec: Path, files, horizons=(10, 200), gravity: float = 9.81) -> None:
    """One recording against each reference file, as is and with R_off applied."""
    print("| reference | R_off | " + " | ".join(f"rot n={n} [deg] at tau = " + ", ".join(f"{t:g}" for t in GRID)
                                         for n in horizons) + " | best tau per horizon |")
    print("|---|---|" + "---|" * (len(horizons) + 1))
    for f in files:
        imu, gt = gt_check.read(rec, f)[:2]
        gap = default_gap_s(gt)
        off = fit_offset(segments(imu, gt, gap))
        deg = gt_check.angle_axis(off.r_off)[0]
        for label, r in (("as is", None), (f"applied ({deg:.2f} deg)", off.r_off)):
            print(f"| {Path(f).name} | {label} | {cells(segments(imu, gt, gap, r_off=r), horizons, gravity)} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=Path("configs/euroc_paper.toml"))
    ap.add_argument("--input", type=Path, help="one recording, scored against each --groundtruth")
    ap.add_argument("--groundtruth", type=Path, action="append", default=[])
    args = ap.parse_args()
    if args.input is not None:
        references(args.input, args.groundtruth)
        return
    cfg = build_config(read_toml(args.config), {})
    d = cfg.data
    sp = make_split(d)
    per = defaultdict(list)
    for s in [*sp.train, *sp.val, *sp.test]:
        per[recording_name(s.name)].append(s)
    hz = tuple(d.eval_horizons)
    print("| flight | " + " | ".join(f"rot n={n} [deg] at tau = " + ", ".join(f"{t:g}" for t in GRID) for n in hz)
          + " | best tau per horizon |")
    print("|---|" + "---|" * (len(hz) + 1))
    for name in sorted(per):
        print(f"| {name} | {cells(per[name], hz, d.gravity)} |", flush=True)


if __name__ == "__main__":
    main()
