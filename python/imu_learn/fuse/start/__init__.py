"""A run's first state, one type for every way of finding it (:class:`~.types.Start`):

* :mod:`.types`: the type, and the controlled start from ground truth;
* :mod:`.level`: roll and pitch levelled from the accelerometer (at rest, or over the first
  seconds), gravity from pose aiding;
* :mod:`.aiding`: the navigator's start from its aiding (pose aiding's first pose; position aiding's
  track);
* :mod:`.track`: heading from a position track (the fixes', or a GNSS solution's velocities);
* :mod:`.data`: the experiments' start from the data (a rest after the start, yaw hypotheses over
  the first fixes, a gauge for relative aiding).
"""
from .types import Start, groundtruth_start

__all__ = ["Start", "groundtruth_start"]
