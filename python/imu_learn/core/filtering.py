"""The floor's zero-phase low-pass in the core: one second-order section forward and backward
(``scipy.signal.sosfiltfilt`` for one section, its padding and steady-state starts; the core's
``filtfilt_section``, a direct recursion per column with the GIL released)."""
from __future__ import annotations

import numpy as np

from imu_learn import _imu_core as core


def filtfilt_section(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """x (N, C), N > 9, filtered by the one section ``sos`` ((1, 6) or (6,): b0, b1, b2, a0, a1, a2)
    forward and backward; (N, C) float64."""
    return core.filtfilt_section(np.ascontiguousarray(x, dtype=np.float64),
                                 np.ascontiguousarray(np.reshape(sos, -1), dtype=np.float64))
