"""Inertial-aided navigation: fuse an IMU stream (raw, or refined by a checkpoint) with aiding in a
GTSAM factor graph and score the trajectory against ground truth.

* :mod:`.noise`   the IMU's noise densities and random walks (a dataset's ``sensor.yaml`` or the
  config) as GTSAM preintegration parameters;
* :mod:`.aiding`  aiding measurements: real (EuRoC's Leica laser tracker) and simulated from ground
  truth (GNSS-like position, VO-like relative pose), with outages;
* :mod:`.graph`   the factor graph (``CombinedImuFactor`` between keyframes, aiding factors, a
  ground-truth prior on the first state), solved by iSAM2 keyframe by keyframe (causal) and
  refined at the end (smoothed);
* :mod:`.score`   position and rotation RMSE, and the drift inside each outage;
* :mod:`.config`, :mod:`.run` the experiment: recordings x IMU inputs x aiding scenarios
  (``python -m imu_learn.fuse --config configs/fuse_euroc.toml``).
"""
from .aiding import PositionFixes, RelativePoses, apply_outages, leica_fixes, simulate_position, simulate_relative_pose
from .graph import FusionResult, IncrementalFusion, fuse
from .noise import ImuNoise
from .settings import FusionSettings, PriorSigmas

__all__ = [
    "FusionResult", "FusionSettings", "ImuNoise", "IncrementalFusion", "PositionFixes", "PriorSigmas", "RelativePoses", "apply_outages", "fuse", "leica_fixes",
    "simulate_position", "simulate_relative_pose",
]
