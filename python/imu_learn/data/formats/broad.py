"""BROAD benchmark trials (``.mat``): ``imu_gyr`` [rad/s], ``imu_acc`` [m/s^2], ``opt_quat``
(w,x,y,z, IMU -> ENU world, NaN where the optical system lost the body), ``opt_pos`` [m] and
``sampling_rate`` [Hz]; no timestamps, so sample i is at i / sampling_rate.

Rows whose optical ground truth is NaN are removed from the ground truth; the Rust alignment then
sees them as gaps and splits the recording into segments there.
"""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import InvalidInputError
from imu_learn.util.atomic import atomic_write_bytes

from .source import ImuSource

NAME = "broad"
IMU_VARIABLES = ("imu_gyr", "imu_acc")
TRIAL_VARIABLES = (*IMU_VARIABLES, "opt_quat", "opt_pos", "sampling_rate")


def detect(path: Path) -> bool:
    """A ``.mat`` trial."""
    return path.suffix.lower() == ".mat"


def find_recordings(root: Path) -> List[Path]:
    """Every ``.mat`` trial under ``root``."""
    return list(root.rglob("*.mat"))


def _load_mat(path: Path, required: Tuple[str, ...]) -> dict:
    """Every variable of a ``.mat`` file; :class:`InvalidInputError` naming those of ``required``
    it lacks."""
    import scipy.io

    m = scipy.io.loadmat(str(path))
    missing = [k for k in required if k not in m]
    if missing:
        raise InvalidInputError(f"{path}: missing variable(s) {missing}")
    return m


def read_recording(
    path: Path, groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
) -> Tuple[ImuData, GroundTruth]:
    path = Path(path)
    if groundtruth is not None:
        raise InvalidInputError("BROAD trials carry their own ground truth; groundtruth= is not used")
    m = _load_mat(path, TRIAL_VARIABLES)
    fs = _rate(path, m)
    gyro = np.ascontiguousarray(m["imu_gyr"], dtype=np.float64)
    acc = np.ascontiguousarray(m["imu_acc"], dtype=np.float64)
    q = np.asarray(m["opt_quat"], dtype=np.float64)
    p = np.asarray(m["opt_pos"], dtype=np.float64)
    n = len(gyro)
    if not (acc.shape == gyro.shape == (n, 3) and q.shape == (n, 4) and p.shape == (n, 3)):
        raise InvalidInputError(
            f"{path}: array shapes disagree: gyr {gyro.shape} acc {acc.shape} quat {q.shape} pos {p.shape}"
        )
    t_ns = nominal_stamps(n, fs)
    imu_ok = np.isfinite(gyro).all(1) & np.isfinite(acc).all(1)
    if not imu_ok.all():
        raise InvalidInputError(f"{path}: IMU row {int(np.flatnonzero(~imu_ok)[0])} is not finite")
    gt_ok = np.isfinite(q).all(1) & np.isfinite(p).all(1)
    gt = GroundTruth(
        t_ns=t_ns[gt_ok].copy(),
        p=np.ascontiguousarray(p[gt_ok]),
        q_wxyz=np.ascontiguousarray(q[gt_ok]),
        v=None,
    )
    return ImuData(t_ns=t_ns, gyro=gyro, acc=acc), gt


def _rate(path: Path, m: dict) -> float:
    fs = float(np.asarray(m["sampling_rate"]).ravel()[0])
    if not (np.isfinite(fs) and fs > 0):
        raise InvalidInputError(f"{path}: sampling_rate {fs} is not a positive number")
    return fs


def nominal_stamps(n: int, fs: float) -> np.ndarray:
    """Integer-ns stamps of ``n`` samples at the trial's nominal rate ``fs``: rounding each stamp (not
    accumulating dt) keeps them within 0.5 ns of i / fs (the trial stores no stamps, only its rate)."""
    return np.round(np.arange(n, dtype=np.float64) * (1e9 / fs)).astype(np.int64)


def read_imu_source(path: Path) -> ImuSource:
    """The IMU of a trial (only ``imu_gyr`` / ``imu_acc`` are needed) with the stamps of its nominal
    ``sampling_rate`` (:func:`nominal_stamps`, as :func:`read_recording` reads them), or none where the
    file holds no rate."""
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    m = _load_mat(path, IMU_VARIABLES)
    gyro = np.ascontiguousarray(m["imu_gyr"], dtype=np.float64)
    acc = np.ascontiguousarray(m["imu_acc"], dtype=np.float64)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or acc.shape != gyro.shape:
        raise InvalidInputError(f"{path}: imu_gyr {gyro.shape} and imu_acc {acc.shape} must both be (N, 3)")
    t_ns = nominal_stamps(len(gyro), _rate(path, m)) if "sampling_rate" in m else None
    return ImuSource(NAME, path, path.parent, Path(path.name), t_ns, gyro, acc)


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray) -> None:
    """``out``: every variable of ``src``'s trial with ``imu_gyr`` / ``imu_acc`` replaced (each
    keeps its dtype)."""
    import scipy.io

    m = _load_mat(src.imu_file, IMU_VARIABLES)
    data = {k: v for k, v in m.items() if not k.startswith("__")}
    data["imu_gyr"] = gyro.astype(m["imu_gyr"].dtype)
    data["imu_acc"] = acc.astype(m["imu_acc"].dtype)
    atomic_write_bytes(out, lambda fh: scipy.io.savemat(fh, data))
