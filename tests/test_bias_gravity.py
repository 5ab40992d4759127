"""A recording's own gyro bias from gravity consistency (imu_learn.core.bias_gravity), without ground
truth: on a synthetic device turning through many attitudes every axis is recovered; on one that keeps
its attitude only the axes perpendicular to gravity are (the one along gravity stays at the prior's
zero and is reported as not observed); ``imu-learn refine --bias gravity`` subtracts the estimate and
writes it into the summary."""
from __future__ import annotations

import json
import math

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.core.bias_gravity import GravitySettings, chunks, gravity_bias
from imu_learn.core.integration import preintegrate
from imu_learn.core.quat import quat_conj, quat_rotate

RATE = 100.0
BIAS = np.array([0.003, -0.002, 0.004])
G = np.array([0.0, 0.0, 9.81])


def turning(seconds=300.0, seed=0, turn=True):
    """A device at rest in position, turning smoothly through many attitudes (or none): its exact
    gyro plus ``BIAS`` and white noise, its accelerometer (gravity only) plus white noise."""
    n = int(seconds * RATE)
    t = (np.arange(n) * 1e9 / RATE).astype(np.int64)
    s = np.arange(n) / RATE
    w = np.stack([0.5 * np.sin(0.3 * s), 0.4 * np.cos(0.21 * s + 1), 0.6 * np.sin(0.13 * s)], 1) * float(turn)
    q = preintegrate(t, w, np.zeros((n, 3))).dq_wxyz
    f = quat_rotate(quat_conj(q), np.tile(G, (n, 1)))
    rng = np.random.default_rng(seed)
    return t, w + BIAS + rng.normal(0, 0.005, (n, 3)), f + rng.normal(0, 0.05, (n, 3))


def test_a_turning_device_gives_every_axis():
    t, g, a = turning()
    est = gravity_bias(t, g, a)
    assert np.all(np.abs(est.gyro_bias - BIAS) < 4 * est.gyro_bias_std), (est.gyro_bias, est.gyro_bias_std)
    assert np.all(est.direction_std < est.settings.observed_below)
    assert est.chunks == 3 and est.windows == 12 + 12 + 5  # the last chunk: 60 s less a sample


def test_one_attitude_leaves_the_axis_along_gravity_unobserved():
    t, g, a = turning(turn=False)
    est = gravity_bias(t, g, a)
    assert np.allclose(est.gyro_bias[:2], BIAS[:2], atol=2e-4)
    assert abs(est.gyro_bias[2]) < 1e-4  # held at the prior's zero: yaw about gravity is not seen
    d = est.to_dict()
    weak = int(np.argmax(est.direction_std))
    assert d["direction_observed"] == [i != weak for i in range(3)]
    assert abs(abs(np.dot(est.directions[weak], est.gravity_body)) - 1) < 1e-3
    assert math.isclose(d["direction_std_rad_s"][weak], est.settings.prior_sigma, rel_tol=0.01)


def test_a_short_recording_gives_no_estimate_and_chunks_cut_at_gaps():
    t, g, a = turning(20.0)
    assert gravity_bias(t, g, a).gyro_bias is None
    t2 = np.r_[t, t[-1] + 10 ** 9 + t]
    assert chunks(t2, GravitySettings(chunk_s=15.0)) == [(0, 1501), (1501, 2000), (2000, 3501), (3501, 4000)]


