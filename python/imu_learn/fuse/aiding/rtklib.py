"""RTKLIB solution files (``.pos``) as position aiding: reader, WGS-84 geodesy, and the fixes tied
to IMU samples for the factor graph.

A ``.pos`` file has ``%`` comment lines, the last of which names the columns, then one epoch a
line: the time (``GPST`` as ``YYYY/MM/DD HH:MM:SS.sss`` or as ``week seconds``), the position
(``latitude(deg) longitude(deg) height(m)`` or ``x-ecef(m) y-ecef(m) z-ecef(m)``), ``Q`` (1 fixed
RTK, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP), ``ns``, the standard deviations (``sdn sde sdu
sdne sdeu sdun`` or ``sdx sdy sdz sdxy sdyz sdzx`` [m]; RTKLIB writes the off-diagonal terms as
signed square roots), ``age``, ``ratio`` and optionally velocities (``vn ve vu`` or ``vx vy vz``
[m/s]) with their deviations. The reader uses the header's names, so columns may come in any
order; the time system must be GPST (a UTC or JST file would need leap seconds: refused).
Anything else malformed is a typed error (:mod:`imu_learn.errors`) naming file, line and field.

Positions go to a local east-north-up frame whose origin is the first epoch (exact WGS-84
formulas; the ECEF-to-geodetic inverse is iterated to machine precision). Each epoch's
covariance is rotated into ENU and its per-axis standard deviations become the factor's sigmas
(off-diagonal terms are dropped), multiplied by a gain for solutions worse than fixed (float:
``float_gain``, as rtklibexplorer/GNSS_IMU's ``float_err_gain``).
"""
from __future__ import annotations

import calendar
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.data.formats.fields import number
from imu_learn.errors import (
    AidingError,
    AidingOverlapError,
    ColumnCountError,
    HeaderError,
    InvalidInputError,
    NotNumericError,
    SolutionQualityError,
    TimestampError,
    TooFewRowsError,
)

from .sampling import snap_to_samples
from .types import GnssFixes

log = logging.getLogger(__name__)

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
GPS_EPOCH_S = 315964800  # 1980-01-06 00:00:00 as seconds since 1970 (no leap seconds on GPST)
LLH_COLS = ("latitude(deg)", "longitude(deg)", "height(m)")
ECEF_COLS = ("x-ecef(m)", "y-ecef(m)", "z-ecef(m)")
Q_NAMES = {1: "fix", 2: "float", 3: "sbas", 4: "dgps", 5: "single", 6: "ppp"}


@dataclass(frozen=True)
class RtkSolution:
    """A parsed ``.pos`` file in a local ENU frame (origin: the first epoch). ``t_ns`` (M,) GPST [ns
    since 1970, no leap seconds]; ``enu`` (M, 3) [m]; ``sigma_enu`` (M, 3) [m] per-axis standard
    deviations; ``vel_enu`` (M, 3) [m/s] or None without velocity columns; ``q`` (M,) the quality
    flag; ``lines`` (M,) their 1-based line numbers; ``origin_llh`` (lat [deg], lon [deg], h [m])."""

    path: str
    t_ns: np.ndarray
    enu: np.ndarray
    sigma_enu: np.ndarray
    vel_enu: Optional[np.ndarray]
    q: np.ndarray
    lines: np.ndarray
    origin_llh: Tuple[float, float, float]
    position_kind: str  # "llh" or "ecef"

    def __len__(self) -> int:
        return len(self.t_ns)


# --- WGS-84 ----------------------------------------------------------------------------------------

