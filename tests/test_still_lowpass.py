"""``--bias``'s still detector looks at the IMU before the profile's low-pass (imu_learn.core.still,
imu_learn.infer.bias.still_input, imu_learn.calib.correction.profile_step): whether a rest counts
must not depend on a filter the reference may not have observed.

The synthetic recording: 15 s of vibration (70 Hz on the accelerometer, the gyro too noisy to be
still), 6 s at rest (white noise), 15 s of vibration again. On the raw accelerometer the rest is the
quietest part and counts; a 20 Hz low-pass removes the vibration but not the rest's noise below 20 Hz,
so the vibrating parts become the quietest, the detector's threshold (3 x the 5th percentile) drops
below the rest's spread and the rest no longer counts. A profile with that low-pass and the same
profile without it must give the same estimate: the recording's own bias after the floor."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.core.still import BIAS_SETTINGS, still_bias

RATE = 200.0
G = 9.81
IMU_REL = "mav0/imu0/data.csv"
M_G = np.array([[1.01, 0.002, -0.001], [0.0, 0.99, 0.003], [0.001, 0.0, 1.02]])
B_G = np.array([0.01, -0.02, 0.015])  # the floor's gyro bias (raw units)
M_A, B_A = 1.01, np.array([0.05, -0.03, 0.02])
OWN = np.array([0.002, -0.001, 0.003])  # the recording's own bias after the floor [rad/s]


def recording(seed: int = 0):
    """(t_ns, raw gyro, raw acc, the rest's index range): vibration, rest, vibration (module doc); after
    the floor the gyro reads OWN plus noise and the accelerometer gravity's norm."""
    n_move, n_rest = int(15 * RATE), int(6 * RATE)
    n = 2 * n_move + n_rest
    t = (np.arange(n) * 1e9 / RATE).astype(np.int64)
    s = np.arange(n) / RATE
    rng = np.random.default_rng(seed)
    rest = np.zeros(n, bool)
    rest[n_move:n_move + n_rest] = True
    w = OWN + np.where(rest[:, None], rng.normal(0, 0.002, (n, 3)), rng.normal(0, 0.05, (n, 3)))
    a = np.tile([0.0, 0.0, G], (n, 1))
    a[~rest, 0] += 0.5 * np.sin(2 * np.pi * 70.0 * s[~rest])
    a += np.where(rest[:, None], rng.normal(0, 0.08, (n, 3)), rng.normal(0, 0.005, (n, 3)))
    raw_g = B_G + w @ np.linalg.inv(M_G).T  # the floor: M_g (w_m - b_g) = w
    raw_a = a / M_A + B_A  # M_a (a_m - b_a) = a
    return t, raw_g, raw_a, (n_move, n_move + n_rest)


def floor_profile(cutoff_acc):
    """A profile whose floor changes the data (gyro scale, misalignment and bias; accelerometer scale
    and bias), its accelerometer low-passed at ``cutoff_acc`` [Hz] (None: not), the gyro not."""
    from imu_learn.baselines.traditional import TraditionalTiming
    from imu_learn.calib.profile import Affine, Profile

    m = TraditionalTiming()
    p = m.params
    p.M_g, p.b_g, p.M_a, p.b_a = M_G.copy(), B_G.copy(), np.eye(3) * M_A, B_A.copy()
    p.cutoff_gyro, p.cutoff_acc, p.time_offset = None, cutoff_acc, 0.0
    fl = m.to_dict()
    return Profile(device="synthetic", sample_rate_hz=RATE, time_offset_s=0.0, time_offset_s_std=math.nan,
                   gyro=Affine(np.asarray(fl["M_g"]), np.asarray(fl["b_g"]), "rad/s", np.zeros((3, 3)),
                               np.full(3, 0.002)),
                   acc=Affine(np.asarray(fl["M_a"]), np.asarray(fl["b_a"]), "m/s^2"),
                   g_sensitivity=np.asarray(fl["G"]), gravity_mps2=G, gravity_mps2_std=math.nan, floor=fl)


def test_the_low_pass_flips_the_rest_when_the_detector_sees_it():
    """The construction (module doc): on the floor's output with the low-pass the rest is not found,
    on the same floor without it (or on the floor's samples before the low-pass) it is."""
    t, g, a, (r0, r1) = recording()
    settings = replace(BIAS_SETTINGS, gravity=G)
    g_lp, a_lp = floor_profile(20.0).apply(t, g, a)
    g_no, a_no = floor_profile(None).apply(t, g, a)
    assert np.array_equal(g_lp, g_no)  # the gyro is not filtered: only the accelerometer differs
    assert still_bias(t, g_lp, a_lp, settings).gyro_bias is None  # the old input: the rest refused
    est = still_bias(t, g_no, a_no, settings)
    assert est.gyro_bias is not None and est.still_s > 4.0
    assert all(r0 / RATE - 0.5 <= s["t0_s"] and s["t0_s"] + s["duration_s"] <= r1 / RATE + 0.5 for s in est.stretches)
    # the detector on the samples before the low-pass, the estimate on the filtered ones: the same here
    both = still_bias(t, g_lp, a_lp, settings, detect=(g_no, a_no))
    assert np.array_equal(both.gyro_bias, est.gyro_bias) and both.stretches == est.stretches
    assert np.abs(est.gyro_bias - OWN).max() < 4e-4, est.gyro_bias  # 0.002 / sqrt(1000) per axis, 6 sigma


def write_asl(folder, t, g, a):
    f = folder / IMU_REL
    f.parent.mkdir(parents=True)
    core.write_asl_imu(str(f), t, g, a, "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                       "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
    return folder


def test_refine_and_navigate_estimate_the_same_bias_with_and_without_the_low_pass(tmp_path):
    """``refine --profile P --bias still|auto`` with the low-pass in P and without it: the same rest,
    the same still estimate (bit for bit: the gyro is not filtered), near the recording's own bias, and
    ``auto`` within 1e-6 rad/s (its gravity consistency sees the filtered accelerometer, as it should);
    navigate's ``--bias`` (its IMU through the same plan) the same as refine's."""
    from imu_learn.cli.refine import main
    from imu_learn.fuse.navigate import NavigateOptions, Sources, bias_prior, own_bias, read_body_imu

    t, g, a, _ = recording()
    src = write_asl(tmp_path / "in", t, g, a)
    found = {}
    for cut in (20.0, None):
        prof = tmp_path / f"p_{cut}.json"
        floor_profile(cut).save(prof)
        for method in ("still", "auto"):
            out = tmp_path / f"{method}_{cut}.csv"
            assert main(["--profile", str(prof), "--input", str(src / IMU_REL), "--out", str(out), "--bias", method,
                         "--quiet"]) == 0
            entry = json.loads((tmp_path / f"{method}_{cut}.csv.summary.json").read_text())["bias"]
            still = entry if method == "still" else entry["still"]
            assert still["gyro_bias_rad_s"] is not None and still["still_s"] > 4.0, (cut, method, still)
            found[method, cut] = entry["gyro_bias_rad_s"]
            found[method + "'s still", cut] = still["gyro_bias_rad_s"]
        opts = NavigateOptions(bias="still")
        imu = read_body_imu(Sources(input=src, aiding=tmp_path / "unused.tum", profile=prof), opts)
        assert (imu.still_input is None) == (cut is None)
        _, nav = own_bias(opts, imu.t_ns, imu.gyro, imu.acc, "synthetic", bias_prior(imu), imu.still_input)
        assert nav["applied"] and nav["gyro_bias_rad_s"] == found["still", cut]
    assert found["still", 20.0] == found["still", None] and found["auto's still", 20.0] == found["auto's still", None]
    assert np.abs(np.subtract(found["auto", 20.0], found["auto", None])).max() < 1e-6
    assert np.abs(np.asarray(found["still", 20.0]) - OWN).max() < 4e-4
