"""IMU logs recorded beside a GNSS receiver with RTKLIB (rtklibexplorer/GNSS_IMU's car and walk
recordings): a CSV written by the IMU's own firmware and RTKLIB's time-tag file beside it.

``imu_*.csv``: no header, one sample a line, ``ax, ay, az [g], gx, gy, gz [deg/s], t [ms since the
IMU's power-up]``. The log was started and stopped while the IMU was streaming, so its first and
last lines may be cut anywhere. A cut can leave a line that still parses (``0.119`` from
``-0.119``), so the first line is never trusted (dropped and counted, as that project's converter
does, unless ``trust_first_line``); the last one is dropped when it does not end in a newline or
does not parse as a full row. Any other malformed line is an error naming file, line and field.

``imu_*.csv.tag`` (little-endian), RTKLIB's stream time tag: a 60-byte text header
(``TIMETAG RTKLIB <version>``), ``uint32 tick_f`` (RTKLIB's millisecond tick when the file was
opened), ``uint32`` start time [s since 1970-01-01, on the GPS time scale, no leap seconds], a
``float64`` fraction of a second, then 8-byte records ``(uint32 ms since the start, uint32 file
offset)``, one per chunk RTKLIB wrote. The last record's ms is the log's end. As that project's
converter does, the IMU counter of the first kept sample is mapped onto the start and the last
kept sample's onto the end, linearly in between (the counter's clock scaled to RTKLIB's; the scale
is logged and refused when it is off 1 by more than ``MAX_CLOCK_SCALE_ERROR``).

Stamps come out as int64 ns of GPS time written as seconds since 1970 without leap seconds: the
scale of the RTKLIB ``.pos`` files read by :mod:`imu_learn.fuse.aiding.rtklib` ("GPST" date and time).
"""
from __future__ import annotations

import logging
import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.data.types import GroundTruth, ImuData, sample_rate_hz
from imu_learn.errors import (
    ColumnCountError,
    HeaderError,
    InvalidInputError,
    NonFiniteError,
    NotNumericError,
    TimestampError,
    TooFewRowsError,
)
from imu_learn.util.atomic import atomic_write_bytes, atomic_write_text

from .fields import number
from .groundtruth import read_groundtruth
from .source import ImuSource

log = logging.getLogger(__name__)

NAME = "gnss-imu"
FIELDS = ("ax", "ay", "az", "gx", "gy", "gz", "t_ms")
STANDARD_GRAVITY = 9.80665  # m/s^2 per g, the unit the accelerometer logs in
TAG_HEADER_LEN = 60
TAG_MAGIC = b"TIMETAG"
MAX_CLOCK_SCALE_ERROR = 0.01


@dataclass(frozen=True)
class TimeTag:
    """An RTKLIB time-tag file: ``start_ns`` [ns, GPST since 1970], ``end_ms`` (the last record's
    ms since the start), ``n_records``, ``tick_f`` and the header text ``version``."""

    path: str
    version: str
    tick_f: int
    start_ns: int
    end_ms: int
    n_records: int

    @property
    def end_ns(self) -> int:
        return self.start_ns + self.end_ms * 1_000_000


@dataclass(frozen=True)
class GnssImuLog:
    """What :func:`read_imu_log` returns: ``imu`` (stamps [ns, GPST], gyro [rad/s], acc [m/s^2]);
    ``counter_ms`` (N,) the IMU's own stamps as logged; ``clock_scale`` the seconds of the tag's
    clock per second of the IMU counter; ``skipped_lines`` the 1-based numbers of the cut
    first/last lines left out."""

    imu: ImuData
    counter_ms: np.ndarray
    clock_scale: float
    skipped_lines: Tuple[int, ...]
    path: str
    tag: TimeTag

    @property
    def rate_hz(self) -> float:
        """The median sample rate on the GPS time scale."""
        return sample_rate_hz(self.imu.t_ns)


