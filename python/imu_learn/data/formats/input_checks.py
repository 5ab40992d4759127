"""Plausibility checks of a user's own IMU CSV: the mistakes a column map and its units let pass.

A user's CSV (``--columns``, ``--time-unit``, ``--gyro-unit``, ``--acc-unit``) parses whenever its
fields are numbers, so a wrong unit or a wrong column order gives numbers that are wrong by a factor
of 1000, 57 or 9.8, or a gyro that reads gravity. :func:`check_user_imu` looks at the samples read
and stops with one :class:`~imu_learn.errors.ImplausibleInputError` naming the likely mistake and the
option that fixes it, or logs a warning where the data cannot decide. It is called by
:func:`imu_learn.data.formats.csv_columns.read_imu_source`, the one place every read of a user's CSV
goes through (``read_imu_source`` and ``read_recording`` with ``columns=``), before any work.

The checks, in order (each assumes the ones before it passed):

1. columns: with no ``--columns`` given (the default map assumed), a file with more columns than the
   map names is refused: the default map would read the first seven of them.
2. a constant column, or one of integers only, mapped onto a gyro or acc axis (a wrong map, a
   counter, raw counts).
3. the sample rate the stamps give in the stated ``--time-unit`` lies outside :data:`RATE_RANGE_HZ`;
   the unit that gives a rate inside it is named. A stamp too large for int64 ns in the stated unit
   (which the reader refuses as not a number) is explained the same way
   (:func:`explain_time_overflow`), as are decimal stamps that round to repeated ones in the stated
   unit (seconds read as ns; the reader refuses them as repeated: :func:`explain_repeated_stamps`).
   Steps of the stamps longer than :data:`GAP_PERIODS` periods (samples missing): a warning.
4. gyro and acc swapped: the gyro reads a gravity-like magnitude at rest and the acc does not.
5. ``|acc|`` at rest near 1 (g read as m/s^2) or near 96 (m/s^2 read as g); elsewhere far from
   gravity: a warning.
6. the gyro in deg/s read as rad/s (its 90th percentile above :data:`GYRO_P90_MAX_RAD_S`, or its rest
   noise above :data:`GYRO_REST_NOISE_MAX_RAD_S`); a large rest reading is only a warning, as is a
   gyro stated in deg/s that barely moves while the accelerometer does (rad/s read as deg/s).

Rest samples come from the package's still rule (:func:`imu_learn.core.still.still_stretches`):
gyro and acc quiet; where that finds none (a gyro in the wrong unit is too noisy for its caps), the
accelerometer alone quiet. With no rest at all the medians are over the whole file.
"""
from __future__ import annotations

import logging
import math
import re
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.core.stamps import median_period_ns
from imu_learn.core.still import still_stretches
from imu_learn.data.formats.source import DEFAULT_COLUMNS, CsvColumns
from imu_learn.errors import ImplausibleInputError, NotNumericError, TimestampError

logger = logging.getLogger(__name__)

STANDARD_GRAVITY = 9.80665  # m/s^2, 1 g
RAD_PER_DEG = math.pi / 180.0

# 1. A file with more fields than this and no --columns is refused (the default map names seven).
DEFAULT_MAP_WIDTH = len(DEFAULT_COLUMNS.split(","))

# 2. Statistics need a few samples: the column and motion checks skip files shorter than this.
MIN_SAMPLES = 20

# 3. The sample rates [Hz] an IMU logs at; the one a unit fix aims at (the nearest, in log scale).
RATE_RANGE_HZ = (1.0, 10_000.0)
TYPICAL_RATE_HZ = 200.0

# 4, 5. |acc| [m/s^2] at rest that reads as gravity; outside it the acc is far from gravity (a
# warning). A raw magnitude (the file's own numbers) reads as gravity in m/s^2 or in g within
# GRAVITY_RATIO of 9.81 or of 1.
# 4. swapped, where a unit would explain the acc columns' level: their |.|'s relative spread (MAD / median) above
# this, and the gyro columns' at most 1/ratio of it. Real recordings: acc 0.01-0.09, gyro 0.26-0.64 (EuRoC MH_04,
# TUM-VI room 2, Blackbird, Fetch): swapped, each reads as the other
SWAP_ACC_SPREAD, SWAP_SPREAD_RATIO = 0.15, 2.0
GRAVITY_RANGE_MPS2 = (7.0, 13.0)
GRAVITY_WARN_RANGE_MPS2 = (6.0, 14.0)
GRAVITY_RATIO = (0.7, 1.4)
# |acc| at rest [m/s^2 as read] that means g read as m/s^2 (~1) or m/s^2 read as g (~96).
G_AS_MPS2_RANGE = (0.5, 2.0)
MPS2_AS_G_RANGE = (48.0, 192.0)

