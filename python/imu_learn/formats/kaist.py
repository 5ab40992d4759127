"""KAIST Complex Urban: ``sensor_data/xsens_imu.csv`` and ``global_pose.csv`` (pose only).

No real KAIST file is available to the project; the readers are tested on small fixtures
written in the documented format (see crates/imu_core/src/io/kaist.rs)."""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Tuple

from imu_learn import _imu_core as core
from imu_learn.types import GroundTruth, ImuData


def read_recording(
    path: Path, groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
) -> Tuple[ImuData, GroundTruth]:
    root = Path(path)
    t_ns, gyro, acc = core.read_kaist_imu(str(root / "sensor_data" / "xsens_imu.csv"), allow_float_timestamps)
    gt_path = Path(groundtruth) if groundtruth else root / "global_pose.csv"
    d = core.read_kaist_pose(str(gt_path), allow_float_timestamps)
    return ImuData(t_ns, gyro, acc), GroundTruth(d["t_ns"], d["p"], d["q_wxyz"], d.get("v"))