def read_tag(path: Path) -> TimeTag:
    """Parse an RTKLIB ``.tag`` file (layout in the module docstring). A file shorter than its
    header, a header not starting with ``TIMETAG``, a fraction outside [0, 1) or no record are
    :class:`HeaderError` / :class:`TooFewRowsError` naming the file (``line`` = byte offset + 1)."""
    p = str(path)
    data = Path(path).read_bytes()
    fixed = TAG_HEADER_LEN + 16
    if len(data) < fixed:
        raise HeaderError(f"{p}: {len(data)} bytes; an RTKLIB time tag has a {fixed}-byte header", p, 1, None,
                          "header")
    if not data.startswith(TAG_MAGIC):
        raise HeaderError(f"{p}: header {data[:20]!r} does not start with {TAG_MAGIC!r} (not an RTKLIB time tag)",
                          p, 1, None, "header")
    version = data[:TAG_HEADER_LEN].split(b"\0", 1)[0].decode("ascii", "replace").strip()
    tick_f, start_s = struct.unpack_from("<II", data, TAG_HEADER_LEN)
    (frac,) = struct.unpack_from("<d", data, TAG_HEADER_LEN + 8)
    if not (math.isfinite(frac) and 0.0 <= frac < 1.0):
        raise HeaderError(f"{p}: byte {TAG_HEADER_LEN + 8}: fraction of a second {frac!r} is not in [0, 1)", p,
                          TAG_HEADER_LEN + 9, None, "time_sec")
    n = (len(data) - fixed) // 8
    if n == 0:
        raise TooFewRowsError(f"{p}: no time-tag record after the header (the log's end is unknown)", p, 0)
    if (len(data) - fixed) % 8:
        log.info("%s: %d trailing bytes after the last full record ignored", p, (len(data) - fixed) % 8)
    (end_ms,) = struct.unpack_from("<I", data, fixed + 8 * (n - 1))
    start_ns = start_s * 1_000_000_000 + int(round(frac * 1e9))
    return TimeTag(p, version, int(tick_f), int(start_ns), int(end_ms), int(n))


def _parse_row(fields: Sequence[str], p: str, lineno: int) -> Tuple[float, ...]:
    if len(fields) != len(FIELDS):
        raise ColumnCountError(f"{p}:{lineno}: expected {len(FIELDS)} columns ({', '.join(FIELDS)}), found "
                               f"{len(fields)}", p, lineno, None, None)
    return tuple(number(text, p, lineno, c + 1, name) for c, (text, name) in enumerate(zip(fields, FIELDS)))


