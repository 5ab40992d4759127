"""Apply a trained refiner to a recording and write the refined IMU in the input's own format.

    imu-learn refine (--checkpoint CKPT | --profile PROFILE | both) --input IN --out OUT
        [--format auto|asl|euroc|tum-vi|blackbird|broad|kaist|fetch|gnss-imu|rosbag|csv-columns]
        [--columns MAP --time-unit U --gyro-unit U --acc-unit U] [--imu-topic TOPIC]
        [--window W --overlap O] [--device auto|cpu|cuda] [--batch 16] [--copy-folder]
        [--fill-covariance] [--force] [--imu-name NAME] [--quiet]

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

- A user's own CSV (``--columns`` and the units, :mod:`imu_learn.data.formats.csv_columns`): OUT
  is the same file with only the six IMU fields replaced, in the file's own columns and units.

A device profile's floor (``--profile``, or the one a checkpoint carries) runs before the model;
the recording's rate and device are checked against both first (:mod:`imu_learn.infer.rates`).
Where the output goes and what is refused: :mod:`imu_learn.infer.rewrite`.

Each layout's module in :mod:`imu_learn.data.formats` reads and writes it; every file is written to a
temporary file beside its target and renamed into place (:mod:`imu_learn.util.atomic`). The input is
never written: an OUT that resolves to the input file (or, with ``--copy-folder``, the input
folder) is refused. Errors print one line and exit with status 2.

Windowing: :mod:`imu_learn.infer.windowing`, the one rule every path applies a checkpoint with
(by default the checkpoint's training window, half overlap; causal models with carried state).
``--window``/``--overlap`` override it.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Tuple

import numpy as np

from imu_learn.data import formats
from imu_learn.errors import InvalidInputError
from imu_learn.infer.rewrite import Step, output_file, rewrite_recording
from imu_learn.infer.windowing import Windowing, apply, windowing_of
from imu_learn.nn.model import ImuRefiner

FORMATS = ("auto", *formats.FORMATS, formats.USER_CSV)
__all__ = ["FORMATS", "model_step", "output_file", "refine_arrays", "refine_recording", "refine_with_variance",
           "require_covariance_head"]


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
# A recording in its own format (where it goes and what is refused: imu_learn.infer.rewrite)
# --------------------------------------------------------------------------------------------


def model_step(model: ImuRefiner, window: Optional[int] = None, overlap: Optional[int] = None,
               batch: Optional[int] = None, progress: bool = False, variance: bool = False) -> Step:
    """The model as one step of :func:`imu_learn.infer.rewrite.rewrite_recording` (``variance``:
    with the covariance head's per-sample variances)."""

    def step(_t_ns: Optional[np.ndarray], gyro: np.ndarray, acc: np.ndarray):
        if variance:
            return refine_with_variance(model, gyro, acc, window, overlap, batch, progress)
        g, a = refine_arrays(model, gyro, acc, window, overlap, batch, progress)
        return g, a, None

    return step


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
    step = model_step(model, window, overlap, batch, progress, variance=fill_covariance)
    return rewrite_recording(src, input, output, [step], copy_folder, fill_covariance)


def require_covariance_head(model: ImuRefiner, checkpoint: Path) -> None:
    """Before any input is read: ``--fill-covariance`` needs variances, which only a model with a
    covariance head predicts."""
    if getattr(model, "cov_head", None) is None:
        raise InvalidInputError(f"{checkpoint}: no covariance head (trained with model.covariance = false); "
                                f"--fill-covariance needs one, e.g. models/euroc_adis16448_cov.pt")
