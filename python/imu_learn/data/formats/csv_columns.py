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

``skip_bad_lines`` (``--skip-bad-lines``): a line too short for the map or with a field that is
not a finite number (a logger's truncated first or last line) is skipped instead, counted in a
warning and on the source (``ImuSource.skipped_lines``); the writer keeps such lines as they are.

:func:`read_imu_source`, the one read every command's user CSV goes through, then checks that the
numbers fit the map and units (:mod:`imu_learn.data.formats.input_checks`: a sample rate no IMU has, gravity
of 1 m/s^2, a gyro reading gravity, ...) and stops with an ImplausibleInputError naming the option
that fixes the mistake.

The writer keeps the user's format: the original file with only the six IMU fields replaced, in
the file's units; header, comments, time and every other column keep their text.
"""
from __future__ import annotations

import logging
import re
from pathlib import Path
from typing import Optional, Tuple

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.data.formats.input_checks import check_user_imu, explain_repeated_stamps, explain_time_overflow
from imu_learn.data.types import ImuData
from imu_learn.errors import ColumnCountError, InvalidInputError, NotNumericError, TimestampError
from imu_learn.util.atomic import atomic_write_path

from .source import DEFAULT_COLUMNS, CsvColumns, ImuSource  # noqa: F401  (the layout type lives with ImuSource)

logger = logging.getLogger(__name__)

NAME = "csv-columns"
# How many of the skipped lines a warning quotes.
SKIPPED_QUOTED = 3
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
    skip_bad_lines: bool = False,
) -> None:
    """Write ``out``: ``original`` with its gyro and acc replaced by ``gyro`` [rad/s] and ``acc``
    [m/s^2] (one row per sample :func:`read_csv_columns` returns), in the file's own units; with
    ``skip_bad_lines`` the lines the reader skips are kept as they are. Atomic."""
    g = np.ascontiguousarray(gyro, dtype=np.float64)
    a = np.ascontiguousarray(acc, dtype=np.float64)
    atomic_write_path(
        out, lambda tmp: core.write_csv_columns(str(original), str(tmp), g, a, columns, time_unit, gyro_unit, acc_unit,
                                                skip_bad_lines=skip_bad_lines)
    )


def data_line_ends(path: Path) -> Tuple[int, int]:
    """The 1-based numbers of a text file's first line that starts with a number (not blank, a ``#``
    comment or a header) and of its last non-blank line (0: none)."""
    first = last = 0
    with open(path, "rb") as fh:
        for i, line in enumerate(fh, 1):
            text = line.strip()
            if text:
                last = i
                if not first and text[:1] in b"0123456789+-.":
                    first = i
    return first, last


DECIMAL_COMMA = re.compile(r'= "[-+]?\d+,\d+" is not a number')  # 0,123: a locale's decimal comma


def read_checked(path: Path, layout: CsvColumns) -> Tuple[ImuData, Tuple[int, ...]]:
    """The samples of a user's CSV read with ``layout``, checked (:mod:`imu_learn.data.formats.input_checks`)
    before anything is done with them, and the 1-based lines skipped (``layout.skip_bad_lines``)."""
    try:
        r = core.read_csv_columns_checked(str(path), *layout.args(), skip_bad_lines=layout.skip_bad_lines)
    except NotNumericError as e:
        better = explain_time_overflow(Path(path), e, layout)
        if better is None:
            if DECIMAL_COMMA.search(str(e)):
                e.add_note("a decimal comma? the reader takes decimal points: export the file with '.' as the "
                           "decimal separator (and ',' or ';' between fields)")
            raise
        raise better from e
    except TimestampError as e:
        better = explain_repeated_stamps(Path(path), e, layout)
        if better is None:
            raise
        raise better from e
    except ColumnCountError as e:
        if e.line is not None:
            first, last = data_line_ends(Path(path))
            if e.line in (first, last):
                where = "last line, cut by the logger" if e.line == last else "first line, cut where the logger started"
                e.add_note(f"the {where}? --skip-bad-lines leaves such lines out (counted)")
        raise
    skipped = tuple(int(line) for line, _ in r["skipped"])
    if skipped:
        quoted = "; ".join(problem for _, problem in r["skipped"][:SKIPPED_QUOTED])
        more = f"; and {len(skipped) - SKIPPED_QUOTED} more" if len(skipped) > SKIPPED_QUOTED else ""
        logger.warning("%s: skipped %d bad line%s (--skip-bad-lines): %s%s", path, len(skipped),
                       "" if len(skipped) == 1 else "s", quoted, more)
    imu = ImuData(t_ns=r["t_ns"], gyro=r["gyro"], acc=r["acc"])
    check_user_imu(Path(path), imu.t_ns, imu.gyro, imu.acc, layout, names=r["names"], fields=r["fields"])
    return imu, skipped


def read_imu_source(path: Path, layout: CsvColumns) -> ImuSource:
    """A user's CSV as refine takes it: the file stands alone (its folder is the recording's); the
    source carries ``layout``, so :func:`write_imu` writes the user's columns and units back, and the
    lines skipped. The samples are checked first (:func:`read_checked`)."""
    path = Path(path)
    if path.is_dir():
        imu = next(iter(sorted(path.glob("*/imu0/data.csv")) + sorted(path.glob("imu0/data.csv"))), None)
        raise InvalidInputError(f"{path}: a folder; the options of a user's own CSV (--columns, --time-unit, --gyro-unit, "
                                "--acc-unit, --skip-bad-lines) read one file: give its IMU file as --input"
                                + (f" ({imu})" if imu is not None else ""))
    imu, skipped = read_checked(path, layout)
    return ImuSource(NAME, path, path.parent, Path(path.name), imu.t_ns, imu.gyro, imu.acc, layout=layout,
                     skipped_lines=skipped)


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray,
              layout: Optional[CsvColumns] = None) -> None:
    """``out``: ``src``'s CSV with gyro and acc replaced, in its own columns and units (``layout``:
    the source's own when None)."""
    layout = layout or src.layout or CsvColumns()
    write_csv_columns(src.imu_file, out, gyro, acc, *layout.args(), skip_bad_lines=layout.skip_bad_lines)
