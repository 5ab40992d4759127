"""Whole-recording AOE across ground-truth gaps (Brossard's / AirIMU's --mask protocol) for recordings
whose motion capture drops out (TUM-VI): the gyro integrated open loop from the first sample through
every gap, the error counted only where motion capture measured (score.peers.masked_aoe).

    IMU_LEARN_DATA=<root> python experiments/bridged_aoe.py --recordings tum-vi/dataset-room2_512_16 \
        tum-vi/dataset-room4_512_16 --checkpoint models/tumvi_bmi160.pt \
        --method-dir reports/tumvi/methods          # saved fits of `imu-learn evaluate` (optional)

Prints one line per recording and input: AOE (RMSE) [deg], mean error angle [deg], yaw AOE [deg],
samples counted and bridged.

Writes: the bridged-AOE figures of docs/experiments/learning.md ("Starting from the floor") and
models/tumvi_bmi160.md. Data: TUM-VI dataset-room2_512_16 and dataset-room4_512_16 under the data
root; the shipped models/tumvi_bmi160.pt.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from imu_learn.data.loading import AlignOptions, load_sequence
from imu_learn.score.peers import covered, masked_aoe


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--recordings", nargs="+", required=True, help="recording folders relative to the data root")
    ap.add_argument("--checkpoint", default=None, help="a model to refine the gyro with")
    ap.add_argument("--method-dir", default=None, help="folder with saved fits (<name>.json) of evaluate's methods")
    ap.add_argument("--methods", default="traditional,traditional+timing", help="saved fits to apply from --method-dir")
    ap.add_argument("--bridge-s", type=float, default=3.0, help="longest ground-truth gap bridged [s]")
    ap.add_argument("--measured-gap-s", type=float, default=0.05, help="ground truth counts as measured between stamps this close")
    a = ap.parse_args()
    root = Path(os.environ.get("IMU_LEARN_DATA", "datasets"))
    inputs = {"raw": None}
    if a.method_dir:
        from imu_learn.baselines.registry import load_method_class, safe_name
        for name in [m for m in a.methods.split(",") if m]:
            inputs[name] = load_method_class(name)().load(Path(a.method_dir) / f"{safe_name(name)}.json")
    model = None
    if a.checkpoint:
        from imu_learn.infer.checkpoint import load_model
        model = load_model(Path(a.checkpoint))
        inputs[f"model {Path(a.checkpoint).stem}"] = model
    for rec in a.recordings:
        path = root / rec
        segs = load_sequence(path, options=AlignOptions(max_gap_s=a.bridge_s))
        seq = max(segs, key=len)
        gt = np.loadtxt(path / "mav0" / "mocap0" / "data.csv", delimiter=",", comments="#", usecols=0, dtype=np.float64)
        mask = covered(seq.t_ns, gt.astype(np.int64), a.measured_gap_s)
        for name, m in inputs.items():
            if m is None:
                gyro = seq.gyro
            elif name.startswith("model "):
                from imu_learn.infer.refiner import refine_arrays
                gyro, _ = refine_arrays(m, seq.gyro, seq.acc)
            else:
                gyro, _ = m.refine(seq)
            r = masked_aoe(seq, gyro, mask)
            print(f"{rec}  {name:24s}  AOE {r['aoe_deg']:.3f}  mean {r['aoe_mean_deg']:.3f}  yaw {r['yaw_aoe_deg']:.3f}  "
                  f"samples {r['samples']} bridged {r['bridged']} of {len(seq)} ({len(segs)} segment(s) at {a.bridge_s} s)")


if __name__ == "__main__":
    main()