# 6. rad/s: a gyro whose 90th percentile of |gyro| exceeds this is in deg/s (573 deg/s);
GYRO_P90_MAX_RAD_S = 10.0
# a gyro at rest noisier than this (std per axis, the still rule's own gyro cap) is in deg/s;
GYRO_REST_NOISE_MAX_RAD_S = 0.05
# a gyro at rest reading more than this (29 deg/s) is likely in deg/s (a warning: a turntable's
# steady rotation is as quiet as rest);
GYRO_REST_WARN_RAD_S = 0.5
# a gyro stated in deg/s whose 99th percentile stays below this [rad/s] (2.9 deg/s) while the
# accelerometer moves (its |acc| spread above ACC_MOVING_STD_MPS2) is likely in rad/s (a warning).
GYRO_DEG_P99_MIN_RAD_S = 0.05
ACC_MOVING_STD_MPS2 = 0.5

_UNIT_NS = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
_UNIT_WORDS = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}
_AXES = ("gx", "gy", "gz", "ax", "ay", "az")


FIXED_REST_HEAD_S = 30.0  # where check_fixed_units looks for rest [s from the first sample]


def check_fixed_units(path: Path, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, layout_words: str) -> None:
    """A file whose layout fixes its units (``layout_words``, e.g. an ASL IMU CSV: ns, rad/s, m/s^2) but
    whose numbers are in others (a logger's deg/s, g or ms under EuRoC's header): the checks of a user's CSV
    that decide (3-6 of the module doc, no warnings), each stopping with one line that names the mistake
    and how to read the file as what it is, a CSV of the user's own with its units."""
    c = _Context(Path(path), np.asarray(t_ns, dtype=np.int64), np.asarray(gyro, dtype=np.float64),
                 np.asarray(acc, dtype=np.float64), CsvColumns(), [], 0)
    c.warn = False
    try:
        _check_rate(c)
        if len(c.t_ns) < MIN_SAMPLES:
            return
        # rest from the first FIXED_REST_HEAD_S only (a recording's usual rest, at its start): the whole
        # file's still search costs ~40 ms per EuRoC flight on every read of a dataset that is mostly right
        head = int(np.searchsorted(c.t_ns, c.t_ns[0] + int(FIXED_REST_HEAD_S * 1e9)))
        rest = _rest(_Context(c.path, c.t_ns[:head], c.gyro[:head], c.acc[:head], c.layout, [], 0))
        _check_swap(c, rest)
        _check_acc(c, rest)
        _check_gyro(c, rest)
    except ImplausibleInputError as e:
        raise ImplausibleInputError(f"{e} ({layout_words} holds ns, rad/s and m/s^2: read this file as a CSV of your "
                                    f"own, --columns t,gx,gy,gz,ax,ay,az with {e.option} as named)", path=e.path,
                                    option=e.option) from None


def check_user_imu(path: Path, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, layout: CsvColumns,
                   names: Sequence[str] = (), fields: int = 0) -> None:
    """Raise :class:`ImplausibleInputError` for the first mistake found in a user's CSV read with
    ``layout`` (module doc), or log a warning where the data cannot decide. ``t_ns`` [ns], ``gyro``
    [rad/s] and ``acc`` [m/s^2] as read; ``names`` the file's column names (its header, may be empty);
    ``fields`` the number of fields of its first row."""
    c = _Context(Path(path), np.asarray(t_ns, dtype=np.int64), np.asarray(gyro, dtype=np.float64),
                 np.asarray(acc, dtype=np.float64), layout, list(names), int(fields))
    _check_columns_named(c)
    if len(c.t_ns) >= MIN_SAMPLES:
        _check_columns_vary(c)
    _check_rate(c)
    if len(c.t_ns) < MIN_SAMPLES:
        return
    _warn_gaps(c)
    rest = _rest(c)
    _check_swap(c, rest)
    _check_acc(c, rest)
    _check_gyro(c, rest)


