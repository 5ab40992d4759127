"""Plain containers for IMU data, ground truth and aligned sequences.

Quaternions are Hamilton, body(IMU) -> world. The core and these classes store them w,x,y,z and
say so in the name (``q_wxyz``); ``Segment.q_xyzw`` converts through :func:`imu_learn.core.quat.wxyz_to_xyzw`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from imu_learn.core.quat import wxyz_to_xyzw
from imu_learn.core.stamps import median_period_ns, sample_rate_hz  # noqa: F401  (the one sample-rate rule)


@dataclass(frozen=True)
class ImuData:
    """Raw IMU samples: ``t_ns`` (N,) int64; ``gyro`` [rad/s] and ``acc`` [m/s^2] (N, 3) float64."""

    t_ns: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass(frozen=True)
class GroundTruth:
    """Poses on their own stamps; ``v`` is None for pose-only sources (alignment derives it)."""

    t_ns: np.ndarray
    p: np.ndarray
    q_wxyz: np.ndarray
    v: Optional[np.ndarray] = None

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass(frozen=True)
class Segment:
    """IMU samples with ground truth interpolated onto the same stamps (one gap-free segment)."""

    name: str
    t_ns: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray
    p: np.ndarray
    v: np.ndarray
    q_wxyz: np.ndarray

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def q_xyzw(self) -> np.ndarray:
        return wxyz_to_xyzw(self.q_wxyz)

    @property
    def duration_s(self) -> float:
        return float(self.t_ns[-1] - self.t_ns[0]) * 1e-9 if len(self) else 0.0


@dataclass(frozen=True)
class Recording:
    """A loaded recording: its gap-free segments and what alignment dropped."""

    name: str
    segments: list
    report: dict = field(default_factory=dict)
