"""KAIST Complex Urban: ``sensor_data/xsens_imu.csv`` and ``global_pose.csv`` (pose only).

No real KAIST file is available to the project; the readers are tested on small fixtures
written in the documented format (see crates/imu_core/src/io/kaist.rs)."""
from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import InvalidInputError
from imu_learn.util.atomic import atomic_write_text

from .source import ImuSource

NAME = "kaist"
IMU_FILE = Path("sensor_data") / "xsens_imu.csv"
POSE_FILE = "global_pose.csv"
COLUMNS = 17  # of xsens_imu.csv (see crates/imu_core/src/io/kaist.rs)
GYRO_COLS = (8, 9, 10)  # 0-based
ACC_COLS = (11, 12, 13)


def detect(path: Path) -> bool:
    """The recording folder (holding ``sensor_data/xsens_imu.csv``) or that file itself."""
    return path.name == IMU_FILE.name or (path.is_dir() and (path / IMU_FILE).exists())


def find_recordings(root: Path) -> List[Path]:
    """Every recording folder under ``root``."""
    return [p.parent.parent for p in root.rglob(str(IMU_FILE))]


def imu_file(path: Path) -> Path:
    """``xsens_imu.csv`` of a recording folder, or the file itself."""
    f = path if path.is_file() else path / IMU_FILE
    if not f.exists():
        raise FileNotFoundError(2, "No such file or directory", str(f))
    return f


def recording_root(imu: Path) -> Path:
    """The recording folder of an ``xsens_imu.csv`` (the folder above ``sensor_data``)."""
    return imu.parent.parent if imu.parent.name == IMU_FILE.parent.name else imu.parent


def read_recording(
    path: Path, groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
) -> Tuple[ImuData, GroundTruth]:
    f = imu_file(Path(path))
    t_ns, gyro, acc = core.read_kaist_imu(str(f), allow_float_timestamps)
    gt_path = Path(groundtruth) if groundtruth else recording_root(f) / POSE_FILE
    d = core.read_kaist_pose(str(gt_path), allow_float_timestamps)
    return ImuData(t_ns, gyro, acc), GroundTruth(d["t_ns"], d["p"], d["q_wxyz"], d.get("v"))


def read_imu_source(path: Path) -> ImuSource:
    f = imu_file(path)
    t_ns, gyro, acc = core.read_kaist_imu(str(f))  # strict validation, and the arrays
    root = recording_root(f)
    return ImuSource(NAME, f, root, f.relative_to(root), t_ns, gyro, acc)


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray) -> None:
    """``out``: ``src``'s CSV with only the gyro and acc columns replaced (shortest round-trip text);
    every other column and blank line is kept as it is."""
    rows = _refined_rows(src.imu_file, gyro, acc)
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerows(rows)
    atomic_write_text(out, text.getvalue())


def _refined_rows(f: Path, gyro: np.ndarray, acc: np.ndarray) -> List[List[str]]:
    with open(f, newline="") as src:
        rows = list(csv.reader(src))
    data_rows = [r for r in rows if r]
    if len(data_rows) != len(gyro):
        raise InvalidInputError(f"{f}: {len(data_rows)} non-empty rows but {len(gyro)} samples were read")
    out, i = [], 0
    for r in rows:
        if r:
            if len(r) != COLUMNS:
                raise InvalidInputError(f"{f}: a row has {len(r)} columns, expected {COLUMNS}")
            r = list(r)
            for c, v in zip(GYRO_COLS + ACC_COLS, (*gyro[i], *acc[i])):
                r[c] = repr(float(v))
            i += 1
        out.append(r)
    return out