class _Context:
    def __init__(self, path: Path, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, layout: CsvColumns,
                 names: List[str], fields: int) -> None:
        self.path, self.t_ns, self.gyro, self.acc, self.layout = path, t_ns, gyro, acc, layout
        self.names, self.fields = names, fields
        entries = [e.strip().lower() for e in layout.columns.split(",")]
        self.at = {e: i for i, e in enumerate(entries) if e != "_"}
        self.deg = layout.gyro_unit == "deg/s"
        self.in_g = layout.acc_unit == "g"
        self.warn = True  # the warnings where the data cannot decide (a file of fixed units: the clear cases only)

    def gyro_raw(self) -> np.ndarray:
        """The gyro in the file's own numbers."""
        return np.degrees(self.gyro) if self.deg else self.gyro

    def acc_raw(self) -> np.ndarray:
        return self.acc / STANDARD_GRAVITY if self.in_g else self.acc

    def column(self, q: str) -> str:
        """``column 5 (acc_x as ax)``: where quantity ``q`` is read from."""
        i = self.at[q]
        name = self.names[i].strip().lstrip("#").strip() if i < len(self.names) else ""
        return f"column {i + 1} ({name} as {q})" if name and name.lower() != q else f"column {i + 1} ({q})"

    def fail(self, message: str, option: str) -> None:
        raise ImplausibleInputError(f"{self.path}: {message}", path=str(self.path), option=option)


def _rate_text(hz: float) -> str:
    if hz >= 1e6:
        return f"{hz / 1e6:.3g} MHz"
    if hz >= 1e3:
        return f"{hz / 1e3:.3g} kHz"
    return f"{hz:.3g} Hz"


def _in(x: float, lo_hi: Tuple[float, float]) -> bool:
    return lo_hi[0] <= x <= lo_hi[1]


def _gravity_like_raw(x: float) -> bool:
    """A magnitude in the file's numbers that reads as gravity in m/s^2 or in g."""
    return any(_in(x / g, GRAVITY_RATIO) for g in (STANDARD_GRAVITY, 1.0))


# 1 ------------------------------------------------------------------------------------------------
_GUESS = [
    ("t", re.compile(r"time|stamp|^t$|^ts$|^sec")),
    ("g", re.compile(r"gyr|omega|^w_?[xyz]|^w_rs|ang|rot|^g[xyz]|rate|dps|rad")),
    ("a", re.compile(r"acc|^a_?[xyz]|^a_rs|lin|^a[xyz]|m_?s|_g$")),
]


def suggest_map(names: Sequence[str], fields: int) -> str:
    """A column map guessed from a header's names (``_`` for the columns it cannot place), else the
    default map padded with ``_``; only an example for a message."""
    out = ["_"] * max(fields, len(names))
    used = set()
    for i, raw in enumerate(names):
        n = raw.strip().lstrip("#").strip().lower()
        axis = re.findall(r"(?<![a-z])([xyz])(?![a-z])|_([xyz])\b|([xyz])$", n)
        ax = next((a for g in axis for a in g if a), "")
        for q, pat in _GUESS:
            key = q if q == "t" else f"{q}{ax}"
            if (q == "t" or ax) and key not in used and pat.search(n):
                out[i] = key
                used.add(key)
                break
    if used != {"t", "gx", "gy", "gz", "ax", "ay", "az"}:
        out = DEFAULT_COLUMNS.split(",") + ["_"] * (len(out) - DEFAULT_MAP_WIDTH)
    while out and out[-1] == "_":
        out.pop()
    return ",".join(out)


def _check_columns_named(c: _Context) -> None:
    if c.layout.columns_named or c.fields <= DEFAULT_MAP_WIDTH:
        return
    c.fail(f"has {c.fields} columns; name them with --columns (e.g. --columns {suggest_map(c.names, c.fields)}: "
           f"each of t,gx,gy,gz,ax,ay,az once in the file's order, _ for a column to skip)", "--columns")


# 2 ------------------------------------------------------------------------------------------------
def _check_columns_vary(c: _Context) -> None:
    raw = np.concatenate([c.gyro_raw(), c.acc_raw()], axis=1)
    for k, q in enumerate(_AXES):
        x = raw[:, k]
        unit = c.layout.gyro_unit if k < 3 else c.layout.acc_unit
        sensor = "gyro" if k < 3 else "accelerometer"
        if np.all(x == x[0]):
            c.fail(f"{c.column(q)} holds {x[0]:.6g} on every line; no {sensor} axis reads one value "
                   f"throughout: the map puts {q} on the wrong column; fix --columns", "--columns")
        if np.all(np.abs(x - np.round(x)) <= 1e-9 * np.maximum(1.0, np.abs(x))):
            c.fail(f"{c.column(q)} holds integers only ({x.min():.0f} to {x.max():.0f}), not {sensor} "
                   f"readings in {unit}: a counter, stamps or raw counts; fix --columns (or convert counts to "
                   f"{unit} first)", "--columns")


