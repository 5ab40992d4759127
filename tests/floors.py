"""Test inputs shared by the profile, refine and bias tests: a floor with set parameters and a
BROAD-style .mat trial without stamps."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_learn.baselines.traditional import TraditionalTiming


def set_floor(cutoffs=(None, None), time_offset: float = 0.54, seed: int = 5) -> TraditionalTiming:
    """``traditional+timing`` with a rotation-sized misalignment, biases and g-sensitivity drawn from
    ``seed``, the given low-pass cut-offs [Hz] and time offset [samples]."""
    rng = np.random.default_rng(seed)
    m = TraditionalTiming()
    p = m.params
    p.M_g, p.b_g = np.eye(3) + 0.01 * rng.standard_normal((3, 3)), 0.01 * rng.standard_normal(3)
    p.G = 1e-3 * rng.standard_normal((3, 3))
    p.M_a, p.b_a = np.eye(3) + 0.01 * rng.standard_normal((3, 3)), 0.1 * rng.standard_normal(3)
    p.cutoff_gyro, p.cutoff_acc, p.time_offset = *cutoffs, time_offset
    return m


def write_broad_trial(path: Path, scipy_io, n: int = 300) -> Path:
    """A BROAD-layout .mat trial (no stamps: only a sampling rate) of white-noise IMU samples."""
    rng = np.random.default_rng(1)
    scipy_io.savemat(path, {"imu_gyr": rng.normal(0, 0.3, (n, 3)), "imu_acc": rng.normal(0, 1, (n, 3)),
                            "opt_quat": np.tile([1.0, 0, 0, 0], (n, 1)), "opt_pos": np.zeros((n, 3)),
                            "sampling_rate": 286.0})
    return path
