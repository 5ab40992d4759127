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


def turning_robot(rest_bias, moving_bias, seed: int = 0, rate: float = 100.0, rest_s: float = 5.0,
                  move_s: float = 40.0, gravity: float = 9.81):
    """(t_ns, gyro, acc): a level robot at rest for ``rest_s`` (gyro: ``rest_bias`` plus white noise),
    then turning about gravity (the body's z) at a varying rate for ``move_s`` with its accelerometer
    shaken (gyro: the rate plus ``moving_bias``)."""
    n0, n1 = int(rest_s * rate), int(move_s * rate)
    t = (np.arange(n0 + n1) * 1e9 / rate).astype(np.int64)
    s = np.arange(n1) / rate
    rng = np.random.default_rng(seed)
    w = np.zeros((n0 + n1, 3))
    w[n0:, 2] = 0.5 * np.sin(2 * np.pi * 0.2 * s) + 0.3 * np.sin(2 * np.pi * 0.07 * s)
    bias = np.vstack([np.tile(rest_bias, (n0, 1)), np.tile(moving_bias, (n1, 1))])
    g = w + bias + rng.normal(0, 0.002, w.shape)
    a = np.tile([0.0, 0.0, gravity], (n0 + n1, 1))
    a[:n0] += rng.normal(0, 0.02, (n0, 3))
    a[n0:] += rng.normal(0, 0.3, (n1, 3))
    return t, g, a
