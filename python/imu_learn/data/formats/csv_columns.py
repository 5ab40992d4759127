"""A user's own IMU CSV: the file's column order, the time, gyro and accelerometer units given by
the caller (``--columns t,gx,gy,gz,ax,ay,az --time-unit s --gyro-unit deg/s --acc-unit g``), read
and written back in the Rust core (``crates/imu_core/src/io/columns.rs``).

* ``columns``: the file's column order, each of ``t, gx, gy, gz, ax, ay, az`` once, ``_`` for a
  column to skip; columns after the last one named are ignored.
* ``time_unit``: ``s | ms | us | ns``; integer or float text, read from its decimal digits exactly
  (no detour through float64) and rounded to the nearest ns.
* ``gyro_unit``: ``rad/s | deg/s``; ``acc_unit``: ``m/s2 | g`` (standard gravity, 9.80665 m/s^2).
* Found in the file: the delimiter (``;``, ``,``, tab or whitespace, from the first line that is
  not a comment), a header (that line when none of its named fields is a number), ``#`` comments.

Errors (:mod:`imu_learn.errors`) name path, line, column and field (``wx_dps (gx)``): a line
shorter than the map is a ColumnCountError, a bad value NotNumericError / NonFiniteError, time that
does not strictly increase a TimestampError, fewer than two samples TooFewRowsError; an unknown
unit or a malformed column map is an InvalidInputError.

The writer keeps the user's format: the original file with only the six IMU fields replaced, in
the file's units; header, comments, time and every other column keep their text.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.data.types import ImuData
from imu_learn.errors import InvalidInputError
from imu_learn.util.atomic import atomic_write_path

from .source import DEFAULT_COLUMNS, CsvColumns, ImuSource  # noqa: F401  (the layout type lives with ImuSource)

NAME = "csv-columns"
TIME_UNITS = ("s", "ms", "us", "ns")
GYRO_UNITS = ("rad/s", "deg/s")
ACC_UNITS = ("m/s2", "g")
STANDARD_GRAVITY = 9.80665


def read_csv_columns(
    path: Path,
    columns: str = DEFAULT_COLUMNS,
    time_unit: str = "ns",
    gyro_unit: str = "rad/s",
    acc_unit: str = "m/s2",
) -> ImuData:
    """The samples of a user's CSV: ``t_ns`` int64, gyro [rad/s], acc [m/s^2]."""
    t_ns, gyro, acc = core.read_csv_columns(str(path), columns, time_unit, gyro_unit, acc_unit)
    return ImuData(t_ns=t_ns, gyro=gyro, acc=acc)


def write_csv_columns(
    original: Path,
    out: Path,
    gyro: np.ndarray,
    acc: np.ndarray,
    columns: str = DEFAULT_COLUMNS,
    time_unit: str = "ns",
    gyro_unit: str = "rad/s",
    acc_unit: str = "m/s2",
) -> None:
    """Write ``out``: ``original`` with its gyro and acc replaced by ``gyro`` [rad/s] and ``acc``
    [m/s^2] (one row per sample :func:`read_csv_columns` returns), in the file's own units. Atomic."""
    g = np.ascontiguousarray(gyro, dtype=np.float64)
    a = np.ascontiguousarray(acc, dtype=np.float64)
    atomic_write_path(
        out, lambda tmp: core.write_csv_columns(str(original), str(tmp), g, a, columns, time_unit, gyro_unit, acc_unit)
    )


def read_imu_source(path: Path, layout: CsvColumns) -> ImuSource:
    """A user's CSV as refine takes it: the file stands alone (its folder is the recording's); the
    source carries ``layout``, so :func:`write_imu` writes the user's columns and units back."""
    path = Path(path)
    if path.is_dir():
        raise InvalidInputError(f"{path}: a folder; a user's CSV (--columns) is one file")
    imu = read_csv_columns(path, *layout.args())
    return ImuSource(NAME, path, path.parent, Path(path.name), imu.t_ns, imu.gyro, imu.acc, layout=layout)


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray,
              layout: Optional[CsvColumns] = None) -> None:
    """``out``: ``src``'s CSV with gyro and acc replaced, in its own columns and units (``layout``:
    the source's own when None)."""
    layout = layout or src.layout or CsvColumns()
    write_csv_columns(src.imu_file, out, gyro, acc, *layout.args())
