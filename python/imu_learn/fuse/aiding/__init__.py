"""Aiding for the factor graph, each measurement tied to an IMU sample:

* :mod:`.types`: the measurement types (position fixes, GNSS fixes with per-fix sigmas, relative and
  absolute poses, poses in the aiding's own world), each with ``select`` and ``since``, the samples it ties (``tied_samples``) and its
  factors for the graph (``factors_by_sample``);
* :mod:`.kinds`: each ``--aiding-kind`` of the navigator as one class (what its rows carry, its start,
  its sigma options, the aiding it builds); not imported here (it uses :mod:`imu_learn.fuse.start`);
* :mod:`.sampling`: the time rules tying a stamp to an IMU sample, and the epoch grid;
* :mod:`.simulate`: aiding simulated from ground truth; :mod:`.real`: the Leica and bag-topic fixes;
* :mod:`.outages`: the one outage window type, and aiding without the measurements inside;
* readers: :mod:`.tum` (trajectory files), :mod:`.rtklib` (RTKLIB solutions), :mod:`.bag` (ROS bag
  topics: poses, positions, NavSatFix fixes), :mod:`.detect`
  tells from a file's content which reader it takes.
"""
from .outages import OutageWindow, apply_outages, clip_outages, outage_mask
from .real import bag_position_source, leica_fixes
from .sampling import epochs, snap_to_samples
from .simulate import simulate_position, simulate_relative_pose
from .types import (
    AbsolutePoses,
    Aiding,
    GnssFixes,
    PositionFixes,
    RelativePoses,
    aiding_gaps,
    aiding_samples,
    check_aiding,
)

__all__ = [
    "AbsolutePoses", "Aiding", "GnssFixes", "OutageWindow", "PositionFixes", "RelativePoses", "aiding_gaps",
    "aiding_samples", "apply_outages", "bag_position_source", "check_aiding", "clip_outages", "epochs", "leica_fixes",
    "outage_mask", "simulate_position", "simulate_relative_pose", "snap_to_samples",
]
