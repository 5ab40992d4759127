"""Calibrate a device this project did not tune the VO path on (TUM-VI's BMI160) from the references a
user has: its motion capture thinned to 20 Hz in the IMU's frame, and the same poses made into a VO's
(another sensor's body frame, a world turned and shifted off gravity, 20 Hz, white noise on every pose);
each with every term (``--no-select``) and with ``--select``, scored on the unseen rooms 2 and 4 beside the raw
IMU and the shipped (motion-capture) profile.

For each reference kind: ``imu-learn calibrate --input DATA/tum-vi/dataset-roomR_512_16 --groundtruth
REF_R ...`` (R = 1, 3, 5, the training rooms of configs/tumvi.toml), then ``imu-learn evaluate --config
configs/eval_tumvi.toml --methods raw,profile:models/profiles/tumvi_bmi160/profile.json,profile:P ...``.
A refused calibration (exit 2) is reported with its line. Prints one markdown table of the calibrations
(what was kept at its prior, the held-back block) and evaluate's table; writes OUT/results.json.

    IMU_LEARN_DATA=<root> python experiments/tumvi_vo_reference.py [--out reports/tumvi_vo_reference]

Data: under the data root, tum-vi/dataset-room{1..5}_512_16 (motion capture in mav0/mocap0/data.csv).
Writes: docs/experiments/references.md ("Another device: TUM-VI from a VO-like reference").
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Dict, List

import numpy as np
from scipy.spatial.transform import Rotation

TRAIN = (1, 3, 5)
EVERY = 6  # 120 Hz motion capture -> 20 Hz
R_BODY_DEG = (-90.0, 2.0, -88.0)  # the VO's body (a camera) against the IMU, "xyz" Euler [deg]
P_BODY_M = np.array([0.04, -0.01, 0.02])  # its origin in the IMU frame
R_WORLD_DEG = (35.0, 8.0, -6.0)  # the VO's world against the motion capture's, "zyx" Euler [deg]
T_WORLD_M = np.array([1.0, -2.0, 0.5])
NOISE_M, NOISE_DEG = 0.003, 0.1  # white, per pose and axis


def thinned(src: Path, dst: Path, vo: bool, seed: int) -> Path:
    """The room's motion capture every EVERY-th pose as TUM; ``vo``: seen as the VO of the module doc."""
    d = np.loadtxt(src, delimiter=",", comments="#")[::EVERY]
    t, p, r = d[:, 0] * 1e-9, d[:, 1:4], Rotation.from_quat(d[:, [5, 6, 7, 4]])
    if vo:
        rng = np.random.default_rng(seed)
        r_b, r_w = Rotation.from_euler("xyz", R_BODY_DEG, degrees=True), Rotation.from_euler("zyx", R_WORLD_DEG,
                                                                                              degrees=True)
        p = r_w.apply(p + r.apply(P_BODY_M)) + T_WORLD_M + rng.normal(scale=NOISE_M, size=p.shape)
        r = r_w * r * r_b * Rotation.from_rotvec(rng.normal(scale=np.radians(NOISE_DEG), size=(len(t), 3)))
    np.savetxt(dst, np.column_stack([t, p, r.as_quat()]), fmt="%.9f")
    return dst


def run(cmd: List[str]) -> subprocess.CompletedProcess:
    print("$ " + " ".join(cmd), file=sys.stderr, flush=True)
    return subprocess.run(cmd, capture_output=True, text=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("reports/tumvi_vo_reference"))
    args = ap.parse_args()
    root = Path(os.environ.get("IMU_LEARN_DATA", "../shared/data"))
    args.out.mkdir(parents=True, exist_ok=True)
    exe = [sys.executable, "-m", "imu_learn.cli"]
    results: Dict[str, Dict] = {}
    methods = ["raw", "profile:models/profiles/tumvi_bmi160/profile.json"]
    for kind in ("mocap20hz", "vo"):
        inputs = []
        for r in TRAIN:
            rec = root / f"tum-vi/dataset-room{r}_512_16"
            ref = thinned(rec / "mav0/mocap0/data.csv", args.out / f"room{r}_{kind}.tum", kind == "vo", r)
            inputs += ["--input", str(rec), "--groundtruth", str(ref)]
        for select in (False, True):
            name = kind + ("+select" if select else "")
            out = args.out / name
            p = run(exe + ["calibrate", *inputs, "--device", "tumvi_" + kind, "--out", str(out), "--no-plot"]
                    + (["--select"] if select else ["--no-select"]))
            if p.returncode != 0:
                results[name] = {"exit": p.returncode, "line": (p.stderr.strip().splitlines() or [""])[-1]}
                continue
            prof = json.loads((out / "profile.json").read_text())
            results[name] = {"exit": 0, "selection": [prof["selection"].get("gyro"), prof["selection"].get("acc")]
                             if prof.get("selection") else None,
                             "kept_at_prior": [k["sensor"] for k in prof["checks"].get("kept_at_prior", [])],
                             "held_back": prof["checks"]["held_back"],
                             "rotation_deg": prof.get("reference", {}).get("rotation_deg")}
            methods.append(f"profile:{out / 'profile.json'}")
    print("| reference | calibrate | levels (gyro, acc) | kept at prior | held-back rotation 200 samples: raw / profile [deg] (z) |")
    print("|---|---|---|---|---|")
    for name, r in results.items():
        if r["exit"]:
            print(f"| {name} | exit {r['exit']}: {r['line']} | | | |")
            continue
        h = r["held_back"]
        print(f"| {name} | written | {r['selection']} | {', '.join(r['kept_at_prior']) or '-'} | "
              f"{h['raw_rot_deg']:.3f} / {h['profile_rot_deg']:.3f} ({h.get('z_rot', float('nan')):.1f}) |")
    ev = run(exe + ["evaluate", "--config", "configs/eval_tumvi.toml", "--methods", ",".join(methods),
                    "--out", str(args.out / "evaluate")])
    table = ev.stdout[ev.stdout.find("tumvi: test"):]
    print(table)
    (args.out / "results.json").write_text(json.dumps({"calibrations": results, "evaluate": table}, indent=1))


if __name__ == "__main__":
    main()
