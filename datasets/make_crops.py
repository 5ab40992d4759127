"""Regenerate the shipped crops from full sequences (run from the repository root):

    python datasets/make_crops.py ../shared/data/euroc datasets/euroc --seconds 60
    python datasets/make_crops.py --dataset tum-vi ../shared/data/tum-vi datasets/tum-vi --seconds 34

EuRoC: copies, for each sequence, the IMU rows and ground-truth poses of ``--seconds`` starting at
the first ground-truth stamp, byte for byte (lines are not reformatted), plus the sensor YAML files
and, where the sequence has one, the rows of the ASL full-state ground truth
(``groundtruth_state_20hz.csv``) in the same time span.

EuRoC full state (MH_04_difficult, a test flight of the standard split with EuRoC's 200 Hz full-state
ground truth; the check crop of the shipped EuRoC model): ``--dataset euroc-state`` copies the
``mav0/imu0`` and ``mav0/state_groundtruth_estimate0`` rows of ``--seconds`` from ``--start-s`` after
the first ground-truth stamp, byte for byte, and the sensor YAML files:

    python datasets/make_crops.py --dataset euroc-state ../shared/data/euroc datasets/euroc --seconds 60 --start-s 20

TUM-VI (room2, a test room of the standard split): copies the ``mav0/imu0`` and ``mav0/mocap0``
rows of ``--seconds`` byte for byte, from the start of the first stretch of motion capture with no
gap above ``--max-gap-ms`` (50 ms: the loader's default, so the crop aligns as one segment) that is
at least that long; the recording's start when its first stretch is long enough, else the next.
"""
from __future__ import annotations

import argparse
import shutil
from pathlib import Path
from typing import List, Tuple


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


def _lines(path: Path) -> List[str]:
    """The file's lines with their own line ends (bytes are written back unchanged)."""
    return path.read_bytes().decode().splitlines(keepends=True)


def _stamp(line: str) -> int:
    return int(line.split(",")[0])


def _header_and_rows(path: Path) -> Tuple[List[str], List[str]]:
    lines = _lines(path)
    return [ln for ln in lines if ln.startswith("#")], [ln for ln in lines if ln.strip() and not ln.startswith("#")]


def _copy_rows(src: Path, dst: Path, t0_ns: int, t1_ns: int) -> int:
    """The header and the rows stamped in [t0_ns, t1_ns] of ``src`` written to ``dst``, bytes unchanged."""
    head, rows = _header_and_rows(src)
    keep = [ln for ln in rows if t0_ns <= _stamp(ln) <= t1_ns]
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_bytes("".join(head + keep).encode())
    return len(keep)


def gap_free_start(stamps: List[int], seconds: float, max_gap_ns: int) -> int:
    """Index of the first stamp that starts a run of ``seconds`` with no step above ``max_gap_ns``."""
    span = int(seconds * 1e9)
    start = 0
    for i in range(1, len(stamps)):
        if stamps[i] - stamps[i - 1] > max_gap_ns:
            start = i
        elif stamps[i] - stamps[start] >= span:
            return start
    raise SystemExit(f"no {seconds:g} s stretch without a ground-truth gap above {max_gap_ns / 1e6:g} ms")


def crop_tumvi(src: Path, dst: Path, seconds: float, max_gap_ms: float = 50.0) -> None:
    mocap = "mav0/mocap0/data.csv"
    stamps = [_stamp(ln) for ln in _header_and_rows(src / mocap)[1]]
    k = gap_free_start(stamps, seconds, int(max_gap_ms * 1e6))
    t0_ns = stamps[k]
    t1_ns = t0_ns + int(seconds * 1e9)
    n_imu = _copy_rows(src / "mav0/imu0/data.csv", dst / "mav0/imu0/data.csv", t0_ns, t1_ns)
    n_mocap = _copy_rows(src / mocap, dst / mocap, t0_ns, t1_ns)
    imu_t0 = _stamp(_header_and_rows(src / "mav0/imu0/data.csv")[1][0])
    print(f"{dst}: {n_imu} IMU rows, {n_mocap} mocap poses, "
          f"{(t0_ns - imu_t0) / 1e9:.3f} s to {(t1_ns - imu_t0) / 1e9:.3f} s of the recording")


def crop_asl_state(src: Path, dst: Path, seconds: float, start_s: float) -> None:
    state = "mav0/state_groundtruth_estimate0/data.csv"
    t0_ns = _stamp(_header_and_rows(src / state)[1][0]) + int(start_s * 1e9)
    t1_ns = t0_ns + int(seconds * 1e9)
    n_imu = _copy_rows(src / "mav0/imu0/data.csv", dst / "mav0/imu0/data.csv", t0_ns, t1_ns)
    n_gt = _copy_rows(src / state, dst / state, t0_ns, t1_ns)
    for y in ("mav0/imu0/sensor.yaml", "mav0/body.yaml"):
        if (src / y).exists():
            shutil.copy(src / y, dst / y)
    print(f"{dst}: {n_imu} IMU rows, {n_gt} states")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("src", type=Path, help="the folder holding the full sequences")
    ap.add_argument("dst", type=Path)
    ap.add_argument("--dataset", choices=("euroc", "euroc-state", "tum-vi"), default="euroc")
    ap.add_argument("--seconds", type=float, help="length of each crop (default 60 EuRoC, 34 TUM-VI)")
    ap.add_argument("--start-s", type=float, default=20.0, help="euroc-state: seconds skipped after the first state")
    ap.add_argument("--max-gap-ms", type=float, default=50.0, help="TUM-VI: largest mocap gap allowed")
    a = ap.parse_args()
    if a.dataset == "euroc":
        for seq in ("MH_01_easy", "V1_01_easy"):
            crop(a.src / seq, a.dst / seq, a.seconds or 60.0)
    elif a.dataset == "euroc-state":
        seq = "MH_04_difficult"
        crop_asl_state(a.src / seq, a.dst / seq, a.seconds or 60.0, a.start_s)
    else:
        seq = "dataset-room2_512_16"
        crop_tumvi(a.src / seq, a.dst / seq, a.seconds or 34.0, a.max_gap_ms)


if __name__ == "__main__":
    main()
