"""The extrinsic's bootstrap spread (calib.reference.rotation_spread), computed from per-block sums,
against the bootstrap done the plain way (Kabsch on every draw's rows)."""
from __future__ import annotations

import math

import numpy as np

from imu_learn.calib.frames import kabsch
from imu_learn.calib.reference import rotation_spread


def plain(a: np.ndarray, b: np.ndarray, blocks: int = 20, seed: int = 0) -> float:
    r0 = kabsch(a, b)[0]
    edges = np.linspace(0, len(a), blocks + 1).astype(int)
    rng = np.random.default_rng(seed)
    angles = []
    for _ in range(30):
        idx = np.concatenate([np.arange(edges[j], edges[j + 1]) for j in rng.integers(0, blocks, blocks)])
        r = kabsch(a[idx], b[idx])[0] @ r0.T
        angles.append(math.degrees(math.acos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0))))
    return float(np.sqrt(np.mean(np.square(angles))))


def test_the_spread_from_block_sums_is_the_plain_bootstrap():
    rng = np.random.default_rng(3)
    for k, noise in enumerate((0.01, 0.05, 0.3)):
        b = rng.standard_normal((4000 + 700 * k, 3))
        q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        r = q * np.sign(np.linalg.det(q))
        a = b @ r.T + noise * rng.standard_normal(b.shape) + 0.02 * rng.standard_normal(3)
        got, ref = rotation_spread((a, b)), plain(a, b)
        assert ref > 0 and math.isclose(got, ref, rel_tol=1e-6), (got, ref)


def test_no_rates_no_spread():
    assert math.isnan(rotation_spread((np.zeros((0, 3)), np.zeros((0, 3)))))
