"""Heading from a position track, as GNSS/INS filters set it: levelled at a still start, the attitude
carried by the gyro to the first fix fast enough, then turned about z so that the body x-axis points
along the track's velocity (a vehicle moving along its x-axis: a car, a walker's forward axis).
:func:`track_start` from the fixes' own central differences (the navigator's position aiding),
:func:`gnss_start` from an RTKLIB solution's velocities (the GNSS outage experiment)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.core.still import STILL_MAX_SPEED_MPS
from imu_learn.errors import InvalidInputError

from .level import level, rot_z


def track_velocity(t_ns: np.ndarray, fix_idx: np.ndarray, fix_p: np.ndarray
                   ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(fix times [s from the IMU's first sample], velocity (central differences of the fixes; zero with
    fewer than two), horizontal speed) of a position track on the IMU's samples ``fix_idx``."""
    tf = (t_ns[np.asarray(fix_idx, dtype=np.int64)] - int(t_ns[0])) * 1e-9
    v = np.gradient(fix_p, tf, axis=0) if len(tf) >= 2 else np.zeros_like(fix_p)
    return tf, v, np.linalg.norm(v[:, :2], axis=1)


def rest_from_track(t_ns: np.ndarray, fix_idx: np.ndarray, fix_p: np.ndarray,
                    max_speed_mps: float = STILL_MAX_SPEED_MPS) -> Optional[Tuple[int, int, str]]:
    """The IMU samples (first, end) over which the position track shows the platform at rest from its
    first fix (the horizontal speed of the fixes' central differences at most ``max_speed_mps``, a GNSS
    still start's rule) up to the last such fix before it first moves, with words for the summary; None
    where the first fix already moves. A car parked with its engine running vibrates beyond every IMU
    still rule (the drive: 0.7-2.7 deg/s, 0.05-0.13 m/s^2 per sample) while its RTK fixes stand still."""
    fix_idx = np.asarray(fix_idx, dtype=np.int64)
    if len(fix_idx) < 3:
        return None
    tf, _, speed = track_velocity(t_ns, fix_idx, fix_p)
    moving = np.flatnonzero(speed > max_speed_mps)
    last = (int(moving[0]) if len(moving) else len(fix_idx)) - 1
    if last < 1:
        return None
    return int(fix_idx[0]), int(fix_idx[last]) + 1, (f"the position track shows it (fixes {0}-{last}, "
                                                     f"{tf[0]:.2f}-{tf[last]:.2f} s, speed at most {max_speed_mps:g} m/s)")


def track_start(t_ns: np.ndarray, gyro: np.ndarray, fix_idx: np.ndarray, fix_p: np.ndarray, R_level: np.ndarray,
                level_end: int, gyro_bias: np.ndarray, min_speed_mps: float = 1.0,
                forward: Optional[np.ndarray] = None) -> Tuple[int, int, np.ndarray, np.ndarray, Dict[str, object]]:
    """Heading from a position track, as GNSS/INS filters set it (and
    :func:`gnss_start` for the car): the first fix after the levelling
    window (IMU sample ``level_end``) whose horizontal speed (central difference of the fixes)
    exceeds ``min_speed_mps``; the levelled attitude carried there by the gyro (minus ``gyro_bias``),
    then turned about z so that the body x-axis points along the track (a vehicle moving along its
    x-axis: a car, a walker's forward axis), or the body axis ``forward`` (3,) where given (the one the
    track shows, :func:`..mounting.track_forward`). Returns (start sample, fix number, R_WB, v, info)."""
    fix_idx = np.asarray(fix_idx, dtype=np.int64)
    tf, v, speed = track_velocity(t_ns, fix_idx, fix_p)
    moving = (fix_idx >= level_end) & (speed > min_speed_mps)
    if not moving.any():
        raise InvalidInputError(f"position aiding: no fix faster than {min_speed_mps:g} m/s after the levelling window: "
                                "the heading cannot be set from the track")
    e = int(np.flatnonzero(moving)[0])
    s0 = int(fix_idx[e])
    R = Rotation.from_matrix(R_level)
    dt = np.diff(t_ns[level_end:s0 + 1]) * 1e-9
    if len(dt):
        steps = Rotation.from_rotvec((gyro[level_end:s0] - np.asarray(gyro_bias)) * dt[:, None])
        for step in steps:
            R = R * step
    Rm = R.as_matrix()
    ahead = Rm @ (np.eye(3)[0] if forward is None else np.asarray(forward, dtype=np.float64))
    turn = float(np.arctan2(v[e, 1], v[e, 0]) - np.arctan2(ahead[1], ahead[0]))
    R0 = rot_z(turn) @ Rm
    axis = "body x-axis" if forward is None else \
        f"the body axis ({', '.join(f'{x:.3f}' for x in forward)}) the track shows as forward"
    info = {"heading_source": f"the track once moving: fix {e} at {tf[e]:.2f} s, {speed[e]:.2f} m/s (> "
                              f"{min_speed_mps:g}); {axis} along the velocity",
            "start_after_first_sample_s": round(float(tf[e]), 3)}
    return s0, e, R0, v[e].copy(), info


@dataclass(frozen=True)
class GnssStartSettings:
    """:func:`gnss_start`'s: the still start's length ``level_s`` [s] and the GNSS speed it allows
    [m/s]; the speed from which the track gives the heading [m/s]; the antenna's ``lever`` [m], body."""

    level_s: float = 10.0
    still_max_speed_mps: float = STILL_MAX_SPEED_MPS
    yaw_min_speed_mps: float = 1.0
    lever: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    # "track": the run starts at the epoch that gives the heading; "still": at the IMU's first sample
    # (the still start), its heading the track's carried back by the gyro (:func:`gnss_start`)
    start_at: str = "track"