# 3 ------------------------------------------------------------------------------------------------
def _check_rate(c: _Context) -> None:
    period = median_period_ns(c.t_ns)
    if period <= 0:
        return
    rate = 1e9 / period
    if _in(rate, RATE_RANGE_HZ):
        return
    unit = c.layout.time_unit
    said = f"the stamps step by {period / _UNIT_NS[unit]:.6g} {unit} ({_rate_text(rate)}) with --time-unit {unit}"
    best = _fitting_unit(rate, unit)
    if best is not None:
        fixed = rate * _UNIT_NS[unit] / _UNIT_NS[best]
        c.fail(f"{said}: they look like {_UNIT_WORDS[best]} ({_rate_text(fixed)}); add --time-unit {best}",
               "--time-unit")
    c.fail(f"{said}, and no time unit gives an IMU's rate ({_rate_text(RATE_RANGE_HZ[0])} to "
           f"{_rate_text(RATE_RANGE_HZ[1])}): is {c.column('t')} the time? fix --columns", "--columns")


GAP_PERIODS = 10  # a step of the stamps this many median periods long: samples missing (a warning)


def _warn_gaps(c: _Context) -> None:
    """One warning where samples are missing: steps of the stamps longer than :data:`GAP_PERIODS` median
    periods (a logger that dropped a second of rows; every command integrates the IMU across them)."""
    period = median_period_ns(c.t_ns)
    if period <= 0:
        return
    d = np.diff(c.t_ns)
    gaps = np.flatnonzero(d > GAP_PERIODS * period)
    if not len(gaps):
        return
    i = int(gaps[np.argmax(d[gaps])])
    logger.warning("%s: %d gap(s) in the stamps longer than %d samples, the longest %.3g s after sample %d (%.3f s from "
                   "the start): samples are missing there and the IMU is integrated across them; check the logger, or "
                   "cut the file there", c.path, len(gaps), GAP_PERIODS, d[i] * 1e-9, i + 1,
                   (c.t_ns[i] - c.t_ns[0]) * 1e-9)


def _fitting_unit(rate: float, unit: str) -> Optional[str]:
    """The time unit, other than ``unit``, in which stamps that give ``rate`` [Hz] read in ``unit`` give
    an IMU's rate (:data:`RATE_RANGE_HZ`; the one nearest :data:`TYPICAL_RATE_HZ`), None if none does."""
    fits = [u for u in _UNIT_NS if u != unit and _in(rate * _UNIT_NS[unit] / _UNIT_NS[u], RATE_RANGE_HZ)]
    return min(fits, key=lambda u: abs(math.log(rate * _UNIT_NS[unit] / _UNIT_NS[u] / TYPICAL_RATE_HZ)),
               default=None)


def explain_repeated_stamps(path: Path, err: TimestampError, layout: CsvColumns,
                            lines: int = 1000) -> Optional[ImplausibleInputError]:
    """For stamps the reader refused as repeated or going back: where the time column's first ``lines``
    values, read as decimals in the stated ``--time-unit``, step at a rate outside an IMU's and another
    unit fits (seconds with decimals read as ns round to the same ns), the error naming that unit; else
    None (the stamps do repeat)."""
    entries = [e.strip().lower() for e in layout.columns.split(",")]
    if "t" not in entries or err.column != entries.index("t") + 1:
        return None
    col, stamps = entries.index("t"), []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for _, line in zip(range(lines), fh):
            fields = re.split(r"[,;\t ]+", line.strip())
            try:
                stamps.append(float(fields[col]))
            except (IndexError, ValueError):
                continue  # a header, a comment
    steps = np.diff(np.asarray(stamps, dtype=np.float64))
    steps = steps[steps > 0]
    if not len(steps):
        return None
    unit = layout.time_unit
    rate = 1e9 / (float(np.median(steps)) * _UNIT_NS[unit])
    best = None if _in(rate, RATE_RANGE_HZ) else _fitting_unit(rate, unit)
    if best is None:
        return None
    where = f"{err.path}:{err.line}" if err.path else str(path)
    return ImplausibleInputError(
        f"{where}: the stamps repeat as read with --time-unit {unit}; as written they step by "
        f"{float(np.median(steps)):.6g} {unit} ({_rate_text(rate)}): they look like {_UNIT_WORDS[best]} "
        f"({_rate_text(rate * _UNIT_NS[unit] / _UNIT_NS[best])}); add --time-unit {best}",
        path=str(path), option="--time-unit")


