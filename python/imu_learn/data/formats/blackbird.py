"""Blackbird (as prepared by uzh-rpg/learned_inertial_model_odometry): a folder with
``data.hdf5`` (``ts`` [s], ``gyro_raw``, ``accel_raw``, ...) and ``stamped_groundtruth_imu.txt``
(``ts x y z qx qy qz qw vx vy vz`` at the IMU stamps)."""
from __future__ import annotations

import shutil
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import InvalidInputError
from imu_learn.util.atomic import atomic_write_path

from .groundtruth import read_groundtruth
from .source import ImuSource

NAME = "blackbird"
IMU_FILE = "data.hdf5"
GROUNDTRUTH_NAME = "stamped_groundtruth_imu.txt"


def detect(path: Path) -> bool:
    """The folder holding ``data.hdf5``, or an HDF5 file itself."""
    return path.suffix.lower() in (".hdf5", ".h5") or (path.is_dir() and (path / IMU_FILE).exists())


def find_recordings(root: Path) -> List[Path]:
    """Every folder under ``root`` that holds a ``data.hdf5``."""
    return [p.parent for p in root.rglob(IMU_FILE)]


def hdf5_file(path: Path) -> Path:
    """``data.hdf5`` of a recording folder, or the file itself."""
    return path / IMU_FILE if path.is_dir() else path


def read_imu(path: Path, gt_t_ns: Optional[np.ndarray] = None) -> ImuData:
    """IMU from ``data.hdf5``. Its float64 second stamps carry ~0.2 µs of rounding at 1.5e9 s,
    so when ground-truth stamps (parsed exactly from decimal text) match them to within 1 µs, those
    are used; otherwise the float stamps are rounded to ns."""
    import h5py

    h5 = hdf5_file(Path(path))
    if not h5.exists():
        raise FileNotFoundError(2, "No such file or directory", str(h5))
    with h5py.File(h5, "r") as f:
        missing = [k for k in ("ts", "gyro_raw", "accel_raw") if k not in f]
        if missing:
            raise InvalidInputError(f"{h5}: missing dataset(s) {missing}; expected ts, gyro_raw, accel_raw")
        ts = np.asarray(f["ts"][:], dtype=np.float64)
        gyro = np.ascontiguousarray(f["gyro_raw"][:], dtype=np.float64)
        acc = np.ascontiguousarray(f["accel_raw"][:], dtype=np.float64)
    if gyro.shape != (len(ts), 3) or acc.shape != (len(ts), 3):
        raise InvalidInputError(f"{h5}: ts {ts.shape}, gyro_raw {gyro.shape}, accel_raw {acc.shape} disagree")
    for name, arr in (("ts", ts), ("gyro_raw", gyro), ("accel_raw", acc)):
        bad = np.flatnonzero(~np.isfinite(arr).reshape(len(arr), -1).all(axis=1))
        if bad.size:
            raise InvalidInputError(f"{h5}: dataset {name!r} row {int(bad[0])} is not finite")
    t_ns = np.round(ts * 1e9).astype(np.int64)
    if gt_t_ns is not None and len(gt_t_ns) == len(t_ns) and np.abs(gt_t_ns - t_ns).max() < 1000:
        t_ns = np.asarray(gt_t_ns, dtype=np.int64).copy()
    return ImuData(t_ns=t_ns, gyro=gyro, acc=acc)


def read_recording(
    path: Path, groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
) -> Tuple[ImuData, GroundTruth]:
    path = Path(path)
    root = path if path.is_dir() else path.parent
    gt = read_groundtruth(Path(groundtruth) if groundtruth else root / GROUNDTRUTH_NAME, allow_float_timestamps)
    return read_imu(root, gt.t_ns), gt


def read_imu_source(path: Path) -> ImuSource:
    f = hdf5_file(path)
    imu = read_imu(f)
    return ImuSource(NAME, f, f.parent, Path(f.name), imu.t_ns, imu.gyro, imu.acc)


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray) -> None:
    """``out``: a copy of ``src``'s HDF5 file with ``gyro_raw`` / ``accel_raw`` replaced (each
    dataset keeps its dtype, chunking and attributes; every other dataset is copied as it is)."""
    import h5py

    def fill(tmp: Path) -> None:
        shutil.copyfile(src.imu_file, tmp)
        with h5py.File(tmp, "r+") as h:
            for name, arr in (("gyro_raw", gyro), ("accel_raw", acc)):
                ds = h[name]
                ds[...] = arr.astype(ds.dtype).reshape(ds.shape)

    atomic_write_path(out, fill)