def gnss_start(imu, sol, gravity: float, cfg: GnssStartSettings) -> Dict[str, object]:
    """The start sample, attitude, position, velocity and gyro bias guess of ``imu`` (stamps ``t_ns``,
    ``gyro``, ``acc``) with the RTKLIB solution ``sol``, from the data alone: levelled over the first
    ``level_s`` (checked still against the fixes' speed), carried by the gyro to the first fixed epoch
    faster than ``yaw_min_speed_mps``, turned onto its velocity heading. With ``start_at = "still"``
    the start is the IMU's first sample instead, at rest, levelled and turned by the same angle
    (``heading_s_after_first_epoch``: when the heading became known)."""
    t = imu.t_ns
    n_level = int(np.searchsorted(t, t[0] + int(cfg.level_s * 1e9)))
    if n_level < 10:
        raise InvalidInputError(f"level_s {cfg.level_s} s holds {n_level} IMU samples")
    speed = np.linalg.norm(sol.vel_enu[:, :2], axis=1) if sol.vel_enu is not None else None
    if speed is not None:
        during = (sol.t_ns >= t[0]) & (sol.t_ns <= t[n_level - 1])
        if during.any() and speed[during].max() > cfg.still_max_speed_mps:
            raise InvalidInputError(f"{sol.path}: the first {cfg.level_s} s of the IMU are not still (GNSS speed up "
                                    f"to {speed[during].max():.2f} m/s): lower level_s")
    f_still = imu.acc[:n_level].mean(axis=0)
    R_lvl = level(f_still)[2]
    gyro_still = imu.gyro[:n_level].mean(axis=0)
    # the mean's standard error, counting distinct rows only (a logger faster than its sensor repeats rows)
    distinct = 1 + int(np.any(np.diff(imu.gyro[:n_level], axis=0) != 0, axis=1).sum())
    gyro_still_se = imu.gyro[:n_level].std(axis=0) / math.sqrt(distinct)
    moving = (sol.q == 1) & (sol.t_ns > t[n_level - 1])
    if speed is None:
        raise InvalidInputError(f"{sol.path}: no velocity columns: the heading at the start needs them")
    moving &= speed > cfg.yaw_min_speed_mps
    if not moving.any():
        raise InvalidInputError(f"{sol.path}: no fixed epoch faster than {cfg.yaw_min_speed_mps} m/s after the still "
                                "start")
    e = int(np.flatnonzero(moving)[0])
    s0 = int(np.clip(np.searchsorted(t, sol.t_ns[e]), 0, len(t) - 1))
    # The levelled attitude carried to the start by the gyro (minus the still start's mean rate).
    R = Rotation.from_matrix(R_lvl)
    dt = np.diff(t[n_level - 1:s0 + 1]) * 1e-9
    for w, h in zip(imu.gyro[n_level - 1:s0] - gyro_still, dt):
        R = R * Rotation.from_rotvec(w * h)
    Rm = R.as_matrix()
    v = sol.vel_enu[e]
    heading_body = math.atan2(Rm[1, 0], Rm[0, 0])  # body x-axis, from east towards north
    heading_vel = math.atan2(v[1], v[0])
    R0 = Rotation.from_euler("z", heading_vel - heading_body).as_matrix() @ Rm
    lever = np.asarray(cfg.lever, dtype=np.float64)
    p0 = sol.enu[e] + v * (t[s0] - sol.t_ns[e]) * 1e-9 - R0 @ lever
    heading_s = (int(t[s0]) - int(sol.t_ns[0])) * 1e-9
    if cfg.start_at == "still":
        # The same heading at the still start: the levelled attitude turned as the carried one was. The
        # run then holds the still start and every fix since (position, zero velocity), which tell tilt
        # and a horizontal accelerometer bias apart as the device turns; outputs from the heading's
        # epoch on use no later data.
        R0 = Rotation.from_euler("z", heading_vel - heading_body).as_matrix() @ R_lvl
        first = int(np.argmin(np.abs(sol.t_ns - t[0])))
        s0, v = 0, np.zeros(3)
        p0 = sol.enu[first] - R0 @ lever
    elif cfg.start_at != "track":
        raise InvalidInputError(f"start_at: 'track' or 'still', got {cfg.start_at!r}")
    # At rest the specific force's norm is gravity's: the excess along it is an accelerometer bias
    # (the part the still start can tell; horizontal biases look like tilt there).
    acc_bias_still = (np.linalg.norm(f_still) - gravity) * f_still / np.linalg.norm(f_still)
    return {"s0": s0, "epoch": e, "R0": R0, "p0": p0, "v0": v.copy(), "gyro_still": gyro_still,
            "gyro_still_se": gyro_still_se, "still_distinct_rows": distinct,
            "acc_bias_still": acc_bias_still,
            "start_s_after_first_epoch": (int(t[s0]) - int(sol.t_ns[0])) * 1e-9,
            "heading_s_after_first_epoch": heading_s, "start_at": cfg.start_at,
            "speed_mps": float(speed[e]), "still_samples": n_level,
            "acc_still_std": imu.acc[:n_level].std(axis=0).tolist(),
            "gyro_still_std": imu.gyro[:n_level].std(axis=0).tolist()}
