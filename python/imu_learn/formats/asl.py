"""EuRoC / TUM-VI ASL folders (``mav0/imu0/data.csv`` + a ground-truth file)."""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Tuple

from imu_learn import _imu_core as core
from imu_learn.errors import InvalidInputError
from imu_learn.types import GroundTruth, ImuData

from .groundtruth import read_groundtruth

# Searched in order when no ground truth is named: the ASL layout's own files first, then the
# pose-only TUM file that open_vins ships beside a sequence.
GROUNDTRUTH_CANDIDATES = (
    "mav0/state_groundtruth_estimate0/data.csv",
    "mav0/mocap0/data.csv",
    "groundtruth_state.csv",
    "groundtruth_pose.tum",
    "groundtruth.tum",
    "groundtruth.txt",
)


def imu_file(path: Path) -> Path:
    """The IMU CSV of an ASL sequence folder, its ``mav0`` folder, or the CSV itself."""
    if path.is_file():
        return path
    for cand in (path / "mav0" / "imu0" / "data.csv", path / "imu0" / "data.csv"):
        if cand.exists():
            return cand
    raise FileNotFoundError(2, "No such file or directory", str(path / "mav0" / "imu0" / "data.csv"))


def sequence_root(path: Path) -> Path:
    """The folder that holds ``mav0`` for any path inside an ASL sequence."""
    p = path if path.is_dir() else path.parent
    for cand in (p, *p.parents):
        if (cand / "mav0").is_dir():
            return cand
    return p


def find_groundtruth(root: Path) -> Path:
    for rel in GROUNDTRUTH_CANDIDATES:
        if (root / rel).exists():
            return root / rel
    raise InvalidInputError(
        f"{root}: no ground truth found (looked for {', '.join(GROUNDTRUTH_CANDIDATES)}); "
        "pass groundtruth= a TUM or ASL ground-truth file"
    )


def read_imu(path: Path, allow_float_timestamps: bool = False) -> ImuData:
    t_ns, gyro, acc = core.read_asl_imu(str(imu_file(Path(path))), allow_float_timestamps)
    return ImuData(t_ns=t_ns, gyro=gyro, acc=acc)


def read_recording(
    path: Path, groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
) -> Tuple[ImuData, GroundTruth]:
    imu = read_imu(path, allow_float_timestamps)
    gt_path = Path(groundtruth) if groundtruth is not None else find_groundtruth(sequence_root(Path(path)))
    return imu, read_groundtruth(gt_path, allow_float_timestamps)
