"""core.nnls against scipy's NNLS (Lawson-Hanson), the independent oracle, on random problems and on
the Allan-variance power law's badly scaled basis."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import nnls

from imu_learn.core.nnls import nonneg_lstsq


@pytest.mark.parametrize("allan", [False, True])
def test_nonneg_lstsq_matches_scipy(allan):
    rng = np.random.default_rng(7 + allan)
    for _ in range(400):
        n = int(rng.integers(1, 5))
        m = int(rng.integers(n + 1, 30))
        if allan:
            t = np.logspace(-2, 3, m)
            A = np.stack([t ** -2.0, t ** -1.0, np.ones_like(t), t / 3.0], axis=1)[:, :n]
            y = A @ np.abs(rng.normal(size=n)) * np.exp(rng.normal(scale=0.3, size=m))
            w = 1.0 / (0.2 * y)
            A, b = A * w[:, None], y * w
        else:
            A, b = rng.normal(size=(m, n)), rng.normal(size=m)
        x_ref, r_ref = nnls(A, b)
        x, r = nonneg_lstsq(A, b)
        assert r == pytest.approx(r_ref, rel=1e-9, abs=1e-12)
        np.testing.assert_allclose(x, x_ref, rtol=1e-8, atol=1e-10 * max(1.0, np.abs(x_ref).max()))
        assert np.all(x >= 0.0)


def test_nonneg_lstsq_all_negative_gives_zero():
    A = np.eye(3)
    x, r = nonneg_lstsq(A, -np.ones(3))
    assert np.all(x == 0.0) and r == pytest.approx(np.sqrt(3.0))
