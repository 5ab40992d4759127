"""Levelling: roll and pitch from the accelerometer, and the aiding's world levelled.

* **Roll and pitch** are levelled from the accelerometer: at rest it measures the specific force
  ``f_B = R_WB^T (0, 0, g)``, so ``roll = atan2(f_y, f_z)`` and ``pitch = atan2(-f_x, hypot(f_y,
  f_z))`` (:func:`level`). The mean is taken over the **still start** when the recording has one
  (:func:`still_start`: the run of 0.25 s blocks from the first sample whose gyro and accelerometer
  spread stay below thresholds and whose mean stays where it started, at least ``min_still_s``
  long), else over the first ``level_s`` seconds, where the vehicle's own accelerations tilt the
  estimate (``attitude_source`` says which; :func:`attitude_from_accelerometer`). A known
  accelerometer bias (checkpoint) is removed first. :func:`first_rest` finds a rest after the start.
* **Gravity from pose aiding**: the aiding's world frame A (for a camera trajectory, the first
  camera's frame) is not gravity-aligned; gravity in A comes from the accelerometer rotated by the
  aiding's attitude, minus the aiding's own acceleration (:func:`gravity_in_aiding`, which works while
  moving), and A is levelled into the navigation frame W (z up) keeping its heading
  (:func:`level_aiding`; :func:`world_from_aiding` from a levelled attitude instead): W is A
  levelled, the body's first heading is the aiding's.
"""
from __future__ import annotations

import logging
from typing import Dict, Optional, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.core.still import ACC_NORM_TOL, MEMS_PRIOR, at_rest
from imu_learn.errors import InvalidInputError

log = logging.getLogger(__name__)

BLOCK_S = 0.25
# A block is still when every gyro axis varies less than this [rad/s] and every accelerometer axis
# less than ACC_STILL [m/s^2] (standard deviation inside the block), and it passes the still rule
# (imu_learn.core.still.at_rest: the mean gyro within 3 sigma of a MEMS gyro's bias spread, the
# accelerometer's mean norm within ACC_NORM_TOL of gravity). EuRoC's ADIS16448 at rest on the
# ground: gyro ~0.003 rad/s, acc ~0.02-0.03 m/s^2 per sample; rotors spinning or the vehicle carried
# exceed both; a steady turn passes the spreads but not the rule.
GYRO_STILL = 0.02
ACC_STILL = 0.08
ACC_MEAN_DRIFT = 0.1  # [m/s^2] a block's mean further than this from the first block's: moving


def block_edges(t_ns: np.ndarray, n_blocks: int) -> np.ndarray:
    """Sample index where each :data:`BLOCK_S` block from the first sample starts (n_blocks + 1 edges)."""
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    return np.searchsorted(t, np.arange(n_blocks + 1) * BLOCK_S)


def block_is_still(g: np.ndarray, a: np.ndarray, gravity: float) -> bool:
    """A block of gyro and accelerometer samples at rest: at least 3 samples, every axis' spread below
    :data:`GYRO_STILL` / :data:`ACC_STILL`, and the still rule (:func:`imu_learn.core.still.at_rest`
    with a MEMS gyro's prior: the mean gyro near a bias, the accelerometer's mean norm within
    :data:`ACC_NORM_TOL` of gravity)."""
    return bool(len(g) >= 3 and g.std(axis=0).max() <= GYRO_STILL and a.std(axis=0).max() <= ACC_STILL
                and at_rest(g.mean(axis=0), np.linalg.norm(a.mean(axis=0)), gravity, MEMS_PRIOR, acc_tol=ACC_NORM_TOL))