def read_csv(path: Path, trust_first_line: bool = False) -> Tuple[np.ndarray, np.ndarray, Tuple[int, ...]]:
    """``(rows (N, 7) float64 in the file's units, line numbers (N,), skipped line numbers)`` of an
    IMU CSV, strictly (module docstring: the cut first/last lines). Blank lines are errors; the IMU
    counter must increase strictly (:class:`TimestampError` naming line and field ``t_ms``)."""
    p = str(path)
    with open(path, "rb") as fh:
        raw = fh.read()
    text = raw.decode("utf-8", errors="replace")
    ends_with_newline = text.endswith("\n")
    lines = text.splitlines()
    skipped = []
    first = 0
    if lines and not trust_first_line:
        skipped.append(1)
        first = 1
    last = len(lines)
    if last > first:
        cut = not ends_with_newline
        if not cut:
            try:
                _parse_row(lines[-1].split(","), p, last)
            except (ColumnCountError, NotNumericError, NonFiniteError):
                cut = True
        if cut:
            skipped.append(last)
            last -= 1
    rows = np.empty((max(last - first, 0), len(FIELDS)), dtype=np.float64)
    for i in range(first, last):
        rows[i - first] = _parse_row(lines[i].split(","), p, i + 1)
    linenos = np.arange(first + 1, last + 1)
    if len(rows) < 2:
        raise TooFewRowsError(f"{p}: {len(rows)} complete IMU row(s) (after leaving out the cut first/last lines "
                              f"{skipped}); at least 2 are needed", p, len(lines))
    d = np.diff(rows[:, 6])
    bad = np.flatnonzero(d <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        what = "repeats" if d[i - 1] == 0 else "precedes"
        raise TimestampError(f"{p}:{linenos[i]}: column 7 (t_ms): {rows[i, 6]:g} ms {what} the previous line's "
                             f"{rows[i - 1, 6]:g} ms (the IMU counter must increase)", p, int(linenos[i]), 7, "t_ms")
    if skipped:
        log.info("%s: left out %d possibly cut line(s) %s", p, len(skipped), skipped)
    return rows, linenos, tuple(skipped)


def mounting_rotation(rpy_deg: Sequence[float]) -> np.ndarray:
    """The matrix taking IMU-frame vectors into the body frame for the IMU's orientation given as
    roll, pitch, yaw [deg] of the body frame relative to the IMU frame (the coordinate-transformation
    convention of Groves' textbook and rtklibexplorer/GNSS_IMU's ``imu_misalign``): the passive
    rotations about x by roll, y by pitch, z by yaw, i.e. ``(Rz(yaw) Ry(pitch) Rx(roll))^T``."""
    from scipy.spatial.transform import Rotation

    r = np.asarray(rpy_deg, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(r)):
        raise InvalidInputError(f"mounting angles must be finite, got {r.tolist()}")
    return Rotation.from_euler("ZYX", r[::-1], degrees=True).as_matrix().T


def read_imu_log(
    path: Path,
    tag: Optional[Path] = None,
    mounting: Optional[np.ndarray] = None,
    delay_s: float = 0.0,
    g: float = STANDARD_GRAVITY,
    trust_first_line: bool = False,
) -> GnssImuLog:
    """An IMU CSV and its time tag (``tag``, default ``<path>.tag``) as stamps [ns, GPST], gyro
    [rad/s] and acc [m/s^2]. ``mounting`` (3, 3): applied to both (body = mounting @ imu; e.g.
    :func:`mounting_rotation`); ``delay_s``: added to every stamp (rtklibexplorer's ``imu_t_off``:
    -0.125 s on the drive); ``g``: m/s^2 per logged g."""
    path = Path(path)
    tag_path = Path(tag) if tag is not None else path.with_name(path.name + ".tag")
    tt = read_tag(tag_path)
    rows, _lines, skipped = read_csv(path, trust_first_line)
    counter = rows[:, 6]
    span_ms = counter[-1] - counter[0]
    if tt.end_ms <= 0:
        raise HeaderError(f"{tt.path}: the last record's ms is {tt.end_ms}: the log has no length", tt.path, None,
                          None, "tick")
    scale = tt.end_ms / span_ms
    if abs(scale - 1.0) > MAX_CLOCK_SCALE_ERROR:
        raise InvalidInputError(f"{path}: the IMU counter spans {span_ms / 1e3:.3f} s but the time tag {tt.path} "
                                f"{tt.end_ms / 1e3:.3f} s (scale {scale:.5f}): is it this log's tag?")
    log.info("%s: %d samples, counter %.3f s mapped onto the tag's %.3f s (scale %.6f)", path, len(rows),
             span_ms / 1e3, tt.end_ms / 1e3, scale)
    rel_ns = np.rint((counter - counter[0]) * scale * 1e6).astype(np.int64)
    t_ns = tt.start_ns + rel_ns + int(round(delay_s * 1e9))
    acc = rows[:, 0:3] * g
    gyro = np.deg2rad(rows[:, 3:6])
    if mounting is not None:
        M = np.asarray(mounting, dtype=np.float64)
        if M.shape != (3, 3) or not np.allclose(M @ M.T, np.eye(3), atol=1e-9) or np.linalg.det(M) < 0:
            raise InvalidInputError(f"mounting must be a (3, 3) rotation matrix, got {M.tolist()}")
        acc, gyro = acc @ M.T, gyro @ M.T
    imu = ImuData(t_ns=t_ns, gyro=np.ascontiguousarray(gyro), acc=np.ascontiguousarray(acc))
    return GnssImuLog(imu, counter.astype(np.int64), float(scale), skipped, str(path), tt)


# --------------------------------------------------------------------------------------------
# The layout (imu_learn.data.formats): ``--format gnss-imu``, or detected by the CSV + tag pair
# --------------------------------------------------------------------------------------------


def tag_path(path: Path) -> Path:
    """The time tag of an IMU CSV: ``<name>.csv.tag`` beside it."""
    path = Path(path)
    return path.with_name(path.name + ".tag")


def _tagged(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() == ".csv" and tag_path(path).is_file()


def detect(path: Path) -> bool:
    """An IMU ``.csv`` file with its RTKLIB time tag ``<name>.csv.tag`` beside it, or a folder holding
    exactly one such log (a folder of several names none: the log is then given by its file)."""
    path = Path(path)
    return _tagged(path) or (path.is_dir() and sum(1 for p in path.glob("*.csv") if _tagged(p)) == 1)


def find_recordings(root: Path) -> List[Path]:
    """Every IMU CSV with its time tag under ``root``."""
    return sorted(p for p in Path(root).rglob("*.csv") if _tagged(p))


def _imu_file(path: Path) -> Path:
    path = Path(path)
    if path.is_dir():
        found = find_recordings(path)
        if len(found) != 1:
            raise InvalidInputError(f"{path}: {len(found)} IMU logs with a .tag beside them in this folder; name the "
                                    "IMU .csv itself")
        return found[0]
    if not path.is_file():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    return path


def read_recording(path: Path, groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
                   ) -> Tuple[ImuData, GroundTruth]:
    """The layout's common signature. These logs carry no ground-truth pose (the RTK fixes are
    position aiding: :mod:`imu_learn.fuse.aiding.rtklib`), so a ground truth must be given explicitly."""
    f = _imu_file(path)
    if groundtruth is None:
        pos = sorted(f.parent.glob("*.pos"))
        hint = (f"; its RTKLIB fixes beside it are a positions reference: --groundtruth {pos[0]}" if pos
                else " (TUM or ASL poses, or an RTKLIB .pos of positions)")
        raise InvalidInputError(f"{f}: a {NAME} log has no ground-truth pose; pass one with --groundtruth{hint}")
    return read_imu_log(f, tag_path(f)).imu, read_groundtruth(Path(groundtruth))


def read_imu_source(path: Path) -> ImuSource:
    """The IMU in SI units on the GPS time scale (no mounting rotation, no delay: the navigator's
    ``--imu-rotation-rpy-deg`` / ``--imu-delay-s`` apply those)."""
    f = _imu_file(path)
    lg = read_imu_log(f, tag_path(f))
    return ImuSource(NAME, f, f.parent, Path(f.name), lg.imu.t_ns, lg.imu.gyro, lg.imu.acc)


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray, g: float = STANDARD_GRAVITY) -> None:
    """``out``: ``src``'s CSV with gyro and acc replaced (back in g and deg/s), the IMU counter and
    the cut first/last lines kept as they were, and its time tag copied beside it (both atomically)."""
    rows, _lines, skipped = read_csv(src.imu_file)
    g_dps = np.rad2deg(np.asarray(gyro, dtype=np.float64))
    a_g = np.asarray(acc, dtype=np.float64) / g
    if len(rows) != len(g_dps) or len(rows) != len(a_g):
        raise InvalidInputError(f"{src.imu_file}: {len(rows)} rows, but {len(g_dps)} gyro / {len(a_g)} acc samples "
                                "to write")
    with open(src.imu_file, "rb") as fh:
        original = fh.read().decode("utf-8", errors="replace").splitlines(keepends=True)
    head = [original[0]] if 1 in skipped else []
    tail = [original[-1]] if len(original) in skipped and len(original) > 1 else []
    body = [",".join(f"{x:.9f}" for x in np.r_[a_g[i], g_dps[i]]) + f",{int(rows[i, 6])}\n" for i in range(len(rows))]
    atomic_write_text(Path(out), "".join(head + body + tail))
    tag = tag_path(src.imu_file)
    atomic_write_bytes(tag_path(Path(out)), lambda fh: fh.write(tag.read_bytes()))
