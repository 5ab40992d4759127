"""Does an IMU error model learnt on one EuRoC flight carry over to the other?

The traditional intrinsic calibration (:class:`imu_learn.baselines.traditional.Traditional`: scale,
misalignment, bias, g-sensitivity, low-pass) is fitted on each flight in turn and applied to both;
printed is the relative pose RMSE over ``--n`` samples with each input's start-up bias removed
(``fit.bias_removed_pose``, the protocol of fit's final table). In-sample rows show how much of a
flight's error a linear model explains; cross rows show whether it is a property of the IMU
(transfers) or of that flight's recording and ground truth (does not). Also printed: the spread of
the gyro bias in V1_01's ASL ground-truth state, to tell bias drift from everything else.

    python bench/euroc_transfer.py [--data ../shared/data/euroc] [--n 200]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import imu_learn as il
from imu_learn import fit
from imu_learn.baselines.traditional import Traditional
from imu_learn.config import build_config
from imu_learn.metrics import with_imu

FLIGHTS = ("MH_01_easy", "V1_01_easy")


def load(root: Path, name: str):
    s = il.load_sequence(root / name, format="euroc", groundtruth=root / name / "groundtruth_pose.tum")
    return s[0] if isinstance(s, list) else s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data/euroc"))
    ap.add_argument("--n", type=int, default=200, help="horizon in IMU samples")
    args = ap.parse_args()
    seqs = {f: load(args.data, f) for f in FLIGHTS}
    cfg = build_config({}, {"data.startup_bias_s": 10.0, "data.val_stride": 10})

    def score(s):
        r = fit.bias_removed_pose([s], args.n, cfg)
        return f"{r['rot_deg']:.4f} deg {r['trans_m']:.5f} m"

    print(f"relative pose RMSE over {args.n} samples, start-up bias removed, windows every 10 samples from 10 s on")
    for f in FLIGHTS:
        print(f"raw {f:12}: {score(seqs[f])}")
    for fitted_on in FLIGHTS:
        m = Traditional()
        m.fit([seqs[fitted_on]], [seqs[fitted_on]])
        for f in FLIGHTS:
            g, a = m.refine(seqs[f])
            kind = "in-sample" if f == fitted_on else "cross    "
            print(f"traditional fitted on {fitted_on} -> {f} ({kind}): {score(with_imu(seqs[f], g, a))}")
    state = args.data / "V1_01_easy" / "groundtruth_state_20hz.csv"
    if state.is_file():
        d = np.loadtxt(state, delimiter=",", comments="#")
        bw = d[:, 11:14]
        print(f"V1_01 ground-truth gyro bias over the flight: std {np.array2string(bw.std(0), precision=5)} rad/s, "
              f"range {np.array2string(bw.max(0) - bw.min(0), precision=5)} rad/s")


if __name__ == "__main__":
    main()
