"""EuRoC ground truth and what can be learnt across the two flights here.

1. V1_01_easy ships two ground truths: ``groundtruth_pose.tum`` (200 Hz, via open_vins) and
   ``groundtruth_state_20hz.csv`` (the ASL full state, EuRoC's own ground truth in the IMU frame).
   Printed: how far apart their poses are at the same stamps, and how well the raw IMU agrees with
   each (relative pose RMSE with the start-up bias removed, ``trainer.bias_removed_pose``, the
   protocol of fit's final table). A constant rotation between them that the IMU does not share
   means one of them is not in the IMU frame.
2. The traditional intrinsic calibration (scale, misalignment, bias, g-sensitivity, low-pass;
   :class:`imu_learn.baselines.traditional.Traditional`) fitted on each flight in turn and applied
   to both: in-sample rows show how much of a flight's error a linear model explains, cross rows
   whether that is a property of the IMU (it transfers) or of the flight (it does not).

    python experiments/euroc_groundtruth.py [--data ../shared/data/euroc]

Writes: docs/experiments/alignment.md, "EuRoC ground truth". Data: EuRoC MH_01_easy and V1_01_easy
with their extra ground-truth files (groundtruth_pose.tum, groundtruth_state_20hz.csv); 1-4 min.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import imu_learn as il
from imu_learn.baselines.traditional import Traditional
from imu_learn.core.quat import quat_conj, quat_mul, xyzw_to_wxyz
from imu_learn.score.metrics import with_imu
from imu_learn.train import trainer
from imu_learn.train.config import build_config

SPARSE = il.AlignOptions(max_gap_s=0.06)  # the ASL state file is 20 Hz


def load(root: Path, name: str, gt: str, options: il.AlignOptions = il.AlignOptions()):
    s = il.load_sequence(root / name, format="euroc", groundtruth=root / name / gt, options=options)
    return s[0] if isinstance(s, list) else s


def compare_files(v1: Path) -> None:
    asl = np.loadtxt(v1 / "groundtruth_state_20hz.csv", delimiter=",", comments="#")
    tum = np.loadtxt(v1 / "groundtruth_pose.tum")
    t_asl, t_tum = asl[:, 0] * 1e-9, tum[:, 0]
    j = np.clip(np.searchsorted(t_tum, t_asl), 1, len(t_tum) - 1)
    j = np.where(np.abs(t_tum[j] - t_asl) < np.abs(t_tum[j - 1] - t_asl), j, j - 1)
    close = np.abs(t_tum[j] - t_asl) < 1e-4
    q_asl, q_tum = asl[close, 4:8], xyzw_to_wxyz(tum[j[close], 4:8])
    d = quat_mul(quat_conj(q_asl), q_tum)  # TUM body in the ASL body frame
    d *= np.sign(d[:, :1])
    angle = np.degrees(2 * np.arcsin(np.clip(np.linalg.norm(d[:, 1:], axis=1), 0, 1)))
    dp = np.linalg.norm(asl[close, 1:4] - tum[j[close], 1:4], axis=1)
    print(f"V1_01, {close.sum()} common stamps: TUM orientation vs ASL state: median {np.median(angle):.2f} deg "
          f"(5-95 %: {np.percentile(angle, 5):.2f}-{np.percentile(angle, 95):.2f}), body-frame axis "
          f"{np.array2string(d[:, 1:].mean(0) / np.linalg.norm(d[:, 1:].mean(0)), precision=2)}; "
          f"position: median {100 * np.median(dp):.1f} cm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data/euroc"))
    args = ap.parse_args()
    cfg = build_config({}, {"data.startup_bias_s": 10.0, "data.val_stride": 10})

    def score(s) -> str:
        return " | ".join(f"n={n}: {r['rot_deg']:.4f} deg {r['trans_m']:.5f} m"
                          for n in (10, 200) for r in [trainer.bias_removed_pose([s], n, cfg)])

    compare_files(args.data / "V1_01_easy")
    mh = load(args.data, "MH_01_easy", "groundtruth_pose.tum")
    v1_tum = load(args.data, "V1_01_easy", "groundtruth_pose.tum")
    v1 = load(args.data, "V1_01_easy", "groundtruth_state_20hz.csv", SPARSE)
    print("raw IMU, start-up bias removed, relative pose RMSE, windows every 10 samples from 10 s on:")
    print(f"  V1_01 against groundtruth_pose.tum      : {score(v1_tum)}")
    print(f"  V1_01 against groundtruth_state_20hz.csv: {score(v1)}")
    print(f"  MH_01 against groundtruth_pose.tum      : {score(mh)}")
    flights = {"MH_01": mh, "V1_01": v1}
    print("traditional calibration (V1_01 scored against the ASL state):")
    for fitted_on, train in flights.items():
        m = Traditional()
        m.fit([train], [train])
        for name, s in flights.items():
            g, a = m.refine(s)
            kind = "in-sample" if name == fitted_on else "cross    "
            print(f"  fitted on {fitted_on} -> {name} ({kind}): {score(with_imu(s, g, a))}")


if __name__ == "__main__":
    main()
