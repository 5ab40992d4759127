"""The IMU's mounting in a wheeled vehicle, from the data: the forward axis the track shows
(:func:`forward_mounting`, used by ``imu-learn calibrate`` against positions where no mounting is given)
and the check of a given one against it (:func:`mounting_check`, ``imu-learn navigate --nhc``: the
constraint holds the body's sideways and vertical velocity at zero, so a body frame turned off the
vehicle's wrecks the track without a word; a car's log navigated unmounted ran up to 131 m off at the
ends of its outages)."""
from __future__ import annotations

import math
from typing import Any, Dict, Optional

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.errors import InvalidInputError

MOUNT_TOL_DEG = 20.0  # a given forward axis this far from the track's: named in a warning
# The track shows a forward axis where the levelled specific force follows its accelerations with a gain
# of this much at least (a car 1.05, a hand-held walk 0.39; a drone, whose body turns apart from its track,
# 0.05-0.09 on EuRoC's flights) and the axis' yaw is this well determined [deg] (car 0.3, walk 3.2).
TRACK_MIN_GAIN = 0.25
TRACK_MAX_ANGLE_STD_DEG = 10.0


def forward_mounting(t_ns: np.ndarray, acc: np.ndarray, fix_t_ns: np.ndarray, fix_p: np.ndarray,
                     gravity: float = 9.81, level_s: float = 2.0, min_speed: float = 3.0) -> Dict[str, Any]:
    """The IMU's mounting estimated without a reference attitude: up = the mean specific force over the
    first ``level_s`` (the vehicle at rest or cruising), forward = the horizontal direction in which the
    levelled specific force follows the track's along-track acceleration (plus gravity along the
    grade) while its left follows the cross-track one (speed times the turn rate), by least squares
    over the fixes faster than ``min_speed``. Returns {"rpy_deg": roll, pitch, yaw of the body frame
    (x forward, z up) relative to the IMU frame (the navigator's ``--imu-rotation-rpy-deg``),
    "forward_imu", "up_imu", "fit_residual_mps2", "fixes_used"}."""
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    tf = (np.asarray(fix_t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    up = np.mean(acc[t <= t[0] + level_s], axis=0)
    up = up / np.linalg.norm(up)
    R_lev = _level_rotation(up)  # IMU -> a gravity-aligned frame (z up)
    # the track: velocity and acceleration by central differences
    v = np.gradient(fix_p, tf, axis=0)
    a = np.gradient(v, tf, axis=0)
    speed = np.linalg.norm(v[:, :2], axis=1)
    heading = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
    rate = np.gradient(heading, tf)
    along = np.einsum("ij,ij->i", a[:, :2], v[:, :2]) / np.maximum(speed, 1e-9) + gravity * v[:, 2] / np.maximum(speed, 1e-9)
    cross = speed * rate
    # the IMU's levelled horizontal specific force, averaged over +-0.25 s around each fix
    f = acc @ R_lev.T
    c = np.concatenate([np.zeros((1, 3)), np.cumsum(f, axis=0)])
    i0 = np.searchsorted(t, tf - 0.25)
    i1 = np.searchsorted(t, tf + 0.25)
    ok = (speed > min_speed) & (i1 - i0 > 2) & (tf > t[0]) & (tf < t[-1])
    ok[:2] = ok[-2:] = False
    if ok.sum() < 20:
        raise InvalidInputError(f"positions: {int(ok.sum())} fixes faster than {min_speed:g} m/s; the IMU's forward "
                                "axis cannot be found from the track: give the mounting with --imu-rotation-rpy-deg R,P,Y")
    fh = (c[i1[ok]] - c[i0[ok]])[:, :2] / (i1[ok] - i0[ok])[:, None]
    A = np.block([[along[ok][:, None], -cross[ok][:, None]], [cross[ok][:, None], along[ok][:, None]]])
    y = np.concatenate([fh[:, 0], fh[:, 1]])
    cs, *_ = np.linalg.lstsq(A, y, rcond=None)
    res = float(np.sqrt(np.mean((A @ cs - y) ** 2)))
    gain = float(np.hypot(cs[0], cs[1]))  # 1: the specific force is the track's acceleration
    # the forward axis' yaw: its standard deviation from the fit's residual
    angle_std_deg = math.degrees(res / max(gain * float(np.sqrt(np.sum(A ** 2) / 2)), 1e-12))
    fwd_l = np.array([cs[0], cs[1], 0.0]) / max(np.hypot(cs[0], cs[1]), 1e-12)
    fwd = R_lev.T @ fwd_l
    M = np.stack([fwd, np.cross(up, fwd), up])  # body = M imu: x forward, y left, z up
    yaw, pitch, roll = Rotation.from_matrix(M.T).as_euler("ZYX", degrees=True)
    return {"rpy_deg": [float(roll), float(pitch), float(yaw)], "forward_imu": fwd.tolist(), "up_imu": up.tolist(),
            "fit_residual_mps2": res, "gain": gain, "angle_std_deg": angle_std_deg,
            "fixes_used": int(ok.sum())}


def _level_rotation(up: np.ndarray) -> np.ndarray:
    """A rotation taking ``up`` (unit) onto +z."""
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(up, z), float(up @ z)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


def mounting_check(t_ns: np.ndarray, acc_imu: np.ndarray, fix_t_ns: np.ndarray, fix_p: np.ndarray,
                   mounting: Optional[np.ndarray], gravity: float = 9.81) -> Dict[str, Any]:
    """The body's forward axis as given (``mounting``: body = M imu; None: the IMU's own x) against the one
    the track shows (:func:`forward_mounting` on the IMU's specific force ``acc_imu`` in its own frame,
    stamps ``t_ns`` with the delay applied): {"checked", "angle_deg", "estimated_rpy_deg", "ok"} (``ok``
    false beyond :data:`MOUNT_TOL_DEG`); not checked where the track is too slow to show it."""
    try:
        est = forward_mounting(t_ns, acc_imu, fix_t_ns, fix_p, gravity)
    except InvalidInputError as e:
        return {"checked": False, "why": str(e)}
    given = np.eye(3)[0] if mounting is None else np.asarray(mounting, dtype=np.float64)[0]
    angle = angle_between_deg(given, est["forward_imu"])
    return {"checked": True, "angle_deg": round(angle, 2), "estimated_rpy_deg": [round(x, 2) for x in est["rpy_deg"]],
            "ok": angle <= MOUNT_TOL_DEG, "tolerance_deg": MOUNT_TOL_DEG}


def angle_between_deg(a: Any, b: Any) -> float:
    """The angle [deg] between two directions (any lengths): a given forward axis and the track's."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return math.degrees(math.acos(float(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1.0, 1.0))))


def track_forward(t_ns: np.ndarray, acc: np.ndarray, fix_t_ns: np.ndarray, fix_p: np.ndarray, gravity: float = 9.81,
                  min_speed: float = 1.0) -> Dict[str, Any]:
    """The forward axis a position track shows in the frame of ``acc`` (:func:`forward_mounting` over the
    fixes faster than ``min_speed``), where the track shows one: a vehicle or walker moving along a body
    axis (gain at least :data:`TRACK_MIN_GAIN`, yaw within :data:`TRACK_MAX_ANGLE_STD_DEG`); a drone
    turning apart from its track shows none. {"shown": bool, "forward": (3,) or None, "why", the
    estimate's figures; where shown, "estimate": :func:`forward_mounting`'s own}."""
    try:
        est = forward_mounting(t_ns, acc, fix_t_ns, fix_p, gravity, min_speed=min_speed)
    except InvalidInputError as e:
        return {"shown": False, "forward": None, "why": str(e)}
    figures = {"gain": round(est["gain"], 3), "angle_std_deg": round(est["angle_std_deg"], 2),
               "fixes_used": est["fixes_used"], "estimated_rpy_deg": [round(x, 2) for x in est["rpy_deg"]]}
    if est["gain"] < TRACK_MIN_GAIN or est["angle_std_deg"] > TRACK_MAX_ANGLE_STD_DEG:
        return {"shown": False, "forward": None, **figures,
                "why": f"the specific force does not follow the track along one body axis (gain {est['gain']:.2f}, "
                       f"at least {TRACK_MIN_GAIN:g}; yaw +-{est['angle_std_deg']:.1f} deg, at most "
                       f"{TRACK_MAX_ANGLE_STD_DEG:g})"}
    return {"shown": True, "forward": np.asarray(est["forward_imu"], dtype=np.float64), **figures, "why": "",
            "estimate": est}


def mounting_from_track(t_ns: np.ndarray, acc: np.ndarray, fix_t_ns: np.ndarray, fix_p: np.ndarray,
                        gravity: float = 9.81, need_forward: bool = False) -> Dict[str, Any]:
    """The mounting calibrate's navigator passes take where none is given: :func:`forward_mounting` over
    the fixes faster than 3 m/s where the track has enough of them (a car); else the forward axis the
    slower track shows (:func:`track_forward` over 1 m/s, with its gain and yaw checks: a walker, a slow
    ground robot), up from the accelerometer's start; else, where the track shows none, the IMU's own axes
    (roll, pitch, yaw 0: the navigator's start then heads the axis its own rule finds), refused where
    ``need_forward`` (``--nhc`` holds the body's sideways velocity at zero). {"rpy_deg", "from", the
    estimate's figures}."""
    try:
        return {**forward_mounting(t_ns, acc, fix_t_ns, fix_p, gravity), "from": "estimated from the track (fixes over 3 m/s)"}
    except InvalidInputError as fast:
        slow = track_forward(t_ns, acc, fix_t_ns, fix_p, gravity)
        figures = {k: v for k, v in slow.items() if k not in ("forward", "shown", "why", "estimate")}
        if slow["shown"]:
            return {**slow["estimate"], "from": "estimated from the track (fixes over 1 m/s; fewer than 20 over 3)"}
        if need_forward:
            raise InvalidInputError(f"{fast}; nor over 1 m/s: {slow['why']}") from None
        return {**figures, "rpy_deg": [0.0, 0.0, 0.0], "why": slow["why"],
                "from": "the IMU's own axes: the track shows no forward axis"}
