"""Apply a trained refiner to a recording and write the refined IMU in the input's own format.

    imu-learn refine --checkpoint CKPT --input IN --out OUT
        [--format auto|asl|euroc|tum-vi|blackbird|broad|kaist|rosbag] [--imu-topic TOPIC]
        [--window W --overlap O] [--device auto|cpu|cuda] [--batch 16] [--copy-folder]
        [--fill-covariance] [--quiet]

Only the IMU is read (no ground truth needed); timestamps and everything but gyro/acc are kept:

- ASL (EuRoC, TUM-VI): IN is a sequence folder, its ``mav0`` or an IMU ``.csv``. OUT is a folder
  (``OUT/mav0/imu0/data.csv`` is written) or a ``.csv`` path. The ORIGINAL header line and the
  original integer-ns stamps are kept; values are written with the shortest text that reads back
  to the same float64. ``--copy-folder`` first copies the whole input sequence folder to OUT.
- KAIST: IN is the folder holding ``sensor_data/xsens_imu.csv`` (or that file). Same 17 columns,
  only gyro (cols 8-10) and acc (cols 11-13, 0-based) replaced; OUT is a folder
  (``OUT/sensor_data/xsens_imu.csv``) or a ``.csv`` path.
- Blackbird: IN is the folder holding ``data.hdf5`` (or that file). OUT gets a copy of the file
  with ``gyro_raw`` / ``accel_raw`` replaced (datasets keep their dtype, chunking, attributes).
- BROAD: IN is a ``.mat`` trial. OUT (a ``.mat`` path, or a folder that gets the input's name)
  gets every variable of the input with ``imu_gyr`` / ``imu_acc`` replaced.
- ROS bags: IN is a ROS 1 ``.bag`` or a ROS 2 bag folder (sqlite3 or mcap); ``--imu-topic`` names
  the sensor_msgs/msg/Imu topic (not needed when the bag has one). OUT is a new bag of the same kind
  (ROS 2 keeps its storage plugin and compression) in which only that topic's angular_velocity and
  linear_acceleration change; every other message, connection and stamp, and the IMU messages'
  headers and covariance fields, are copied unchanged. A ROS 2 OUT folder that exists is refused
  (a folder cannot be replaced in one step); ``--copy-folder`` does not apply.
  ``--fill-covariance`` (a checkpoint with a covariance head) also writes each IMU message's
  angular_velocity_covariance and linear_acceleration_covariance: the diagonal 3x3 (row-major,
  off-diagonals 0) of that sample's predicted discrete-time variances, (rad/s)^2 and (m/s^2)^2
  (:func:`refine_with_variance`); orientation_covariance is kept.

Each layout's module in :mod:`imu_learn.data.formats` reads and writes it; every file is written to a
temporary file beside its target and renamed into place (:mod:`imu_learn.util.atomic`). The input is
never written: an OUT that resolves to the input file (or, with ``--copy-folder``, the input
folder) is refused. Errors print one line and exit with status 2.

Windowing: :mod:`imu_learn.infer.windowing`, the one rule every path applies a checkpoint with
(by default the checkpoint's training window, half overlap; causal models with carried state).
``--window``/``--overlap`` override it.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Optional, Tuple

import numpy as np

from imu_learn.data import formats
from imu_learn.data.formats import ImuSource
from imu_learn.errors import InvalidInputError
from imu_learn.infer.windowing import Windowing, apply, windowing_of
from imu_learn.nn.model import ImuRefiner

FORMATS = ("auto", *formats.FORMATS)


# --------------------------------------------------------------------------------------------
# Windowing and the model: imu_learn.infer.windowing (the one rule)
# --------------------------------------------------------------------------------------------


def _rule(model: ImuRefiner, window: Optional[int], overlap: Optional[int], batch: Optional[int]) -> Windowing:
    """The model's rule (:func:`windowing_of`) with the caller's overrides (None: the rule's)."""
    return windowing_of(model).replace(window, overlap, batch)


def refine_arrays(
    model: ImuRefiner,
    gyro: np.ndarray,
    acc: np.ndarray,
    window: Optional[int] = None,
    overlap: Optional[int] = None,
    batch: Optional[int] = None,
    progress: bool = False,
) -> Tuple[np.ndarray, np.ndarray]:
    """Refine raw gyro [rad/s] and acc [m/s^2] (N, 3) with ``model`` -> (gyro, acc) float64 (N, 3),
    by :mod:`imu_learn.infer.windowing`'s rule (``window``/``overlap``/``batch`` None: the model's,
    i.e. its checkpoint's training window with half overlap)."""
    g, a, _ = apply(model, gyro, acc, _rule(model, window, overlap, batch), progress)
    return g, a


def refine_with_variance(
    model: ImuRefiner,
    gyro: np.ndarray,
    acc: np.ndarray,
    window: Optional[int] = None,
    overlap: Optional[int] = None,
    batch: Optional[int] = None,
    progress: bool = False,
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`refine_arrays` plus the covariance head's per-sample noise variances (N, 6) float64,
    gyro then acc, discrete-time ((rad/s)^2, (m/s^2)^2: the variance of one sample; a noise density
    is sigma * sqrt(dt), see :mod:`imu_learn.nn.covariance`)."""
    g, a, v = apply(model, gyro, acc, _rule(model, window, overlap, batch), progress, variance=True)
    assert v is not None
    return g, a, v


# --------------------------------------------------------------------------------------------
# Where the refined IMU goes (reading and writing each layout is imu_learn.data.formats' job)
# --------------------------------------------------------------------------------------------


def output_file(src: ImuSource, out: Path) -> Path:
    """The file to write for OUT: OUT itself when it names a file of the input's kind, else the
    input's relative path under the folder OUT."""
    if out.suffix.lower() == src.imu_file.suffix.lower() and not out.is_dir():
        return out
    return out / src.rel


def _same(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _inside(child: Path, parent: Path) -> bool:
    try:
        child.resolve().relative_to(parent.resolve())
        return True
    except ValueError:
        return False


def refine_recording(
    model: ImuRefiner,
    input: Path,
    output: Path,
    fmt: str = "auto",
    window: Optional[int] = None,
    overlap: Optional[int] = None,
    copy_folder: bool = False,
    batch: Optional[int] = None,
    progress: bool = False,
    imu_topic: Optional[str] = None,
    fill_covariance: bool = False,
) -> Path:
    """Refine one recording; returns the file (or ROS 2 bag folder) written. ``imu_topic``: the
    IMU topic of a ROS bag; ``fill_covariance``: a bag's IMU covariance fields get the model's
    per-sample variances (the model needs a covariance head)."""
    input, output = Path(input), Path(output)
    src = formats.read_imu_source(input, fmt, imu_topic)
    if fill_covariance and src.fmt != formats.rosbag.NAME:
        raise InvalidInputError(f"--fill-covariance writes the covariance fields of a ROS bag's IMU messages; "
                                f"{input} is {src.fmt}, not a bag")
    if copy_folder and src.fmt == formats.rosbag.NAME:
        raise InvalidInputError("--copy-folder does not apply to ROS bags: the output bag holds every topic already")
    if copy_folder:
        if output.suffix.lower() == src.imu_file.suffix.lower() and not output.is_dir():
            raise InvalidInputError(f"--copy-folder needs OUT to be a folder, got {output}")
        if _same(output, src.root) or _inside(output, src.root) or _inside(src.root, output):
            raise InvalidInputError(f"--copy-folder: OUT {output} and the input folder {src.root} overlap")
        if output.exists() and (not output.is_dir() or any(output.iterdir())):
            raise InvalidInputError(f"--copy-folder: {output} exists and is not an empty folder")
    target = output_file(src, output)
    if _same(target, src.imu_file) or _same(output, input):
        raise InvalidInputError(f"refusing to overwrite the input: OUT {output} is the input {input}")
    if fill_covariance:
        gyro, acc, var = refine_with_variance(model, src.gyro, src.acc, window, overlap, batch, progress)
        formats.rosbag.write_imu(src, target, gyro, acc, variances=var)
        return target
    gyro, acc = refine_arrays(model, src.gyro, src.acc, window, overlap, batch, progress)
    if copy_folder:
        shutil.copytree(src.root, output, dirs_exist_ok=True)
    formats.write_imu(src, target, gyro, acc)
    return target


def require_covariance_head(model: ImuRefiner, checkpoint: Path) -> None:
    """Before any input is read: ``--fill-covariance`` needs variances, which only a model with a
    covariance head predicts."""
    if getattr(model, "cov_head", None) is None:
        raise InvalidInputError(f"{checkpoint}: no covariance head (trained with model.covariance = false); "
                                f"--fill-covariance needs one, e.g. models/euroc_adis16448_cov.pt")
