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
from importlib import import_module
from typing import Any

# the names below, each imported from its module when first used (a reader under this package, as
# calibrate's positions source uses, does not import the simulation's scipy.spatial)
_HOME = {"OutageWindow": ".outages", "apply_outages": ".outages", "clip_outages": ".outages", "outage_mask": ".outages",
         "bag_position_source": ".real", "leica_fixes": ".real", "epochs": ".sampling", "snap_to_samples": ".sampling",
         "simulate_position": ".simulate", "simulate_relative_pose": ".simulate", "AbsolutePoses": ".types",
         "Aiding": ".types", "GnssFixes": ".types", "PositionFixes": ".types", "RelativePoses": ".types",
         "aiding_gaps": ".types", "aiding_samples": ".types", "check_aiding": ".types"}


def __getattr__(name: str) -> Any:
    if name in _HOME:
        return getattr(import_module(_HOME[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "AbsolutePoses", "Aiding", "GnssFixes", "OutageWindow", "PositionFixes", "RelativePoses", "aiding_gaps",
    "aiding_samples", "apply_outages", "bag_position_source", "check_aiding", "clip_outages", "epochs", "leica_fixes",
    "outage_mask", "simulate_position", "simulate_relative_pose", "snap_to_samples",
]