def _blocks(t_ns: np.ndarray, max_s: float) -> int:
    return int(min((int(t_ns[-1]) - int(t_ns[0])) * 1e-9, max_s) // BLOCK_S)


def still_start(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, gravity: float = 9.81,
                max_s: float = 20.0) -> float:
    """Seconds of rest at the start of the recording (0.0 when the first block already moves):
    consecutive :data:`BLOCK_S` blocks from the first sample that are still (:func:`block_is_still`)
    and whose accelerometer mean stays where it started, at most ``max_s``."""
    n_blocks = _blocks(t_ns, max_s)
    edges = block_edges(t_ns, n_blocks)
    still = 0.0
    first = None
    for b in range(n_blocks):
        g, a = gyro[edges[b]:edges[b + 1]], acc[edges[b]:edges[b + 1]]
        if not block_is_still(g, a, gravity):
            break
        mean = a.mean(axis=0)
        first = mean if first is None else first
        # a steady acceleration is as smooth as rest: the mean must also stay where it started
        if np.abs(mean - first).max() > ACC_MEAN_DRIFT:
            break
        still = (b + 1) * BLOCK_S
    return still


def first_rest(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, gravity: float = 9.81, within_s: float = 30.0,
               min_s: float = 1.0) -> Optional[Tuple[int, int]]:
    """(first sample, end sample) of the first stretch of rest at least ``min_s`` long that starts in
    the first ``within_s`` seconds (still blocks, :func:`block_is_still`), or None. A recording that
    starts with a hand-held excitation and then sits on the ground (EuRoC's machine-hall flights
    before take-off) has one after its start."""
    n_blocks = _blocks(t_ns, within_s + 20.0)
    edges = block_edges(t_ns, n_blocks)
    run_start = None
    for b in range(n_blocks):
        ok = block_is_still(gyro[edges[b]:edges[b + 1]], acc[edges[b]:edges[b + 1]], gravity)
        if ok and run_start is None and b * BLOCK_S <= within_s:
            run_start = b
        elif not ok and run_start is not None:
            if (b - run_start) * BLOCK_S >= min_s:
                return int(edges[run_start]), int(edges[b])
            run_start = None
    if run_start is not None and (n_blocks - run_start) * BLOCK_S >= min_s:
        return int(edges[run_start]), int(edges[n_blocks])
    return None


def level(f_B: np.ndarray) -> Tuple[float, float, np.ndarray]:
    """(roll, pitch, R_WB with zero yaw) of a body at rest measuring the specific force ``f_B``."""
    f = np.asarray(f_B, dtype=np.float64)
    if not np.all(np.isfinite(f)) or np.linalg.norm(f) < 1e-6:
        raise InvalidInputError(f"cannot level from the specific force {f.tolist()}")
    roll = float(np.arctan2(f[1], f[2]))
    pitch = float(np.arctan2(-f[0], np.hypot(f[1], f[2])))
    R = Rotation.from_euler("ZYX", [0.0, pitch, roll]).as_matrix()
    return roll, pitch, R


def yaw_of(R: np.ndarray) -> float:
    """The heading (ZYX yaw) of a rotation, radians."""
    return float(np.arctan2(R[1, 0], R[0, 0]))


def rot_z(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def world_from_aiding(R_level: np.ndarray, R_AB0: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(R_WA, R_WB0): the aiding world A levelled into W with A's heading kept, and the body's first
    attitude in W, from the levelled (zero-yaw) attitude ``R_level`` and the aiding's body
    orientation ``R_AB0`` at the same time (module docstring)."""
    R_WA0 = R_level @ R_AB0.T
    turn = rot_z(-yaw_of(R_WA0))
    return turn @ R_WA0, turn @ R_level


def gravity_in_aiding(imu_t_ns: np.ndarray, acc: np.ndarray, t_ns: np.ndarray, p_A: np.ndarray, R_AB: np.ndarray,
                      window_s: float = 3.0, acc_bias: Optional[np.ndarray] = None, edge_s: float = 0.1
                      ) -> Tuple[np.ndarray, Dict[str, object]]:
    """(up_A, info): the direction opposite gravity in the aiding's world A from the first
    ``window_s`` seconds of body poses (``t_ns``, ``p_A``, ``R_AB``) and the accelerometer: the
    specific force rotated into A and averaged, minus the aiding's own mean acceleration over the
    window (its velocity change, velocities from the positions over ``edge_s`` at each end):
    ``mean(R_AB f_B) - (v_end - v_start) / T = -g_A``. Works while moving, where levelling the
    accelerometer alone is tilted by the vehicle's accelerations."""
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    T = min(window_s, float(t[-1]))
    if T < 4 * edge_s:
        raise InvalidInputError(f"gravity from aiding: the aiding spans {t[-1]:.2f} s, at least {4 * edge_s:g} s needed")
    ti = (np.asarray(imu_t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    m = (ti >= 0) & (ti <= T)
    from scipy.spatial.transform import Slerp

    R_i = Slerp(t, Rotation.from_matrix(R_AB))(ti[m])
    f = acc[m] - (np.zeros(3) if acc_bias is None else np.asarray(acc_bias))
    mean_f_A = R_i.apply(f).mean(axis=0)

    def velocity(at: float) -> np.ndarray:
        a, b = np.searchsorted(t, at - edge_s), np.searchsorted(t, at + edge_s)
        a, b = max(a, 0), min(b, len(t) - 1)
        if b <= a:
            b = min(a + 1, len(t) - 1)
        return (p_A[b] - p_A[a]) / max(t[b] - t[a], 1e-3)

    dv = (velocity(T - edge_s) - velocity(edge_s)) / max(T - 2 * edge_s, 1e-3)
    up = mean_f_A - dv
    g = float(np.linalg.norm(up))
    info = {"attitude_source": f"gravity in the aiding's frame: accelerometer rotated by the aiding's attitude and "
                               f"averaged over the first {T:.1f} s, minus the aiding's own mean acceleration "
                               f"({np.linalg.norm(dv):.3f} m/s^2)", "gravity_norm_mps2": round(g, 4)}
    return up / g, info


def level_aiding(up_A: np.ndarray, R_AB0: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(R_WA, R_WB0): the rotation taking the aiding's world A to W (``up_A`` onto z, A's heading
    kept: zero yaw) and the body's first attitude in W."""
    R0 = Rotation.align_vectors([[0.0, 0.0, 1.0]], [np.asarray(up_A, dtype=np.float64)])[0].as_matrix()
    R_WA = rot_z(-yaw_of(R0)) @ R0
    return R_WA, R_WA @ R_AB0


def _rests(gyro: np.ndarray, acc: np.ndarray, span: Tuple[int, int, str], gravity: float) -> bool:
    """Whether the IMU agrees with a rest the aiding shows over ``span``: on average, the still rule
    (:func:`imu_learn.core.still.at_rest`: the mean gyro a MEMS gyro's bias, the mean specific force
    gravity's norm); a device turned in a hand while its carrier stands fails it."""
    g, a = gyro[span[0]:span[1]].mean(axis=0), acc[span[0]:span[1]].mean(axis=0)
    return bool(at_rest(g, float(np.linalg.norm(a)), gravity, MEMS_PRIOR, acc_tol=ACC_NORM_TOL))


def start_rest(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, gravity: float,
               rest: Optional[Tuple[int, int, str]] = None, min_still_s: float = 1.0,
               still: Optional[float] = None) -> Optional[Tuple[int, int, str, float]]:
    """The rest at the start, the one rule the levelling and the navigator's noise at rest share: (first
    sample, end sample, "still" or "aiding", seconds). The IMU's still start (:func:`still_start`; ``still``
    its seconds when already found) at least ``min_still_s`` long; else ``rest`` (first, end, words: a rest
    the aiding shows, :func:`imu_learn.fuse.start.track.rest_from_track`, a car parked with its engine running
    whose vibration no IMU still rule passes) at least ``min_still_s`` long where the IMU's mean readings
    there are a rest's (:func:`_rests`); else None."""
    still = still_start(t_ns, gyro, acc, gravity) if still is None else still
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    if still >= min_still_s:
        return 0, int(np.searchsorted(t, still)), "still", still
    if rest is not None and t[rest[1] - 1] - t[rest[0]] >= min_still_s and _rests(gyro, acc, rest, gravity):
        return rest[0], rest[1], "aiding", float(t[rest[1] - 1] - t[rest[0]])
    return None


def attitude_from_accelerometer(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, gravity: float = 9.81,
                                acc_bias: Optional[np.ndarray] = None, level_s: float = 2.0,
                                min_still_s: float = 1.0, rest: Optional[Tuple[int, int, str]] = None
                                ) -> Tuple[np.ndarray, Dict[str, object]]:
    """(R_WB zero yaw, info): levelled from the mean specific force over the rest at the start
    (:func:`start_rest`: the IMU's still start, else ``rest``, the one the aiding shows), else over the first
    ``level_s`` seconds (module docstring). ``info["levelled_samples"]``: the samples averaged; ``info["rest_from"]``:
    "still", "aiding" or None (moving)."""
    still = still_start(t_ns, gyro, acc, gravity)
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    i = np.arange(len(t))
    span = start_rest(t_ns, gyro, acc, gravity, rest, min_still_s, still)
    if span is None:
        m, source = t < level_s, (f"no still start: accelerometer averaged over the first {level_s:g} s while moving "
                                  "(its own accelerations tilt the estimate)")
    else:
        m = (i >= span[0]) & (i < span[1])
        source = (f"still start ({still:.2f} s at rest, accelerometer averaged over it)" if span[2] == "still" else
                  f"at rest as {rest[2]} ({span[3]:.2f} s, accelerometer averaged over it)")  # type: ignore[index]
    f = acc[m].mean(axis=0) - (np.zeros(3) if acc_bias is None else np.asarray(acc_bias))
    roll, pitch, R = level(f)
    info = {"attitude_source": source, "still_s": round(still, 3), "roll_deg": round(float(np.rad2deg(roll)), 3),
            "pitch_deg": round(float(np.rad2deg(pitch)), 3), "levelled_over_s": round(float(t[m][-1]), 3),
            "levelled_samples": [int(i[m][0]), int(i[m][-1]) + 1], "rest_from": None if span is None else span[2]}
    return R, info
