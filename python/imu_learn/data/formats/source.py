"""What a layout hands to ``imu_learn.refine``: the recording's IMU and where it lives on disk."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Tuple

import numpy as np

DEFAULT_COLUMNS = "t,gx,gy,gz,ax,ay,az"


@dataclass(frozen=True)
class CsvColumns:
    """How a user's CSV is laid out (the CLI's --columns / --time-unit / --gyro-unit / --acc-unit /
    --skip-bad-lines). ``columns_named``: whether the caller named the columns (False: the default
    map assumed, and a file with more columns than it names is refused). ``skip_bad_lines``: a line
    too short for the map or with a field that is not a finite number is skipped (and counted)
    instead of failing the read."""

    columns: str = DEFAULT_COLUMNS
    time_unit: str = "ns"
    gyro_unit: str = "rad/s"
    acc_unit: str = "m/s2"
    columns_named: bool = True
    skip_bad_lines: bool = False

    def args(self) -> tuple:
        return (self.columns, self.time_unit, self.gyro_unit, self.acc_unit)


@dataclass(frozen=True)
class ImuSource:
    """One recording's IMU as read by its layout's ``read_imu_source``.

    ``imu_file`` is also the template of a refined copy: the layout's ``write_imu`` writes it again
    with only gyro and acc replaced, so everything else in the file is kept as it is.
    """

    fmt: str  # the layout's name (asl, blackbird, broad, kaist, ..., csv-columns): the module that writes it back
    imu_file: Path  # the file that holds the IMU
    root: Path  # the recording's folder (what refine's --copy-folder copies)
    rel: Path  # imu_file relative to root (where the IMU goes under an output folder)
    t_ns: Optional[np.ndarray]  # the file's own stamps; None where it has none (BROAD)
    gyro: np.ndarray  # (N, 3) float64 [rad/s]
    acc: np.ndarray  # (N, 3) float64 [m/s^2]
    topic: Optional[str] = None  # the bag topic the IMU was read from (ROS bags only)
    layout: Optional[CsvColumns] = None  # a user's CSV: its columns and units (written back in them)
    skipped_lines: Tuple[int, ...] = ()  # a user's CSV read with skip_bad_lines: the 1-based lines skipped