_INT64_MAX = 2**63 - 1
_EPOCH_S = (946_684_800, 4_102_444_800)  # 2000-01-01 to 2100-01-01, the stamps of Unix time [s]


def explain_time_overflow(path: Path, err: NotNumericError, layout: CsvColumns) -> Optional[ImplausibleInputError]:
    """For a stamp the reader refused as not a number although it is one, too large for int64 ns in
    the stated ``--time-unit`` (microsecond Unix time read as ms, ns as s): the error naming the unit
    that fits (the one that reads the stamp as Unix time, else the largest that fits), else None."""
    entries = [e.strip().lower() for e in layout.columns.split(",")]
    if "t" not in entries or err.column != entries.index("t") + 1:
        return None
    m = re.search(r'= "(.*)" is not a number', str(err))
    try:
        value = abs(float(m.group(1))) if m else math.nan
    except ValueError:
        return None
    unit = layout.time_unit
    if not math.isfinite(value) or value * _UNIT_NS[unit] <= _INT64_MAX:
        return None
    fits = [u for u in _UNIT_NS if value * _UNIT_NS[u] <= _INT64_MAX]
    if not fits:
        return None
    epoch = [u for u in fits if _in(value * _UNIT_NS[u] * 1e-9, _EPOCH_S)]
    best = epoch[0] if epoch else max(fits, key=lambda u: _UNIT_NS[u])
    where = f"{err.path}:{err.line}" if err.path else str(path)
    return ImplausibleInputError(
        f"{where}: the stamp {m.group(1) if m else value} with --time-unit {unit} lies beyond the "
        f"{_INT64_MAX / 1e9 / 86400 / 365.25:.0f} years int64 nanoseconds hold: the stamps look like "
        f"{_UNIT_WORDS[best]}; add --time-unit {best}", path=str(path), option="--time-unit")


# rest -----------------------------------------------------------------------------------------------
def _rest(c: _Context) -> Optional[np.ndarray]:
    """Indices of rest samples: the still rule on gyro and acc, else on the acc alone; None if none."""
    for gyro in (c.gyro, np.zeros_like(c.gyro)):
        spans = still_stretches(c.t_ns, gyro, c.acc)
        if spans:
            return np.concatenate([np.arange(a, b) for a, b in spans])
    return None


def white_noise(x: np.ndarray, idx: np.ndarray) -> float:
    """The per-sample white noise of ``x`` over the samples ``idx`` (ascending), per axis the spread of
    consecutive differences over sqrt(2), the median over the axes: a rest found on the accelerometer alone
    may turn slowly (TUM-VI's hand-held rig: 0.058 rad/s of spread, refused as deg/s before), which the
    differences leave out, while a gyro's noise read in the wrong unit is white and stays."""
    idx = np.asarray(idx)
    pairs = np.flatnonzero(np.diff(idx) == 1)
    if not len(pairs):
        return 0.0
    d = x[idx[pairs + 1]] - x[idx[pairs]]
    return float(np.median(np.std(d, axis=0))) / math.sqrt(2.0)


def _median_norm(x: np.ndarray, rest: Optional[np.ndarray]) -> float:
    return float(np.median(np.linalg.norm(x if rest is None else x[rest], axis=1)))


def _where(rest: Optional[np.ndarray]) -> str:
    return "at rest" if rest is not None else "over the file"


# 4 ------------------------------------------------------------------------------------------------
def _acc_explained(c: _Context, a_si: float) -> bool:
    """|acc| [m/s^2 as read] that is gravity, or gravity in the other acc unit."""
    return _in(a_si, GRAVITY_RANGE_MPS2) or _in(a_si, MPS2_AS_G_RANGE if c.in_g else G_AS_MPS2_RANGE)


def swapped_map(columns: str) -> str:
    """``columns`` with gx<->ax, gy<->ay, gz<->az."""
    swap = {"gx": "ax", "gy": "ay", "gz": "az", "ax": "gx", "ay": "gy", "az": "gz"}
    return ",".join(swap.get(e.strip().lower(), e.strip()) for e in columns.split(","))


