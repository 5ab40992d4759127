"""Quaternion order conversions: the one place the project reorders quaternion components."""
from __future__ import annotations

import numpy as np


def xyzw_to_wxyz(q_xyzw: np.ndarray) -> np.ndarray:
    """x,y,z,w (TUM, ROS, scipy) -> w,x,y,z (imu_learn, ASL CSV, GTSAM); works on (..., 4)."""
    q = np.asarray(q_xyzw)
    return np.concatenate([q[..., 3:4], q[..., 0:3]], axis=-1)


def wxyz_to_xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    """w,x,y,z -> x,y,z,w; works on (..., 4)."""
    q = np.asarray(q_wxyz)
    return np.concatenate([q[..., 1:4], q[..., 0:1]], axis=-1)
