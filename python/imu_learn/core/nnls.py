"""Non-negative least squares for the few-term fits here (an Allan-variance power law of four terms,
the navigator's two noise terms): every active set is tried and the best feasible one kept, exact for
a handful of columns and without importing scipy.optimize (half a second of calibrate's start)."""
from __future__ import annotations

from itertools import combinations
from typing import Tuple

import numpy as np

MAX_COLUMNS = 8  # 2^8 active sets: beyond that use an iterative solver


def nonneg_lstsq(A: np.ndarray, b: np.ndarray) -> Tuple[np.ndarray, float]:
    """(x >= 0 minimising |A x - b|, the residual norm), as ``scipy.optimize.nnls``: the NNLS optimum's
    positive entries are the unconstrained least-squares solution on their columns, so the best of
    those solutions that are non-negative is the optimum (x = 0 where none is)."""
    A = np.asarray(A, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    n = A.shape[1]
    if n > MAX_COLUMNS:
        raise ValueError(f"nonneg_lstsq: {n} columns; at most {MAX_COLUMNS}")
    best_x, best_r = np.zeros(n), float(np.linalg.norm(b))
    for k in range(1, n + 1):
        for cols in combinations(range(n), k):
            sub = A[:, cols]
            xs, *_ = np.linalg.lstsq(sub, b, rcond=None)
            if np.any(xs <= 0.0) or not np.all(np.isfinite(xs)):
                continue
            r = float(np.linalg.norm(sub @ xs - b))
            if r < best_r:
                best_x = np.zeros(n)
                best_x[list(cols)] = xs
                best_r = r
    return best_x, best_r