def _spread(x: np.ndarray) -> float:
    """The relative spread of ``|x|`` over the file (median absolute deviation over the median)."""
    m = np.linalg.norm(x, axis=1)
    med = float(np.median(m))
    return float(np.median(np.abs(m - med))) / med if med > 0 else math.inf


def _turns_like_a_rate(c: _Context) -> bool:
    """The acc columns' magnitude spreads as a turning rate's does and the gyro columns' holds as gravity's
    (a recording that moves: EuRoC's columns swapped, 0.50 against 0.07); a unit that would explain the acc
    columns' level (deg/s read as g gives ~10 g) does not explain that."""
    a, g = _spread(c.acc), _spread(c.gyro)
    return a > SWAP_ACC_SPREAD and g < a / SWAP_SPREAD_RATIO


def _check_swap(c: _Context, rest: Optional[np.ndarray]) -> None:
    g_raw = _median_norm(c.gyro_raw(), rest)
    a_si = _median_norm(c.acc, rest)
    if _gravity_like_raw(g_raw) and (not _acc_explained(c, a_si) or _turns_like_a_rate(c)):
        a_raw = _median_norm(c.acc_raw(), rest)
        c.fail(f"the gyro columns read |gyro| = {g_raw:.3g} {_where(rest)}, as gravity does, and the acc columns "
               f"|acc| = {a_raw:.3g}: gyro and acc look swapped; fix --columns (e.g. --columns "
               f"{swapped_map(c.layout.columns)})", "--columns")


# 5 ------------------------------------------------------------------------------------------------
def _check_acc(c: _Context, rest: Optional[np.ndarray]) -> None:
    a = _median_norm(c.acc, rest)
    where = _where(rest)
    if not c.in_g and _in(a, G_AS_MPS2_RANGE):
        c.fail(f"|acc| {where} is {a:.3g} m/s2 with --acc-unit m/s2, near 1: the acc columns look like units of g; "
               "add --acc-unit g", "--acc-unit")
    if c.in_g and _in(a, MPS2_AS_G_RANGE):
        c.fail(f"|acc| {where} is {a / STANDARD_GRAVITY:.3g} g ({a:.3g} m/s2) with --acc-unit g, near 9.81 g: "
               "the acc columns look like m/s2; add --acc-unit m/s2", "--acc-unit")
    if c.warn and not _in(a, GRAVITY_WARN_RANGE_MPS2):
        logger.warning("%s: |acc| %s is %.3g m/s2, far from gravity (9.81): check --acc-unit (%s) and --columns",
                       c.path, where, a, c.layout.acc_unit)


# 6 ------------------------------------------------------------------------------------------------
def _check_gyro(c: _Context, rest: Optional[np.ndarray]) -> None:
    w = np.linalg.norm(c.gyro, axis=1)
    if not c.deg:
        p90 = float(np.percentile(w, 90))
        if p90 > GYRO_P90_MAX_RAD_S:
            c.fail(f"|gyro| exceeds {p90:.3g} rad/s ({math.degrees(p90):.0f} deg/s) in a tenth of the samples, "
                   "faster than an IMU turns: the gyro columns look like deg/s; add --gyro-unit deg/s", "--gyro-unit")
        if rest is not None:
            noise = white_noise(c.gyro, rest)
            if noise > GYRO_REST_NOISE_MAX_RAD_S:
                c.fail(f"the gyro's noise at rest is {noise:.3g} rad/s per axis, far above a gyro's in rad/s (and "
                       f"{noise * RAD_PER_DEG:.2g} rad/s read as deg/s): the gyro columns look like deg/s; add "
                       "--gyro-unit deg/s", "--gyro-unit")
            at_rest = float(np.median(w[rest]))
            if c.warn and at_rest > GYRO_REST_WARN_RAD_S:
                logger.warning("%s: |gyro| at rest is %.3g rad/s (%.0f deg/s): if the gyro columns are in deg/s, add "
                               "--gyro-unit deg/s", c.path, at_rest, math.degrees(at_rest))
        return
    p99 = float(np.percentile(w, 99))
    moving = float(np.std(np.linalg.norm(c.acc, axis=1))) > ACC_MOVING_STD_MPS2
    if p99 < GYRO_DEG_P99_MIN_RAD_S and moving:
        logger.warning("%s: the gyro stays below %.3g deg/s (99%% of the samples) while the accelerometer moves: if "
                       "the gyro columns are in rad/s, drop --gyro-unit deg/s", c.path, math.degrees(p99))
