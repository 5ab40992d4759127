"""Is a position aiding's world z up? From the data alone (no attitude, no truth), before any fusion.

Position aiding is fused in its own world with gravity along its −z (ENU, a motion-capture room):
positions given in another frame (a camera's first frame as a VO's world: z forward, y down) fuse
with exit 0 and an attitude that is wrong by the frames' angle, the track following the fixes. The
accelerometer's specific-force norm needs no attitude (:mod:`.delay`'s idea): a position track's second
difference over ±h at each row is the triangle-weighted mean of its acceleration ``a``, and
``|a + g u|`` (``u`` the world's up) must match the same triangle mean of the accelerometer's norm.
Every direction ``u`` on a sphere (:data:`DIRECTIONS` Fibonacci points, about 3° apart) is tried; the
residual's RMS (median removed: an accelerometer scale or bias shifts the norm) at z up is compared with
the best one's. To first order ``|a + g u| − g = a·u``: motion along z identifies u's tilt, level motion
its level (a level robot's world tilted 10° shows), but a world upside down only where the track moves
vertically.

Units: with z up, the positions scaled by each of :data:`SCALES` (mm, cm, ... given as m) against the
accelerometer; a factor other than 1 that fits :data:`RATIO` times better, and explains the norm
:data:`RATIO` times better than no positions at all, is refused, naming it.
The rule: refused where the best direction lies more than :data:`MAX_TILT_DEG` from z up, its RMS
at most 1 / :data:`RATIO` of z up's and at least :data:`MIN_GAIN` m/s² below it; not checked with fewer
than :data:`MIN_EPOCHS` rows with both neighbours. Measured: ORB-SLAM2 stereo positions of EuRoC MH_01,
MH_05, V1_03 in their camera frame 112-116° from z up (RMS 0.22-0.58 against 0.83-1.44 m/s² at z up);
the same flights' ground truth, Fetch's motion capture, the GNSS drive and walk (ENU) at z up itself (it
is the grid's first direction); Fetch's motion capture tilted 10° about x: 9.9°, passing (under
:data:`MAX_TILT_DEG`), turned 90°: 89.5°, refused; EuRoC's ground truth in mm or cm: refused as x1000, x100.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Dict, Optional, Tuple

import numpy as np

from .delay import double_integral

DIRECTIONS = 4000  # trial up directions (Fibonacci sphere, about 3° apart)
MAX_TILT_DEG = 15.0  # refused beyond this tilt of the best-fitting up from z
RATIO = 1.5  # ... where z up's RMS is at least this times the best one's
MIN_GAIN = 0.05  # ... and at least this much above it [m/s^2]
MIN_EPOCHS = 50  # rows with both neighbours the check needs
MIN_HALF_S = 0.2  # the second difference's half-width: at least this [s], and 4 rows' spacing
MAX_EPOCHS = 3000
SCALES = (1e-3, 1e-2, 0.1, 1.0, 10.0)  # factors tried on the positions (mm, cm, dm, m, 10 m): units, not a scale fit


@dataclass(frozen=True)
class GravityCheck:
    """The verdict (``ok``, ``refused``, ``not checked``), the best-fitting up direction in the aiding's
    world and its angle from z [deg], the residual RMS there and at z up [m/s^2], the rows used, the
    half-width [s], and why."""

    verdict: str
    up: Tuple[float, float, float]
    tilt_deg: float
    rms_best: float
    rms_z_up: float
    epochs: int
    half_width_s: float
    why: str
    scale: float = 1.0  # the factor on the positions that fits the accelerometer best, z up (:data:`SCALES`)

    def to_dict(self) -> Dict[str, object]:
        return {"verdict": self.verdict, "up_in_aiding_world": [round(float(x), 4) for x in self.up],
                "tilt_deg": round(self.tilt_deg, 1), "rms_best_mps2": round(self.rms_best, 4),
                "rms_z_up_mps2": round(self.rms_z_up, 4), "epochs": self.epochs,
                "half_width_s": round(self.half_width_s, 3), "why": self.why, "scale": self.scale,
                "method": "imu_learn.fuse.start.gravity"}


def sphere(n: int = DIRECTIONS) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    polar, azimuth = np.arccos(1.0 - 2.0 * i / n), np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.c_[np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)]


def _epochs(t: np.ndarray, h: float, dt: float, lo: float, hi: float) -> np.ndarray:
    """Row times whose ±h window lies inside [lo, hi] with no aiding gap in it, thinned to about h / 2 apart."""
    gap = np.r_[0.0, np.cumsum(np.diff(t) > max(3.0 * dt, 0.1))]
    c = t[(t - h >= lo) & (t + h <= hi)]
    c = c[np.interp(c - h, t, gap) == np.interp(c + h, t, gap)]
    c = c[::max(1, int(round(0.5 * h / dt)))]
    return c[:: max(1, int(np.ceil(len(c) / MAX_EPOCHS)))]


def _rms_over(U: np.ndarray, a: np.ndarray, f: np.ndarray, gravity: float, chunk: int = 500) -> np.ndarray:
    """(len(U),) the RMS (median removed) of ``f`` − (|a + g u| − g) for each up direction u of ``U``."""
    out = np.empty(len(U))
    for i in range(0, len(U), chunk):
        r = f[None, :] - (np.linalg.norm(a[None, :, :] + gravity * U[i:i + chunk, None, :], axis=2) - gravity)
        r -= np.median(r, axis=1, keepdims=True)
        out[i:i + chunk] = np.sqrt(np.mean(r * r, axis=1))
    return out


def check_gravity(imu_t_ns: np.ndarray, acc: np.ndarray, t_ns: np.ndarray, p: np.ndarray, gravity: float,
                  use: Optional[np.ndarray] = None) -> GravityCheck:
    """The check (module doc) of positions ``p`` (M, 3) [m] at stamps ``t_ns`` against the accelerometer
    ``acc`` (N, 3) [m/s^2, any frame] at ``imu_t_ns``; ``use``: the rows to use (default all)."""
    t0 = int(imu_t_ns[0])
    ti = (np.asarray(imu_t_ns, dtype=np.int64) - t0) * 1e-9
    keep = np.ones(len(t_ns), bool) if use is None else np.asarray(use, dtype=bool)
    t = (np.asarray(t_ns, dtype=np.int64)[keep] - t0) * 1e-9
    p = np.asarray(p, dtype=np.float64)[keep]
    none = GravityCheck("not checked", (0.0, 0.0, 1.0), float("nan"), float("nan"), float("nan"), 0, float("nan"), "")
    if len(t) < MIN_EPOCHS:
        return replace(none, why=f"{len(t)} aiding rows: too few (< {MIN_EPOCHS}) to tell the world's up")
    dt = float(np.median(np.diff(t)))
    h = max(MIN_HALF_S, 4.0 * dt)
    c = _epochs(t, h, dt, max(t[0], ti[0]), min(t[-1], ti[-1]))
    if len(c) < MIN_EPOCHS:
        return replace(none, why=f"{len(c)} rows with both neighbours {h:.2f} s away: too few (< {MIN_EPOCHS}) to "
                                 "tell the world's up")

    def at(x: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(x, t, p[:, k]) for k in range(3)], axis=1)

    a = (at(c + h) - 2.0 * at(c) + at(c - h)) / (h * h)
    F = double_integral(ti, np.linalg.norm(np.asarray(acc, dtype=np.float64), axis=1) - gravity)
    f = (np.interp(c + h, ti, F) - 2.0 * np.interp(c, ti, F) + np.interp(c - h, ti, F)) / (h * h)
    U = np.vstack([[0.0, 0.0, 1.0], sphere()])
    rms = _rms_over(U, a, f, gravity)  # every up direction, the positions as given
    k = int(np.argmin(rms))
    # units, z up: a factor on the positions that explains the accelerometer's norm better than 1 does and far
    # better than no positions at all (not by shrinking the positions' noise where they barely accelerate; a
    # tilted up would let a small factor fit a level change: a car's 1 m/s^2 step under 1 cm fixes)
    best_of = {x: float(_rms_over(U[:1], x * a, f, gravity)[0]) for x in SCALES}
    k_best = min(best_of, key=best_of.get)
    no_positions = float(np.sqrt(np.mean((f - np.median(f)) ** 2)))
    if k_best != 1.0 and best_of[1.0] >= RATIO * best_of[k_best] and no_positions >= RATIO * best_of[k_best]:
        why = (f"the positions are x{1 / k_best:g} the distances the accelerometer measures (its specific-force norm "
               f"fits them best scaled by {k_best:g}: RMS {best_of[k_best]:.3f} against {best_of[1.0]:.3f} m/s^2 as "
               "given, z up): millimetres or centimetres? give them in metres")
        return GravityCheck("refused", (0.0, 0.0, 1.0), float("nan"), best_of[k_best], best_of[1.0], int(len(c)), h,
                            why, k_best)
    tilt = float(np.degrees(np.arccos(np.clip(U[k, 2], -1.0, 1.0))))
    up, best, z_up = tuple(float(x) for x in U[k]), float(rms[k]), float(rms[0])
    refused = tilt > MAX_TILT_DEG and z_up >= RATIO * best and z_up - best >= MIN_GAIN
    why = (f"the accelerometer's specific-force norm fits the positions best with the world's up "
           f"({up[0]:+.2f}, {up[1]:+.2f}, {up[2]:+.2f}), {tilt:.0f} deg from z (RMS {best:.3f} against {z_up:.3f} m/s^2 "
           f"with z up; {len(c)} rows, +-{h:.2f} s)")
    return GravityCheck("refused" if refused else "ok", up, tilt, best, z_up, int(len(c)), h, why)

