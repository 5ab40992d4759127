"""The navigator's first state from its aiding, no ground truth: pose aiding levels its world with
gravity seen in it and takes the first pose's heading (:func:`pose_start`); position aiding takes the
heading from the track once moving (:func:`position_start`)."""
from __future__ import annotations

import logging
from typing import Optional

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.core.still import MIN_STILL_START_S

from ..aiding.types import AidingRows
from ..mounting import MOUNT_TOL_DEG, angle_between_deg, track_forward
from . import level as initial
from .track import rest_from_track, track_start
from .types import Start

log = logging.getLogger(__name__)


def pose_start(t_ns, gyro, acc, rows: AidingRows, s0: int, bias0: np.ndarray, gravity: float, level_s: float
               ) -> Start:
    """Sample ``s0``'s state from the data and pose (or position) aiding ``rows``: roll and pitch from
    gravity in the aiding's frame (:func:`.level.gravity_in_aiding`), heading from the first pose,
    position and velocity from the first rows (zero velocity on a still start)."""
    R_level, info = initial.attitude_from_accelerometer(t_ns[s0:], gyro[s0:], acc[s0:], gravity,
                                                        acc_bias=bias0[3:], level_s=level_s)
    if rows.R is not None:
        # gravity in the aiding's frame from the first seconds (the aiding's own acceleration removed):
        # works while moving, where the accelerometer alone is tilted by the motion
        up_A, g_info = initial.gravity_in_aiding(t_ns[s0:], acc[s0:] , rows.t_ns, rows.p, rows.R,
                                                 window_s=max(level_s, 3.0), acc_bias=bias0[3:])
        R_WA, R_WB = initial.level_aiding(up_A, rows.R[0])
        info["accelerometer_only"] = {k: info.pop(k) for k in ("attitude_source", "roll_deg", "pitch_deg",
                                                               "levelled_over_s")}
        tilt = np.degrees(np.arccos(np.clip((R_WB.T @ [0, 0, 1]) @ (R_level.T @ [0, 0, 1]), -1, 1)))
        info.update(g_info)
        info["accelerometer_only"]["tilt_difference_deg"] = round(float(tilt), 3)
        info["heading_source"] = "the first aiding pose's yaw (moved into the IMU frame with the extrinsic)"
    else:
        R_WA, R_WB = np.eye(3), R_level
        info["heading_source"] = ("none yet (position-only aiding): zero yaw under a loose prior; the fixes resolve it "
                                  "once the track moves")
    p_W = rows.p @ R_WA.T
    t_rel = (rows.t_ns - rows.t_ns[0]) * 1e-9
    if info["still_s"] >= MIN_STILL_START_S:
        v = np.zeros(3)
        info["velocity_source"] = "zero (still start)"
    else:
        k = int(np.searchsorted(t_rel, 0.2))
        k = min(max(k, 1), len(t_rel) - 1)
        v = (p_W[k] - p_W[0]) / max(t_rel[k], 1e-3)
        info["velocity_source"] = f"aiding finite difference over the first {t_rel[k]:.2f} s"
    info["position_source"] = "the first aiding row"
    info["R_WA_deg_from_identity"] = round(float(np.rad2deg(Rotation.from_matrix(R_WA).magnitude())), 3)
    return Start(s0, s0, R_WB, p_W[0], v, bias0, info=info, R_WA=R_WA)


def position_start(t_ns, gyro, acc, rows: AidingRows, lever: np.ndarray, bias0: np.ndarray, gravity: float,
                   level_s: float, body_x_forward: bool = False) -> Start:
    """The first state for position-only aiding ``rows``: levelled at the IMU's start, heading from the
    track once moving (:func:`.track.track_start`), where the run starts. The track's heading goes to the
    body's x-axis where ``body_x_forward`` (``--nhc``: the mounting checked, :func:`..mounting.mounting_check`)
    or where the track shows no other forward axis; else to the one it shows (:func:`..mounting.track_forward`:
    a car's IMU mounted backwards, a walker's turned 90 deg, would otherwise start that far off), with a
    warning naming ``--imu-rotation-rpy-deg``."""
    rest = rest_from_track(t_ns, rows.sample, rows.p)
    R_level, info = initial.attitude_from_accelerometer(t_ns, gyro, acc, gravity, acc_bias=bias0[3:],
                                                        level_s=level_s, min_still_s=MIN_STILL_START_S, rest=rest)
    first, level_end = info["levelled_samples"]
    # the gyro's mean at rest (the IMU's still start, or the rest the track shows) is its bias: used to carry the
    # attitude to the start
    gb = gyro[first:level_end].mean(axis=0) if info["rest_from"] is not None else bias0[:3]
    forward = None if body_x_forward else forward_axis(t_ns, acc, rows, gravity, info)
    s0, e, R0, v0, h_info = track_start(t_ns, gyro, rows.sample, rows.p, R_level, level_end, gb, forward=forward)
    info.update(h_info)
    info["velocity_source"] = "the track's central difference at the first fast fix"
    info["position_source"] = "the first fast fix (minus the lever arm)"
    return Start(s0, s0, R0, rows.p[e] - R0 @ lever, v0, bias0, info=info)


def forward_axis(t_ns, acc, rows: AidingRows, gravity: float, info: dict) -> Optional[np.ndarray]:
    """The body axis the track shows as forward (:func:`..mounting.track_forward`) where it is more than
    :data:`..mounting.MOUNT_TOL_DEG` from the body's x-axis (one warning line), else None (the x-axis);
    ``info["forward_axis"]`` says which."""
    shown = track_forward(t_ns, acc, rows.t_ns, rows.p, gravity)
    entry = {k: v for k, v in shown.items() if k not in ("forward", "estimate")}
    info["forward_axis"] = entry
    if not shown["shown"]:
        entry["used"] = "the body's x-axis (the track shows no forward axis)"
        return None
    forward = shown["forward"]
    angle = angle_between_deg(np.eye(3)[0], forward)
    entry["angle_from_x_deg"] = round(angle, 2)
    if angle <= MOUNT_TOL_DEG:
        entry["used"] = "the body's x-axis (the track's forward axis is within the tolerance)"
        return None
    entry["used"] = "the track's forward axis"
    rpy = ", ".join(f"{x:g}" for x in shown["estimated_rpy_deg"])
    log.warning(f"the body's x-axis is {angle:.0f} deg from the axis the track moves along (a mounting of roll, pitch, "
                f"yaw {rpy} deg estimated, a z-up body; roll + 180 for a z-down one): the heading at the start puts "
                "that axis along the track; give "
                "--imu-rotation-rpy-deg R,P,Y for the body frame you mean (with --nhc it is required)")
    return forward
