"""Ground-truth files that stand on their own: TUM trajectories and ASL state / pose CSVs."""
from __future__ import annotations

from pathlib import Path

from imu_learn import _imu_core as core
from imu_learn.data.types import GroundTruth


def _from_dict(d: dict) -> GroundTruth:
    return GroundTruth(t_ns=d["t_ns"], p=d["p"], q_wxyz=d["q_wxyz"], v=d.get("v"))


def read_groundtruth(path: Path, allow_float_timestamps: bool = False) -> GroundTruth:
    """Read a TUM file (``.tum``/``.txt``: ``t[s] tx ty tz qx qy qz qw`` [vx vy vz]) or an ASL CSV.

    An ASL CSV with 17 columns is a full state (p, q_wxyz, v, biases); with 8 columns it is a pose
    (TUM-VI ``mocap0``). The column count is read from the header.
    """
    path = Path(path)
    if path.suffix.lower() != ".csv":
        return _from_dict(core.read_tum(str(path), allow_float_timestamps))
    with open(path, encoding="utf-8", errors="replace") as f:
        header = f.readline()
    if header.count(",") + 1 == 8:
        return _from_dict(core.read_asl_pose(str(path), allow_float_timestamps))
    return _from_dict(core.read_asl_state(str(path), allow_float_timestamps))
