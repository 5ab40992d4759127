"""Real position fixes on the IMU's clock: EuRoC's Leica MS50 laser tracker (a prism's position, 20 Hz;
lever arm from its ``sensor.yaml``; read strictly by :func:`imu_learn.data.formats.asl.read_leica`) and a
ROS bag's position or pose topic, each snapped to the nearest IMU sample by the time rules of
:mod:`.sampling`."""
from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

from imu_learn.data.formats.rosbag import read_positions
from imu_learn.errors import AidingError, AidingOverlapError, InvalidInputError

from .sampling import snap_to_samples
from .types import PositionFixes


def _span(t0: int, t1: int) -> str:
    return f"[{t0}, {t1}] ns ({(t1 - t0) * 1e-9:.3f} s)"


def leica_fixes(leica_t_ns, leica_p, lever, imu_t_ns, rate_hz: Optional[float], sigma_m: float,
                source: str = "") -> PositionFixes:
    """Real laser-tracker fixes on the IMU's clock: each tied to the nearest IMU sample (module
    docstring: fixes outside the IMU's span or without a sample within half a period are dropped
    and counted on the result), then thinned to at most one per ``1/rate_hz`` s (all when
    ``rate_hz`` is None). ``source``: the file the fixes were read from, for messages (row i of the
    arrays is line i + 2 of an ASL file). Raises :class:`AidingError` when there are no fixes and
    :class:`AidingOverlapError` when none lies inside the IMU's time span."""
    imu_t_ns = np.asarray(imu_t_ns, dtype=np.int64)
    leica_t_ns = np.asarray(leica_t_ns, dtype=np.int64)
    leica_p = np.asarray(leica_p, dtype=np.float64)
    rate = "20 Hz" if rate_hz is None else f"{rate_hz:g} Hz"
    label = f"Leica MS50 (real) {rate}, sigma {sigma_m:g} m"
    where = f"{source}: " if source else ""
    if leica_t_ns.ndim != 1 or leica_p.shape != (len(leica_t_ns), 3):
        raise InvalidInputError(f"{where}Leica stamps (N,) and positions (N, 3) expected, got "
                                f"{leica_t_ns.shape} and {leica_p.shape}")
    if rate_hz is not None and not rate_hz > 0:
        raise InvalidInputError(f"{where}Leica rate must be > 0 Hz or None (every fix), got {rate_hz!r}")
    if len(leica_t_ns) == 0:
        raise AidingError(f"{where}no Leica fixes (only a header?)", source or None, label)
    nearest, inside, close = snap_to_samples(imu_t_ns, leica_t_ns)
    if not inside.any():
        lines = f"lines 2-{len(leica_t_ns) + 1}: " if source else ""
        raise AidingOverlapError(
            f"{where}{lines}Leica fixes and IMU do not overlap in time: the fixes span "
            f"{_span(int(leica_t_ns[0]), int(leica_t_ns[-1]))}, the IMU {_span(int(imu_t_ns[0]), int(imu_t_ns[-1]))} "
            "(are both on the same clock and in ns? is the scenario's time_offset_s right?)",
            source or None, label)
    keep = inside & close
    if not keep.any():
        raise AidingError(f"{where}none of the {int(inside.sum())} Leica fixes inside the IMU's span "
                          "has an IMU sample within half a sample period", source or None, label)
    idx, p = nearest[keep], leica_p[keep]
    shared = 0
    if rate_hz is None:  # every fix; a second fix on one sample is dropped (not thinning)
        idx, first = np.unique(idx, return_index=True)
        shared = int(keep.sum()) - len(idx)
    else:  # the first fix of each 1/rate_hz bin (fixes sharing a sample share its bin)
        bins = (imu_t_ns[idx] - imu_t_ns[0]) // int(round(1e9 / rate_hz))
        _bins, first = np.unique(bins, return_index=True)
        idx = idx[first]
    return PositionFixes(idx, p[first], float(sigma_m), np.asarray(lever, dtype=np.float64), label, source,
                         dropped_outside=int((~inside).sum()),
                         dropped_unmatched=int((inside & ~close).sum()) + shared)


def bag_position_source(bag, topic: str, lever=(0.0, 0.0, 0.0)) -> Tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Real position fixes from a ROS bag topic (geometry_msgs/msg/PointStamped as EuRoC's Leica, or
    the position of a PoseStamped / TransformStamped / Odometry topic), in the form
    :func:`leica_fixes` takes: ``(t_ns, p, lever, source)``. ``lever``: the measured point in the
    body frame (a bag does not say it; the fuse config does). Header stamps; typed bag errors."""
    t_ns, p = read_positions(bag, topic)
    lever_arm = np.asarray(lever, dtype=np.float64).reshape(3)
    return t_ns, p, lever_arm, f"{bag} topic {topic}"
