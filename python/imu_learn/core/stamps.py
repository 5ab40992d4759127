"""Sample stamps: the one sample-period and sample-rate rule of the package (re-exported by
:mod:`imu_learn.data.types`, where users find it; here so that the core can use it too)."""
from __future__ import annotations

import numpy as np

from imu_learn.errors import InvalidInputError


def median_period_ns(*t_ns: np.ndarray) -> float:
    """The one sample-period rule: the median of the sample periods [ns], pooled over one or more
    stamp arrays (each int64 ns; arrays with fewer than two stamps add nothing); 0.0 with no period."""
    dts = [np.diff(np.asarray(t, dtype=np.int64)) for t in t_ns if len(t) > 1]
    if not dts:
        return 0.0
    d = dts[0] if len(dts) == 1 else np.concatenate(dts)
    # stamps take few distinct periods (EuRoC's: one, or two 256 ns apart), where a partition is slow
    # (calibrate asks this hundreds of times): a candidate from a thinned copy is the median exactly when
    # it holds both middle ranks (fewer below than the lower one, more up to it than the upper one)
    few = np.sort(d[:: max(1, len(d) // 63)])
    v = few[len(few) // 2]
    below = np.count_nonzero(d < v)
    if below <= (len(d) - 1) // 2 and below + np.count_nonzero(d == v) > len(d) // 2:
        return float(v)
    return float(np.median(d))


def sample_rate_hz(*t_ns: np.ndarray) -> float:
    """The one sample-rate rule [Hz]: 1e9 / :func:`median_period_ns` of the same stamps; 0.0 with no period."""
    period = median_period_ns(*t_ns)
    return 1e9 / period if period > 0 else 0.0


def checked_stamps_ns(t_ns: np.ndarray, what: str = "t_ns") -> np.ndarray:
    """``t_ns`` as int64 nanoseconds, refused (:class:`InvalidInputError` naming ``what``) where they are
    not: a float array (seconds would be truncated to whole nanoseconds of nothing), a wrong shape, or
    stamps that do not strictly increase (naming the first such index)."""
    t = np.asarray(t_ns)
    if t.ndim != 1:
        raise InvalidInputError(f"{what} must be a 1-d array of int64 nanoseconds, got shape {t.shape}")
    if not np.issubdtype(t.dtype, np.integer):
        raise InvalidInputError(f"{what} must be integer nanoseconds (int64), got {t.dtype}: stamps in seconds "
                                "are (t * 1e9).round().astype(np.int64)")
    t = t.astype(np.int64, copy=False)
    bad = np.flatnonzero(np.diff(t) <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        raise InvalidInputError(f"{what}[{i}] = {int(t[i])} does not follow {what}[{i - 1}] = {int(t[i - 1])}: "
                                "the stamps must strictly increase")
    return t
