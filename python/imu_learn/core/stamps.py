"""Sample stamps: the one sample-period and sample-rate rule of the package (re-exported by
:mod:`imu_learn.data.types`, where users find it; here so that the core can use it too)."""
from __future__ import annotations

import numpy as np


def median_period_ns(*t_ns: np.ndarray) -> float:
    """The one sample-period rule: the median of the sample periods [ns], pooled over one or more
    stamp arrays (each int64 ns; arrays with fewer than two stamps add nothing); 0.0 with no period."""
    dts = [np.diff(np.asarray(t, dtype=np.int64)) for t in t_ns if len(t) > 1]
    return float(np.median(np.concatenate(dts))) if dts else 0.0


def sample_rate_hz(*t_ns: np.ndarray) -> float:
    """The one sample-rate rule [Hz]: 1e9 / :func:`median_period_ns` of the same stamps; 0.0 with no period."""
    period = median_period_ns(*t_ns)
    return 1e9 / period if period > 0 else 0.0
