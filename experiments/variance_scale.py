"""k_gyro, k_acc of a covariance head over keyframe intervals (imu_learn.fuse.variance), per recording and pooled.

    OMP_NUM_THREADS=1 python experiments/variance_scale.py --checkpoint models/euroc_adis16448_cov.pt \
        --data-root ../shared/data --K 20 \
        euroc/MH_01_easy euroc/MH_03_medium euroc/MH_05_difficult euroc/V2_01_easy euroc/V2_03_difficult

Each recording is DIR[=GROUNDTRUTH] relative to --data-root (EuRoC default ground truth:
mav0/state_groundtruth_estimate0/data.csv, the files of configs/euroc_paper.toml). Prints one line
per recording and the pooled line; ``--json FILE`` writes them too. The k to pass to
``imu-learn fuse --variance-scale`` is the pooled robust pair (k_gyro, k_acc).

Writes: docs/experiments/navigate.md, "Calibrating the learned variances over the keyframe
interval" (the pooled k behind ``imu-learn navigate --variance-scale``). Data: the EuRoC flights
listed above under --data-root; models/euroc_adis16448_cov.pt. The calibration itself is the
library's (imu_learn.fuse.variance.calibrate_model); this runs it over recordings and prints.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recordings", nargs="+", metavar="DIR[=GT]")
    ap.add_argument("--checkpoint", type=Path, default=Path("models/euroc_adis16448_cov.pt"))
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument("--K", type=int, default=20, help="samples per keyframe interval (default 20: 10 Hz at 200 Hz)")
    ap.add_argument("--gravity", type=float, default=9.81)
    ap.add_argument("--skip-s", type=float, default=0.0, help="seconds dropped at each recording's start")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)

    import torch

    from imu_learn.data.loading import load_recording
    from imu_learn.fuse.variance import calibrate_model
    from imu_learn.infer.checkpoint import load_model

    torch.set_num_threads(a.threads)
    model = load_model(a.checkpoint)
    seqs = []
    for spec in a.recordings:
        d, _, gt = spec.partition("=")
        path = a.data_root / d
        gt_path = a.data_root / gt if gt else path / "mav0/state_groundtruth_estimate0/data.csv"
        rec = load_recording(path, format="euroc", groundtruth=gt_path)
        seqs.extend(rec.segments)
    out = calibrate_model(model, seqs, K=a.K, gravity=a.gravity, skip_s=a.skip_s)
    rows = {**{k: v.as_dict() for k, v in out["per_sequence"].items()}, "pooled": out["pooled"].as_dict()}
    print(f"checkpoint {a.checkpoint}, K = {a.K}; k: robust median(z^2)/0.4549 (mean z^2)")
    for name, r in rows.items():
        print(f"{name:20s} k_gyro {r['k_gyro']:.4f} ({r['k_gyro_mean']:.4f})  k_acc {r['k_acc']:.4f} "
              f"({r['k_acc_mean']:.4f})  intervals {r['intervals']}")
    if a.json is not None:
        a.json.write_text(json.dumps({"checkpoint": str(a.checkpoint), "K": a.K, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
