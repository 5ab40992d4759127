"""The core reads (N, 3) and (N, 4) arrays as rows without copying: an array whose memory is not rows
(Fortran order: numpy's ``asfortranarray``, or the transpose of a (3, N) array) is refused, never read
in the wrong order."""
from __future__ import annotations

import numpy as np
import pytest

from imu_learn import _imu_core as core
from imu_learn.errors import InvalidInputError


def _imu(n: int = 50):
    rng = np.random.default_rng(0)
    t = np.arange(n, dtype=np.int64) * 5_000_000
    return t, rng.normal(0.0, 0.5, (n, 3)), rng.normal(0.0, 1.0, (n, 3)) + [0.0, 0.0, 9.81]


def test_rows_in_fortran_order_are_refused():
    t, g, a = _imu()
    starts, hs = np.array([0, 10], dtype=np.uint64), np.array([5], dtype=np.uint64)
    ok = core.integrate_windows(t, g, a, starts, hs)
    with pytest.raises(InvalidInputError, match="gyro must be C-contiguous"):
        core.integrate_windows(t, np.asfortranarray(g), a, starts, hs)
    with pytest.raises(InvalidInputError, match="acc must be C-contiguous"):
        core.integrate_windows(t, g, np.ascontiguousarray(a.T).T, starts, hs)
    again = core.integrate_windows(t, np.ascontiguousarray(np.asfortranarray(g)), a, starts, hs)
    np.testing.assert_array_equal(again["dq_wxyz"], ok["dq_wxyz"])
