"""Aiding on the IMU's clock: the time rules that tie a measurement to an IMU sample (tested in
tests/test_fuse_aiding.py).

* A real fix stamped exactly at an IMU sample is tied to that sample; otherwise to the nearest one,
  and exactly halfway between two samples to the earlier (:func:`snap_to_samples`). It is dropped
  (and counted in ``dropped_outside``) when stamped before the first or after the last IMU sample,
  never moved onto the end samples; and dropped (``dropped_unmatched``) inside the span when no IMU
  sample is within half the median sample period (an IMU gap), or when an earlier fix already took
  its sample. No fix inside the IMU's span at all is an :class:`~imu_learn.errors.AidingOverlapError`.
* Simulated epochs (and the graph's keyframe grid) take the first IMU sample at or after each
  grid time ``t_0 + k / rate_hz`` (:func:`epochs`): a grid time exactly at a sample is that sample,
  one exactly halfway between two samples the later. The grid starts at the first sample, so no
  simulated epoch lies outside the IMU's span.
"""
from __future__ import annotations

from typing import Tuple

import numpy as np

from imu_learn.errors import InvalidInputError


def epochs(t_ns: np.ndarray, rate_hz: float) -> np.ndarray:
    """Sample indices of a ``rate_hz`` grid starting at the first sample: for each grid time the
    first sample at or after it (a grid time exactly at a sample is that sample; one halfway
    between two samples is the later), each index once."""
    if not rate_hz > 0:
        raise InvalidInputError(f"aiding rate must be > 0 Hz, got {rate_hz!r}")
    period_ns = int(round(1e9 / rate_hz))
    grid = np.arange(int(t_ns[0]), int(t_ns[-1]) + 1, period_ns, dtype=np.int64)
    idx = np.clip(np.searchsorted(t_ns, grid), 0, len(t_ns) - 1)
    return np.unique(idx)


def snap_to_samples(imu_t_ns: np.ndarray, t_ns: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For stamps ``t_ns`` on the IMU's clock: the nearest IMU sample of each (a stamp exactly at a
    sample is that sample; exactly halfway between two, the earlier), whether the stamp lies inside
    the IMU's span [first, last sample], and whether it is within half the median sample period of
    its sample."""
    imu = np.asarray(imu_t_ns, dtype=np.int64)
    t = np.asarray(t_ns, dtype=np.int64)
    if len(imu) < 2:
        raise InvalidInputError(f"snapping needs at least 2 IMU samples, got {len(imu)}")
    half = int(np.median(np.diff(imu))) // 2
    k = np.clip(np.searchsorted(imu, t), 1, len(imu) - 1)
    nearest = np.where(np.abs(t - imu[k - 1]) <= np.abs(imu[k] - t), k - 1, k)
    inside = (t >= imu[0]) & (t <= imu[-1])
    close = np.abs(imu[nearest] - t) <= half
    return nearest, inside, close
