"""What the factor graph is run with, in one object: the IMU's noise, gravity, the keyframe grid, the
first state's prior and the estimator (:class:`FusionSettings`, taken by
:class:`imu_learn.fuse.graph.IncrementalFusion` and :func:`imu_learn.fuse.graph.fuse`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Tuple, Union

import numpy as np

from imu_learn.errors import InvalidInputError

from .noise import ImuNoise

# The causal estimate's window [s] (keyframes this recent stay in the fixed-lag smoother): chosen by
# measurement (docs/experiments/scale.md). Shorter windows cost less per update; a window shorter than the gap
# between fixes marginalises states no fix has corrected yet (their prior is then the IMU's alone).
DEFAULT_LAG_S = 10.0
# [s] The first seconds stay in the window whatever the lag: attitude and bias are still settling
# there, and marginalised at those estimates they stay wrong in the prior on the window (EuRoC V1_01
# with 1 Hz fixes and a 30 s outage: causal RMSE 6.1 m with lag 10 s from the start, 2.87 m as the
# whole graph with the first 30 s held).
SETTLE_S = 30.0
# The smoothed estimate: "batch", Levenberg-Marquardt over the whole graph (every factor kept: memory
# and time linear, docs/experiments/scale.md); "window", each keyframe's last estimate in the fixed-lag window
# (no graph kept, no batch pass).
SMOOTHING = ("batch", "window")


@dataclass(frozen=True)
class PriorSigmas:
    """The first state's prior: pose and velocity from ground truth (tight), bias zero (loose). The
    bias sigmas are one value for every axis or three, per body axis (a device profile's per-recording
    spread: :func:`imu_learn.fuse.start.prior.profile_bias_sigmas`)."""

    rot_rad: float = 1e-3
    pos_m: float = 1e-3
    vel_mps: float = 1e-2
    bias_gyro: Union[float, Tuple[float, float, float]] = 0.1  # rad/s: EuRoC's ADIS16448 starts with up to ~0.08 rad/s
    bias_acc: Union[float, Tuple[float, float, float]] = 0.5  # m/s^2
    # When set: heading [rad] apart from roll/pitch (rot_rad), both in the navigation frame (a levelled
    # start whose heading is less known than its tilt); None: rot_rad about every body axis.
    yaw_rad: Optional[float] = None

    def bias_sigmas(self) -> np.ndarray:
        """(6,) the first bias's sigmas in GTSAM's order: accelerometer (m/s^2), then gyro (rad/s), per axis."""
        return np.r_[np.broadcast_to(np.asarray(self.bias_acc, dtype=np.float64), (3,)),
                     np.broadcast_to(np.asarray(self.bias_gyro, dtype=np.float64), (3,))]

    def pose_noise(self, R0: np.ndarray, gtsam):
        """The first pose's prior noise model (GTSAM's Pose3 tangent: body rotation, then position)."""
        if self.yaw_rad is None:
            return gtsam.noiseModel.Diagonal.Sigmas(np.r_[[self.rot_rad] * 3, [self.pos_m] * 3])
        R0 = np.asarray(R0, dtype=np.float64)
        cov = np.diag(np.r_[[self.rot_rad ** 2] * 2, self.yaw_rad ** 2, [self.pos_m ** 2] * 3])
        cov[:3, :3] = R0.T @ cov[:3, :3] @ R0  # R = R0 Exp(xi): a world-frame angle is R0 xi
        return gtsam.noiseModel.Gaussian.Covariance(cov)


@dataclass(frozen=True)
class FusionSettings:
    """The graph's settings. ``noise``: the IMU's datasheet noise (per-sample variances, when a run
    has them, replace its white noise); ``gravity`` [m/s^2], z up; ``keyframe_hz``: the keyframe grid
    beside the aiding's own samples; ``prior``: the first state's; ``iterations``: iSAM2 steps at each
    aiding epoch (1 + relinearising extra updates); ``resolve_after_s``: after a coast longer than
    this, the graph so far (or the fixed-lag window and the coast) is re-solved in batch;
    ``lag_s``: the causal estimate's fixed-lag window (inf: iSAM2 over the whole graph);
    ``smoothing``: one of :data:`SMOOTHING`."""

    noise: ImuNoise = field(default_factory=ImuNoise)
    gravity: float = 9.81
    keyframe_hz: float = 10.0
    prior: PriorSigmas = field(default_factory=PriorSigmas)
    iterations: int = 1
    resolve_after_s: float = 2.0
    lag_s: float = DEFAULT_LAG_S
    smoothing: str = "batch"

    def __post_init__(self) -> None:
        if self.smoothing not in SMOOTHING:
            raise InvalidInputError(f"smoothing: one of {', '.join(SMOOTHING)}, got {self.smoothing!r}")
        if not float(self.lag_s) > 0:
            raise InvalidInputError(f"lag_s: the fixed-lag window must be > 0 s (inf: the whole graph), got {self.lag_s}")