def llh_to_ecef(lat_deg: np.ndarray, lon_deg: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Geodetic latitude, longitude [deg] and ellipsoidal height [m] -> ECEF (..., 3) [m]."""
    lat, lon = np.deg2rad(lat_deg), np.deg2rad(lon_deg)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.stack([(n + h) * np.cos(lat) * np.cos(lon), (n + h) * np.cos(lat) * np.sin(lon),
                     (n * (1.0 - WGS84_E2) + h) * np.sin(lat)], axis=-1)


def ecef_to_llh(xyz: np.ndarray) -> Tuple[float, float, float]:
    """ECEF (3,) [m] -> (lat [deg], lon [deg], h [m]); the latitude iterated to machine precision."""
    x, y, z = (float(v) for v in np.asarray(xyz, dtype=np.float64).reshape(3))
    p = math.hypot(x, y)
    lon = math.atan2(y, x)
    lat = math.atan2(z, p * (1.0 - WGS84_E2))
    h = 0.0
    for _ in range(20):
        n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * math.sin(lat) ** 2)
        h = p / math.cos(lat) - n if abs(lat) < math.pi / 4 else z / math.sin(lat) - n * (1.0 - WGS84_E2)
        new = math.atan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
        if abs(new - lat) < 1e-15:
            lat = new
            break
        lat = new
    n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * math.sin(lat) ** 2)
    h = p / math.cos(lat) - n if abs(lat) < math.pi / 4 else z / math.sin(lat) - n * (1.0 - WGS84_E2)
    return math.degrees(lat), math.degrees(lon), h


def ecef_to_enu_rotation(lat_deg: float, lon_deg: float) -> np.ndarray:
    """The (3, 3) matrix taking ECEF vectors to east, north, up at (lat, lon)."""
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    sla, cla, slo, clo = math.sin(la), math.cos(la), math.sin(lo), math.cos(lo)
    return np.array([[-slo, clo, 0.0], [-sla * clo, -sla * slo, cla], [cla * clo, cla * slo, sla]])


def normal_gravity(lat_deg: float, h: float) -> float:
    """WGS-84 normal gravity [m/s^2] (Somigliana) at latitude ``lat_deg`` with the second-order
    free-air height correction: what a level accelerometer at rest reads, to ~1e-5 m/s^2."""
    s2 = math.sin(math.radians(lat_deg)) ** 2
    g0 = 9.7803253359 * (1.0 + 0.00193185265241 * s2) / math.sqrt(1.0 - WGS84_E2 * s2)
    m = 0.00344978650684  # omega^2 a^2 b / GM
    return g0 * (1.0 - 2.0 / WGS84_A * (1.0 + WGS84_F + m - 2.0 * WGS84_F * s2) * h + 3.0 / WGS84_A ** 2 * h * h)


# --- reader ----------------------------------------------------------------------------------------

def looks_like_pos(lines: Sequence[str]) -> bool:
    """Whether the first lines of a file are an RTKLIB solution's: ``%`` comment lines, the last of
    which names the time system and RTKLIB's position columns (any time system: the reader then says
    which it takes)."""
    hdr = None
    for line in lines:
        if line.startswith("%"):
            hdr = line
        elif line.strip():
            break
    if hdr is None:
        return False
    tokens = hdr.lstrip("%").split()
    return bool(tokens) and tokens[0] in ("GPST", "UTC", "JST") and (
        all(c in tokens for c in LLH_COLS) or all(c in tokens for c in ECEF_COLS) or "Q" in tokens)


def _time_ns(tokens: Sequence[str], p: str, lineno: int) -> int:
    a, b = tokens
    if "/" in a:  # YYYY/MM/DD HH:MM:SS.sss
        try:
            y, mo, d = (int(v) for v in a.split("/"))
            hh, mm, ss = b.split(":")
            whole, _, frac = ss.partition(".")
            sec = calendar.timegm((y, mo, d, int(hh), int(mm), int(whole), 0, 0, 0))
            if not (1 <= mo <= 12 and 1 <= d <= 31 and 0 <= int(hh) < 24 and 0 <= int(mm) < 60
                    and 0 <= int(whole) < 61 and (frac == "" or frac.isdigit())):
                raise ValueError
        except ValueError:
            raise NotNumericError(f"{p}:{lineno}: column 1-2 (GPST): {a} {b!r} is not a date and time "
                                  "YYYY/MM/DD HH:MM:SS.sss", p, lineno, 1, "GPST") from None
        return sec * 1_000_000_000 + (int(round(int(frac) * 10 ** (9 - len(frac)))) if frac else 0)
    try:
        week, tow = int(a), float(b)
        if week < 0 or not (0.0 <= tow < 604800.0):
            raise ValueError
    except ValueError:
        raise NotNumericError(f"{p}:{lineno}: column 1-2 (GPST): {a} {b!r} is neither a date and time nor "
                              "a GPS week and seconds of week", p, lineno, 1, "GPST") from None
    return (GPS_EPOCH_S + week * 604800) * 1_000_000_000 + int(round(tow * 1e9))


def _header(lines: List[str], p: str) -> Tuple[int, List[str], str]:
    """The column header (the last ``%`` line before the data): (its line index, the value column
    names after the time, the position kind)."""
    hdr = -1
    for i, line in enumerate(lines):
        if line.startswith("%"):
            hdr = i
        elif line.strip():
            break
    if hdr < 0:
        raise HeaderError(f"{p}:1: no '%' header line naming the columns (is this an RTKLIB .pos file?)", p, 1)
    tokens = lines[hdr].lstrip("%").split()
    if not tokens or tokens[0] != "GPST":
        raise HeaderError(f"{p}:{hdr + 1}: time system {tokens[0] if tokens else ''!r}: only GPST is read (a UTC "
                          "or JST solution needs leap seconds; set RTKLIB's output time to GPST)", p, hdr + 1, 1,
                          tokens[0] if tokens else None)
    names = tokens[1:]
    kind = next((k for k, cols in (("llh", LLH_COLS), ("ecef", ECEF_COLS)) if all(c in names for c in cols)), "")
    if not kind:
        raise HeaderError(f"{p}:{hdr + 1}: header names neither {' '.join(LLH_COLS)} nor {' '.join(ECEF_COLS)} "
                          f"(got {' '.join(names)}; RTKLIB's dms or xyz-enu output is not read)", p, hdr + 1)
    sd = ("sdn(m)", "sde(m)", "sdu(m)") if kind == "llh" else ("sdx(m)", "sdy(m)", "sdz(m)")
    missing = [c for c in ("Q",) + sd if c not in names]
    if missing:
        raise HeaderError(f"{p}:{hdr + 1}: header lacks {', '.join(missing)}", p, hdr + 1)
    return hdr, names, kind


def _covariance(vals: Dict[str, float], kind: str) -> np.ndarray:
    """The epoch's position covariance from RTKLIB's deviations (off-diagonals: signed sqrt)."""
    keys = (("sdn(m)", "sde(m)", "sdu(m)", "sdne(m)", "sdeu(m)", "sdun(m)") if kind == "llh"
            else ("sdx(m)", "sdy(m)", "sdz(m)", "sdxy(m)", "sdyz(m)", "sdzx(m)"))
    s = [vals.get(k, 0.0) for k in keys]
    o = [math.copysign(v * v, v) for v in s[3:]]
    if kind == "llh":  # to E, N, U order: n,e,u -> e,n,u
        return np.array([[s[1] ** 2, o[0], o[1]], [o[0], s[0] ** 2, o[2]], [o[1], o[2], s[2] ** 2]])
    return np.array([[s[0] ** 2, o[0], o[2]], [o[0], s[1] ** 2, o[1]], [o[2], o[1], s[2] ** 2]])


def read_pos(path: Path) -> RtkSolution:
    """Read an RTKLIB ``.pos`` file (module docstring) into a local ENU frame at its first epoch.
    Errors: :class:`HeaderError` (no/unknown header), :class:`ColumnCountError`,
    :class:`NotNumericError`, :class:`NonFiniteError` (NaN, inf), :class:`SolutionQualityError`
    (Q not 1-6), :class:`TimestampError` (an epoch not after the one before),
    :class:`TooFewRowsError` (no epoch); each names file, line and field."""
    p = str(path)
    with open(path, encoding="utf-8", errors="replace") as fh:
        lines = fh.read().splitlines()
    hdr, names, kind = _header(lines, p)
    width = 2 + len(names)
    col = {n: 2 + i for i, n in enumerate(names)}
    pos_cols = LLH_COLS if kind == "llh" else ECEF_COLS
    vel_cols = (("vn(m/s)", "ve(m/s)", "vu(m/s)") if kind == "llh" else ("vx(m/s)", "vy(m/s)", "vz(m/s)"))
    has_vel = all(c in col for c in vel_cols)
    t_l, pos_l, cov_l, vel_l, q_l, line_l = [], [], [], [], [], []
    prev = None
    data = [i for i in range(hdr + 1, len(lines)) if lines[i].strip() and not lines[i].startswith("%")]
    last = data[-1] if data else -1
    for i in data:
        line, lineno = lines[i], i + 1
        tok = line.split()
        if len(tok) < width and i == last and i > data[0]:  # a logger stopped mid-line: as the IMU logs' reader
            log.info("%s: left out its last line %d, cut (%d of %d columns)", p, lineno, len(tok), width)
            break
        if len(tok) != width:
            raise ColumnCountError(f"{p}:{lineno}: expected {width} columns (GPST date/week and time, "
                                   f"{' '.join(names)}), found {len(tok)} (a cut last line is left out; repair "
                                   "or remove a cut line inside the file)", p, lineno)
        t = _time_ns(tok[:2], p, lineno)
        vals: Dict[str, float] = {}
        for name, c in col.items():
            vals[name] = number(tok[c], p, lineno, c + 1, name)
        q = vals["Q"]
        if q != int(q) or int(q) not in Q_NAMES:
            raise SolutionQualityError(f"{p}:{lineno}: column {col['Q'] + 1} (Q): {tok[col['Q']]!r} is not a "
                                       "quality flag 1-6", p, lineno, col["Q"] + 1, "Q")
        if prev is not None and t <= prev:
            what = "repeats" if t == prev else "goes back from"
            raise TimestampError(f"{p}:{lineno}: column 1-2 (GPST): {' '.join(tok[:2])} {what} the previous "
                                 "epoch (stamps must increase)", p, lineno, 1, "GPST")
        if kind == "llh" and not (-90.0 <= vals[LLH_COLS[0]] <= 90.0 and -180.0 <= vals[LLH_COLS[1]] <= 360.0):
            raise NotNumericError(f"{p}:{lineno}: latitude/longitude {vals[LLH_COLS[0]]}, {vals[LLH_COLS[1]]} out "
                                  "of range", p, lineno, col[LLH_COLS[0]] + 1, LLH_COLS[0])
        prev = t
        t_l.append(t)
        pos_l.append([vals[c] for c in pos_cols])
        cov_l.append(_covariance(vals, kind))
        if has_vel:
            vel_l.append([vals[c] for c in vel_cols])
        q_l.append(int(q))
        line_l.append(lineno)
    if not t_l:
        raise TooFewRowsError(f"{p}: no solution epoch after the header (line {hdr + 1})", p, len(lines))
    pos = np.asarray(pos_l, dtype=np.float64)
    if kind == "llh":
        ecef = llh_to_ecef(pos[:, 0], pos[:, 1], pos[:, 2])
        origin = (float(pos[0, 0]), float(pos[0, 1]), float(pos[0, 2]))
    else:
        ecef = pos
        origin = ecef_to_llh(ecef[0])
    R = ecef_to_enu_rotation(origin[0], origin[1])
    enu = (ecef - ecef[0]) @ R.T
    cov = np.asarray(cov_l)
    if kind == "ecef":
        cov = R @ cov @ R.T
    sigma = np.sqrt(np.clip(np.einsum("kii->ki", cov), 0.0, None))
    vel = None
    if has_vel:
        v = np.asarray(vel_l, dtype=np.float64)
        vel = v[:, [1, 0, 2]] if kind == "llh" else v @ R.T  # n,e,u -> e,n,u
    return RtkSolution(p, np.asarray(t_l, dtype=np.int64), enu, sigma, vel, np.asarray(q_l, dtype=np.int8),
                       np.asarray(line_l, dtype=np.int64), origin, kind)


# --- fixes on the IMU's samples --------------------------------------------------------------------

FLOAT_GAIN = 2.0  # a float epoch's sigmas over a fixed one's (rtklibexplorer/GNSS_IMU's float_err_gain)


def fixes_on_imu(sol: RtkSolution, imu_t_ns: np.ndarray, lever: Sequence[float] = (0.0, 0.0, 0.0),
                 qualities: Sequence[int] = (1, 2), float_gain: float = FLOAT_GAIN, other_gain: float = 5.0,
                 sigma_floor_m: float = 0.0, move_to_sample: bool = True, label: Optional[str] = None) -> GnssFixes:
    """The solution's epochs with a quality in ``qualities`` as :class:`GnssFixes` at the nearest
    IMU sample (the time rules of :func:`imu_learn.fuse.aiding.snap_to_samples`; epochs outside the
    IMU's span or without a sample within half a period are dropped and counted). With
    ``move_to_sample`` and velocity columns, each position is moved by ``v * (t_sample - t_fix)``
    onto its sample's stamp (up to half an IMU period: 5 mm per m/s at 100 Hz). Sigmas: the
    epoch's ENU deviations (at least ``sigma_floor_m``) times 1 (fixed), ``float_gain`` (float) or
    ``other_gain``. ``lever``: the antenna in the body frame [m]. ``label``: what the fixes are
    (default: the RTKLIB solution's file and qualities; a bag's NavSatFix topic names itself)."""
    imu_t_ns = np.asarray(imu_t_ns, dtype=np.int64)
    if not (float_gain > 0 and other_gain > 0 and sigma_floor_m >= 0):
        raise InvalidInputError(f"gains must be > 0 and the floor >= 0: {float_gain}, {other_gain}, {sigma_floor_m}")
    use = np.isin(sol.q, np.asarray(qualities, dtype=np.int8))
    if label is None:
        label = f"RTKLIB {Path(sol.path).name} (real), Q in {list(qualities)}"
    if not use.any():
        raise AidingError(f"{sol.path}: no epoch with quality {list(qualities)}", sol.path, label)
    t = sol.t_ns[use]
    nearest, inside, close = snap_to_samples(imu_t_ns, t)
    if not inside.any():
        span = f"[{int(imu_t_ns[0])}, {int(imu_t_ns[-1])}] ns"
        raise AidingOverlapError(f"{sol.path}: lines {int(sol.lines[use][0])}-{int(sol.lines[use][-1])}: fixes span "
                                 f"[{int(t[0])}, {int(t[-1])}] ns, the IMU {span}: no overlap (same time scale?)",
                                 sol.path, label)
    keep = inside & close
    idx = nearest[keep]
    idx, first = np.unique(idx, return_index=True)
    sel = np.flatnonzero(use)[np.flatnonzero(keep)[first]]
    p = sol.enu[sel].copy()
    if move_to_sample and sol.vel_enu is not None:
        p += sol.vel_enu[sel] * ((imu_t_ns[idx] - sol.t_ns[sel]) * 1e-9)[:, None]
    q = sol.q[sel]
    gain = np.where(q == 1, 1.0, np.where(q == 2, float_gain, other_gain))
    sig = np.maximum(sol.sigma_enu[sel], sigma_floor_m) * gain[:, None]
    if not np.all(sig > 0):
        bad = int(sol.lines[sel][np.flatnonzero(~np.all(sig > 0, axis=1))[0]])
        raise SolutionQualityError(f"{sol.path}:{bad}: a zero standard deviation; set a sigma floor", sol.path, bad,
                                   None, "sdn(m)")
    dropped_unmatched = int((inside & ~close).sum()) + int(keep.sum()) - len(idx)
    return GnssFixes(idx.astype(np.int64), p, float(np.median(sig)), np.asarray(lever, dtype=np.float64), label,
                     sol.path, int((~inside).sum()), dropped_unmatched, 0, sig, q, sel.astype(np.int64))
