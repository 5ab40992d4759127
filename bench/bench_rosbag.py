"""Throughput of ROS bag reading and writing (imu_learn.data.formats.rosbag), measured now on this
machine and printed as a markdown table, for ROS 1, ROS 2 sqlite3 and ROS 2 mcap:

- read IMU: sensor_msgs/msg/Imu messages/s of ``read_imu`` (decode, stamps, checks);
- write: messages/s of ``write_imu`` (every message of the bag copied, the IMU ones re-encoded
  with new vectors), and IMU messages/s of that write.

The bags are the test fixtures' (imu_learn.data.sample_bags from the shipped MH_04_difficult crop:
its IMU, ground truth as three pose topics, positions, images every 5 s), written to a temporary folder.

    python bench/bench_rosbag.py [--repeat 3] [--quick]

Nothing is hard-coded: every figure printed is measured by this run (best of ``--repeat``).
"""
from __future__ import annotations

import argparse
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

from imu_learn.data.formats import rosbag
from imu_learn.data.sample_bags import KINDS, write_sample_bag

REPO = Path(__file__).resolve().parent.parent
CROP = REPO / "datasets" / "euroc" / "MH_04_difficult"


def best_of(repeat: int, fn) -> float:
    """The shortest wall time of ``repeat`` calls of ``fn`` [s]."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def total_messages(bag: Path) -> int:
    with rosbag.open_bag(bag) as reader:
        return int(reader.message_count)


def measure(folder: Path, kind: str, repeat: int, seconds: float) -> dict:
    bag = write_sample_bag(folder, kind, CROP, seconds=seconds)
    src = rosbag.read_imu_source(bag, "/imu0")
    n_imu, n_all = len(src.t_ns), total_messages(bag)
    read_s = best_of(repeat, lambda: rosbag.read_imu(bag, "/imu0"))
    out = folder / f"out_{bag.name}"

    def write() -> None:
        if out.is_dir():
            shutil.rmtree(out)
        rosbag.write_imu(src, out, src.gyro, src.acc)

    write_s = best_of(repeat, write)
    return {"kind": kind, "imu": n_imu, "all": n_all, "read_imu_per_s": n_imu / read_s,
            "write_per_s": n_all / write_s, "write_imu_per_s": n_imu / write_s}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="10 s of the crop, one repeat")
    a = ap.parse_args()
    repeat, seconds = (1, 10.0) if a.quick else (a.repeat, 0.0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in KINDS:
            rows.append(measure(Path(tmp), kind, repeat, seconds))
    print(f"\n### ROS bag throughput ({platform.processor() or platform.machine()}, Python {platform.python_version()},"
          f" best of {repeat})\n")
    print("| bag | IMU msgs | all msgs | read IMU [msg/s] | write [msg/s] | write [IMU msg/s] |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['kind']} | {r['imu']} | {r['all']} | {r['read_imu_per_s']:,.0f} | {r['write_per_s']:,.0f} "
              f"| {r['write_imu_per_s']:,.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
