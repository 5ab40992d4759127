"""Regenerate the shipped EuRoC crops from full sequences (run from the repository root):

    python datasets/make_crops.py ../shared/data/euroc datasets/euroc --seconds 60

Copies, for each sequence, the IMU rows and ground-truth poses of ``--seconds`` starting at the
first ground-truth stamp, byte for byte (lines are not reformatted), plus the sensor YAML files
and, where the sequence has one, the rows of the ASL full-state ground truth
(``groundtruth_state_20hz.csv``) in the same time span.
"""
from __future__ import annotations

import argparse
import shutil
from pathlib import Path


def crop(src: Path, dst: Path, seconds: float) -> None:
    gt_lines = (src / "groundtruth_pose.tum").read_text().splitlines(keepends=True)
    gt_header = [ln for ln in gt_lines if ln.startswith("#")]
    gt_rows = [ln for ln in gt_lines if ln.strip() and not ln.startswith("#")]
    t0_ns = int(round(float(gt_rows[0].split()[0]) * 1e9))
    t1_ns = t0_ns + int(seconds * 1e9)
    gt_keep = [ln for ln in gt_rows if int(round(float(ln.split()[0]) * 1e9)) <= t1_ns]
    imu_lines = (src / "mav0/imu0/data.csv").read_text().splitlines(keepends=True)
    imu_keep = [imu_lines[0]] + [ln for ln in imu_lines[1:] if t0_ns <= int(ln.split(",")[0]) <= t1_ns]
    (dst / "mav0/imu0").mkdir(parents=True, exist_ok=True)
    (dst / "mav0/imu0/data.csv").write_text("".join(imu_keep))
    (dst / "groundtruth_pose.tum").write_text("".join(gt_header + gt_keep))
    state = src / "groundtruth_state_20hz.csv"
    if state.exists():
        lines = state.read_text().splitlines(keepends=True)
        head = [ln for ln in lines if ln.startswith("#")]
        rows = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
        keep = [ln for ln in rows if t0_ns <= int(ln.split(",")[0]) <= t1_ns]
        (dst / state.name).write_text("".join(head + keep))
        print(f"{dst / state.name}: {len(keep)} states")
    for y in ("mav0/imu0/sensor.yaml", "mav0/body.yaml"):
        if (src / y).exists():
            shutil.copy(src / y, dst / y)
    print(f"{dst}: {len(imu_keep) - 1} IMU rows, {len(gt_keep)} poses")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("src", type=Path)
    ap.add_argument("dst", type=Path)
    ap.add_argument("--seconds", type=float, default=60.0)
    a = ap.parse_args()
    for seq in ("MH_01_easy", "V1_01_easy"):
        crop(a.src / seq, a.dst / seq, a.seconds)


if __name__ == "__main__":
    main()
