"""Inertial-aided navigation: fuse an IMU stream (raw, or refined by a checkpoint) with aiding in a
GTSAM factor graph, and score the trajectory. One home per concern:

* :mod:`.settings`  what the graph runs with (:class:`FusionSettings`: noise, gravity, keyframes, the
  first state's prior, the estimator); :mod:`.noise` the IMU's noise densities;
* :mod:`.graph`     the factor graph (:class:`IncrementalFusion`, causal iSAM2 / fixed-lag and the
  smoothing pass) and the one loop over its samples (:func:`~.graph.feed`, :func:`fuse`);
* :mod:`.factors`   factors beyond the IMU and the aiding, through one hook (NHC, learned
  displacements, GNSS velocities);
* :mod:`.aiding`    the measurement types, the time rules, simulation, real fixes, outages, the
  readers (TUM, RTKLIB, bag topics, extrinsics) and the one aiding-format detector;
* :mod:`.geo`       a local ENU track back to WGS-84, and its CSV, KML and GeoJSON files;
* :mod:`.inputs`    an IMU input by name or file: samples, variances, displacement hook;
* :mod:`.start`     the first state (one type): ground truth, from the data, from the aiding;
* :mod:`.score`     every score; :mod:`.output` every file written (trajectories, results, plots);
* :mod:`.navigate`  a user's recording with its aiding file (``imu-learn navigate``);
* :mod:`.experiments` the experiments of a config (``imu-learn fuse --config``): batch, online,
  GNSS outages;
* :mod:`.variance`  a covariance head's variances calibrated over the keyframe interval.

GTSAM (the ``fuse`` extra) is imported where the graph is built.
"""
from .aiding import PositionFixes, RelativePoses, apply_outages, leica_fixes, simulate_position, simulate_relative_pose
from .graph import FusionResult, IncrementalFusion, fuse
from .noise import ImuNoise
from .settings import FusionSettings, PriorSigmas

__all__ = [
    "FusionResult", "FusionSettings", "ImuNoise", "IncrementalFusion", "PositionFixes", "PriorSigmas", "RelativePoses", "apply_outages", "fuse", "leica_fixes",
    "simulate_position", "simulate_relative_pose",
]
