"""Synthetic recordings with a known answer: closed-form trajectories, their exact IMU, a Fetch
recorder's files, and an independent quaternion oracle (numpy only).

The tests check the package against these, and bench/bench_scale.py builds its long recordings
from them. Deliberately not imu_learn.core.quat: rotation here is the sandwich product q (0, v) q*
built on a plain Hamilton product, so the package's algebra is not checked against itself.
Quaternions are w,x,y,z; stamps are exact 200 Hz nanoseconds.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_learn.data.types import Segment

G = 9.81
RATE = 200.0
DT_NS = 5_000_000  # 200 Hz, exactly
DT = DT_NS * 1e-9
AXIS = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)


def stamps(seconds: float) -> np.ndarray:
    n = int(round(seconds * RATE)) + 1
    return 10**18 + np.arange(n, dtype=np.int64) * DT_NS


def qconj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q) v via the quaternion sandwich q (0, v) q*."""
    qv = np.concatenate([np.zeros(v.shape[:-1] + (1,)), v], -1)
    return qmul(qmul(q, qv), qconj(q))[..., 1:]


def axis_angle(axis, angle) -> np.ndarray:
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    angle = np.asarray(angle, dtype=np.float64)
    return np.concatenate([np.cos(angle / 2)[..., None], np.sin(angle / 2)[..., None] * axis], -1)


def spin(seconds: float = 20.0, rate: float = 0.7, axis=AXIS) -> Segment:
    """Constant body rate ``rate`` about a fixed axis, at rest at the origin, with its closed-form
    IMU: gyro = rate·axis, acc = Rᵀ [0, 0, g] (exact under the zero-order hold)."""
    t_ns = stamps(seconds)
    t = (t_ns - t_ns[0]) * 1e-9
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    q = axis_angle(axis, rate * t)
    z = np.zeros((len(t), 3))
    gyro = np.tile(rate * axis, (len(t), 1))
    acc = rotate(qconj(q), np.tile([0.0, 0.0, G], (len(t), 1)))
    return Segment("spin", t_ns, gyro, acc, z, z.copy(), q)


def moving(seconds: float = 20.0, cubic=(0.0, 0.0, 0.0)) -> Segment:
    """Wobbling rotation about a drifting axis and a quadratic (+ optional cubic) position curve with
    its exact derivative as velocity. No IMU (zeros): synthesise one to suit the test."""
    t_ns = stamps(seconds)
    t = (t_ns - t_ns[0]) * 1e-9
    q = qmul(axis_angle([0.0, 0.0, 1.0], 0.5 * t + 0.3 * np.sin(0.8 * t)),
             axis_angle([1.0, -1.0, 0.0], 0.2 * np.sin(1.3 * t)))
    p0, v0, a0, c = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -0.2]), np.array([0.05, -0.08, 0.02]), np.array(cubic)
    tt = t[:, None]
    p = p0 + v0 * tt + 0.5 * a0 * tt**2 + c * tt**3
    v = v0 + a0 * tt + 3 * c * tt**2
    z = np.zeros((len(t), 3))
    return Segment("moving", t_ns, z, z.copy(), p, v, q)


def spin_and_climb(n=2000, dt_ns=5_000_000, w=0.5, a=0.2, g=9.81):
    """Yaw at w rad/s about the gravity axis while climbing with a [m/s^2]: body-frame gyro and
    specific force are constant, so zero-order-hold preintegration is exact; closed-form pose.
    Returns t [ns] from 0, gyro, acc, p (n, 3) and body-to-world matrices R (n, 3, 3)."""
    t = np.arange(n, dtype=np.int64) * dt_ns
    ts = t * 1e-9
    gyro = np.tile([0.0, 0.0, w], (n, 1))
    acc = np.tile([0.0, 0.0, g + a], (n, 1))
    p = np.c_[np.zeros(n), np.zeros(n), 0.5 * a * ts**2]
    c, s = np.cos(w * ts), np.sin(w * ts)
    R = np.zeros((n, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return t, gyro, acc, p, R


# ---- the Fetch (Debias_IMU) recorder's layout ----------------------------------------------

FETCH_T0 = 1691116804753040896  # Fetch recordings: a float64 (multiple of 256 ns at this epoch)
IMU_HEADER = "# timestamp, wx, wy, wz, ax, ay, az"
MOCAP_HEADER = "# timestamp, x, y, z, qw, qx, qy, qz"


def fetch_row(t: float, vals) -> str:
    return ",".join(f"{x:.18e}" for x in [t, *vals])


def write_fetch_recording(root: Path, seconds: float = 4.0, name: str = "01_crop") -> Path:
    """A recording of a robot turning at 0.5 rad/s about z: IMU at 100 Hz, mocap at ~90 Hz, both
    with float64 stamps printed as the recorder prints them."""
    rec = root / name if name else root
    (rec / "mav0" / "imu0").mkdir(parents=True)
    (rec / "mav0" / "mocap0").mkdir(parents=True)
    w = 0.5
    t_imu = FETCH_T0 + np.arange(int(seconds * 100)) * 10_000_000
    imu = [fetch_row(float(t), [0.0, 0.0, w, 0.0, 0.0, 9.81]) for t in t_imu]
    (rec / "mav0" / "imu0" / "data.csv").write_text("\n".join([IMU_HEADER] + imu) + "\n")
    t_gt = FETCH_T0 - 50_000_000 + np.arange(int((seconds + 0.2) * 90)) * 11_111_111
    mocap = []
    for t in t_gt:
        a = w * (t - FETCH_T0) * 1e-9
        mocap.append(fetch_row(float(t), [0.0, 0.0, 0.36, np.cos(a / 2), 0.0, 0.0, np.sin(a / 2)]))
    (rec / "mav0" / "mocap0" / "data.csv").write_text("\n".join([MOCAP_HEADER] + mocap) + "\n")
    return rec