def test_refine_bias_gravity_subtracts_the_estimate(tmp_path, capsys):
    from imu_learn.calib.profile import Affine, Profile
    from imu_learn.cli.refine import main
    from test_still_bias import IMU_REL, write_asl

    t, g, a = turning(150.0)
    src = write_asl(tmp_path / "in", t, g, a)
    eye = Affine(np.eye(3), np.zeros(3), "rad/s")
    prof = Profile(device="synthetic", sample_rate_hz=RATE, time_offset_s=0.0, time_offset_s_std=math.nan, gyro=eye,
                   acc=Affine(np.eye(3), np.zeros(3), "m/s^2"), g_sensitivity=np.zeros((3, 3)), gravity_mps2=9.81,
                   gravity_mps2_std=math.nan, floor={})
    prof.save(tmp_path / "profile.json")
    out = tmp_path / "out.csv"
    assert main(["--profile", str(tmp_path / "profile.json"), "--input", str(src / IMU_REL), "--out", str(out),
                 "--bias", "gravity"]) == 0
    summary = json.loads((tmp_path / "out.csv.summary.json").read_text())["bias"]
    assert summary["method"] == "gravity" and summary["applied"] and "perpendicular to gravity" in summary["observable"]
    est = np.array(summary["gyro_bias_rad_s"])
    assert np.all(np.abs(est - BIAS) < 5e-4), est
    _, g_out, _ = core.read_asl_imu(str(out))
    assert np.allclose(g_out, g - est, atol=1e-6)
    # too short for its windows: one warning line, nothing subtracted
    src2 = write_asl(tmp_path / "short", *turning(20.0))
    assert main(["--profile", str(tmp_path / "profile.json"), "--input", str(src2 / IMU_REL), "--out",
                 str(tmp_path / "o2.csv"), "--bias", "gravity"]) == 0
    assert capsys.readouterr().err.count("--bias gravity:") == 1


def test_still_along_gravity_takes_each_estimate_where_it_sees():
    from types import SimpleNamespace

    from imu_learn.infer.rewrite import still_along_gravity

    grav = SimpleNamespace(gyro_bias=np.array([4.0, 5.0, 6.0]), gravity_body=np.array([0.0, 0.0, -9.8]))
    assert np.allclose(still_along_gravity(np.array([1.0, 2.0, 3.0]), grav), [4.0, 5.0, 3.0])
    tilted = SimpleNamespace(gyro_bias=np.zeros(3), gravity_body=np.array([1.0, 1.0, 0.0]))
    assert np.allclose(still_along_gravity(np.array([2.0, 0.0, 5.0]), tilted), [1.0, 1.0, 0.0])
    assert np.allclose(still_along_gravity(None, grav), grav.gyro_bias)
    none = SimpleNamespace(gyro_bias=None, gravity_body=None)
    assert np.allclose(still_along_gravity(np.array([1.0, 2.0, 3.0]), none), [1.0, 2.0, 3.0])
    assert still_along_gravity(None, none) is None


def test_refine_bias_still_plus_gravity_combines_the_two_estimates_it_reports(tmp_path):
    from imu_learn.calib.profile import noise_only
    from imu_learn.cli.refine import main
    from test_still_bias import IMU_REL, write_asl

    t, g, a = turning(150.0)
    src = write_asl(tmp_path / "in", t, g, a)
    noise_only("synthetic", RATE, {}).save(tmp_path / "profile.json")  # no floor: the samples as they are
    outs = {}
    for method in ("gravity", "still+gravity"):
        out = tmp_path / f"{method}.csv"
        assert main(["--profile", str(tmp_path / "profile.json"), "--input", str(src / IMU_REL), "--out", str(out),
                     "--bias", method, "--quiet"]) == 0
        outs[method] = json.loads((tmp_path / f"{method}.csv.summary.json").read_text())["bias"]
    both = outs["still+gravity"]
    assert both["method"] == "still+gravity" and both["applied"]
    assert both["gravity"]["gyro_bias_rad_s"] == outs["gravity"]["gyro_bias_rad_s"]  # the same estimator, same input
    u = np.array(both["gravity"]["gravity_direction_body"])
    u = u / np.linalg.norm(u)
    gb = np.array(both["gravity"]["gyro_bias_rad_s"])
    sb = both["still"]["gyro_bias_rad_s"]
    want = gb if sb is None else gb + u * (u @ (np.array(sb) - gb))
    assert np.allclose(both["gyro_bias_rad_s"], want)
