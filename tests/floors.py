"""Test inputs shared by the profile, refine and bias tests: a floor with set parameters and a
BROAD-style .mat trial without stamps."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.baselines.traditional import TraditionalTiming
from imu_learn.calib.profile import Affine, Profile
from imu_learn.cli.refine import main as refine_main


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


ASL_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
              "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")


def refine_identity_floor(tmp_path: Path, t, g, a, bias: str, bias_prior, gyro_bias_std: float,
                          rate: float = 100.0, gravity: float = 9.81):
    """``imu-learn refine --profile P --bias BIAS`` on an ASL recording of (t, g, a), P the identity
    floor with ``gyroscope.bias_std`` = ``gyro_bias_std`` and ``bias_prior``: (the summary's bias entry,
    the refined gyro). The recording is TMP/in/mav0/imu0/data.csv, the profile TMP/profile.json."""
    f = tmp_path / "in" / "mav0/imu0/data.csv"
    f.parent.mkdir(parents=True)
    core.write_asl_imu(str(f), t, g, a, ASL_HEADER)
    prof = Profile(device="synthetic", sample_rate_hz=rate, time_offset_s=0.0, time_offset_s_std=math.nan,
                   gyro=Affine(np.eye(3), np.zeros(3), "rad/s", np.zeros((3, 3)), np.full(3, gyro_bias_std)),
                   acc=Affine(np.eye(3), np.zeros(3), "m/s^2"), g_sensitivity=np.zeros((3, 3)), gravity_mps2=gravity,
                   gravity_mps2_std=math.nan, floor={}, bias_prior=bias_prior)
    prof.save(tmp_path / "profile.json")
    out = tmp_path / "o.csv"
    assert refine_main(["--profile", str(tmp_path / "profile.json"), "--input", str(f), "--out", str(out),
                        "--bias", bias, "--quiet"]) == 0
    _, g_out, _ = core.read_asl_imu(str(out))
    return json.loads((tmp_path / "o.csv.summary.json").read_text())["bias"], g_out
