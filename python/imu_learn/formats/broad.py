"""BROAD benchmark trials (``.mat``): ``imu_gyr`` [rad/s], ``imu_acc`` [m/s^2], ``opt_quat``
(w,x,y,z, IMU -> ENU world, NaN where the optical system lost the body), ``opt_pos`` [m] and
``sampling_rate`` [Hz]; no timestamps, so sample i is at i / sampling_rate.

Rows whose optical ground truth is NaN are removed from the ground truth; the Rust alignment then
sees them as gaps and splits the recording into segments there.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Tuple

import numpy as np

from imu_learn.errors import InvalidInputError
from imu_learn.types import GroundTruth, ImuData


def read_recording(
    path: Path, groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
) -> Tuple[ImuData, GroundTruth]:
    import scipy.io

    path = Path(path)
    if groundtruth is not None:
        raise InvalidInputError("BROAD trials carry their own ground truth; groundtruth= is not used")
    m = scipy.io.loadmat(str(path))
    missing = [k for k in ("imu_gyr", "imu_acc", "opt_quat", "opt_pos", "sampling_rate") if k not in m]
    if missing:
        raise InvalidInputError(f"{path}: missing variable(s) {missing}")
    fs = float(np.asarray(m["sampling_rate"]).ravel()[0])
    if not (np.isfinite(fs) and fs > 0):
        raise InvalidInputError(f"{path}: sampling_rate {fs} is not a positive number")
    gyro = np.ascontiguousarray(m["imu_gyr"], dtype=np.float64)
    acc = np.ascontiguousarray(m["imu_acc"], dtype=np.float64)
    q = np.asarray(m["opt_quat"], dtype=np.float64)
    p = np.asarray(m["opt_pos"], dtype=np.float64)
    n = len(gyro)
    if not (acc.shape == gyro.shape == (n, 3) and q.shape == (n, 4) and p.shape == (n, 3)):
        raise InvalidInputError(
            f"{path}: array shapes disagree: gyr {gyro.shape} acc {acc.shape} quat {q.shape} pos {p.shape}"
        )
    # Integer-ns stamps from the nominal rate; rounding each stamp (not accumulating dt) keeps
    # them within 0.5 ns of i / fs.
    t_ns = np.round(np.arange(n, dtype=np.float64) * (1e9 / fs)).astype(np.int64)
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
