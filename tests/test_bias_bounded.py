"""A recording's own gyro bias bounded by what the device's bias can be (imu_learn.core.still's still
rule, imu_learn.infer.bias's registry and bound): a steady turn about gravity, as quiet as rest, is
refused (exit 0, the profile's bias kept, the summary says so); a real rest is accepted; an estimate
far from the device prior is shrunk (precision-weighted) or rejected; the registry lists every name
the command line accepts; navigate keeps the device bias along what ``still+gravity`` did not see."""
from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.core.still import (
    BIAS_SETTINGS,
    BIAS_SPREAD_FLOOR,
    MEMS_BIAS_BOUND,
    MEMS_PRIOR,
    BiasPrior,
    at_rest,
    prior_spread,
    still_bias,
)
from imu_learn.infer.bias import REGISTRY, BiasEstimate, bound, choices, combine, info_diag

RATE = 100.0
G = 9.81
BIAS = np.array([0.003, -0.002, 0.004])
IMU_REL = "mav0/imu0/data.csv"


def steady(rest_s: float, turn_s: float, rate: float = 0.3, seed: int = 0):
    """At rest for ``rest_s``, then turning at ``rate`` rad/s about gravity (the body's z, level) for
    ``turn_s``: the gyro (plus ``BIAS`` and white noise) as quiet as at rest, the accelerometer on
    gravity throughout."""
    n0, n1 = int(rest_s * RATE), int(turn_s * RATE)
    t = (np.arange(n0 + n1) * 1e9 / RATE).astype(np.int64)
    w = np.zeros((n0 + n1, 3))
    w[n0:, 2] = rate
    rng = np.random.default_rng(seed)
    g = w + BIAS + rng.normal(0, 0.002, w.shape)
    a = np.tile([0.0, 0.0, G], (len(t), 1)) + rng.normal(0, 0.02, w.shape)
    return t, g, a


def shaking(seconds: float = 60.0, seed: int = 0):
    """Level and never turning, shaken back and forth (1 m/s^2 at 0.5 Hz along x): never still (the
    accelerometer's spread), gravity's direction steady over 10 s windows; the gyro ``BIAS`` plus
    white noise."""
    n = int(seconds * RATE)
    t = (np.arange(n) * 1e9 / RATE).astype(np.int64)
    s = np.arange(n) / RATE
    rng = np.random.default_rng(seed)
    a = np.stack([np.sin(np.pi * s), np.zeros(n), np.full(n, G)], 1) + rng.normal(0, 0.02, (n, 3))
    return t, BIAS + rng.normal(0, 0.002, (n, 3)), a


def write_asl(folder, t, g, a):
    f = folder / IMU_REL
    f.parent.mkdir(parents=True)
    core.write_asl_imu(str(f), t, g, a, "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                       "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
    return folder


def profile(path, bias_std=(0.002, 0.002, 0.002)):
    """A profile of the identity floor (nothing applied) whose gyro bias spreads ``bias_std``."""
    from imu_learn.calib.profile import Affine, Profile

    prof = Profile(device="synthetic", sample_rate_hz=RATE, time_offset_s=0.0, time_offset_s_std=math.nan,
                   gyro=Affine(np.eye(3), np.zeros(3), "rad/s", np.zeros((3, 3)), np.asarray(bias_std, float)),
                   acc=Affine(np.eye(3), np.zeros(3), "m/s^2"), g_sensitivity=np.zeros((3, 3)), gravity_mps2=G,
                   gravity_mps2_std=math.nan, floor={})
    prof.save(path)
    return path


def test_the_prior_spread_is_floored_and_capped():
    assert np.allclose(prior_spread([0.0001, 0.02, 0.3]), [BIAS_SPREAD_FLOOR, 0.02, MEMS_BIAS_BOUND])
    assert np.allclose(prior_spread(None), MEMS_BIAS_BOUND)
    assert np.allclose(prior_spread([math.nan, 0.01, 0.01]), [MEMS_BIAS_BOUND, 0.01, 0.01])
    p = BiasPrior.from_bias_std([0.001, 0.02, 0.01], "x", isotropic=True)
    assert np.allclose(p.std, 0.02)


def test_the_still_rule_wants_the_gyro_near_the_prior_and_the_norm_near_gravity():
    prior = BiasPrior.from_bias_std([0.002] * 3, "test")  # 5 mrad/s after the floor: 15 mrad/s at 3 sigma
    assert at_rest(np.array([0.01, 0.0, -0.01]), np.array(G), G, prior)
    assert not at_rest(np.array([0.0, 0.0, 0.3]), np.array(G), G, prior)  # a steady turn
    assert not at_rest(np.array([0.0, 0.0, 0.0]), np.array(G * 1.05), G, prior)  # 5 % off gravity
    assert not at_rest(np.array([0.0, 0.0, 0.3]), None, None, MEMS_PRIOR)  # beyond a MEMS gyro's bias too


def test_a_steady_turn_is_refused_and_a_real_rest_accepted():
    t, g, a = steady(0.0, 60.0)
    est = still_bias(t, g, a, BIAS_SETTINGS)
    assert est.gyro_bias is None and est.refused and abs(est.refused[0]["gyro_mean_rad_s"][2] - 0.3 - BIAS[2]) < 1e-3
    t, g, a = steady(20.0, 40.0)
    est = still_bias(t, g, a, BIAS_SETTINGS)
    assert est.gyro_bias is not None and np.all(np.abs(est.gyro_bias - BIAS) < 5e-4) and est.still_s > 15.0
    assert len(est.refused) == 1 and est.refused[0]["t0_s"] > 20.0  # the turn after it


def test_a_slow_turn_is_refused_where_the_device_measured_its_rest_spread():
    """A profile's ``bias_std`` from full-floor refits can be far wider than the device's bias (Fetch's
    34-138 mrad/s x sqrt(6 recordings), the prior then capped at 50 mrad/s: a 0.1 rad/s turn passed as rest and ``--bias moving``
    subtracted it); where its ``bias_prior`` measured the spread of the bias at rest (moving, still error,
    rest-to-motion: a few mrad/s), that spread, floored at 5 mrad/s, is the still rule's sigma."""
    wide = BiasPrior.from_bias_std([0.082, 0.199, 0.338], "fetch-like")
    measured = BiasPrior.from_bias_std([0.082, 0.199, 0.338], "fetch-like", measured={
        "moving_std_rad_s": [0.0013, 0.0037, 0.0049], "still_error_std_rad_s": [0.0019, 0.0034, 0.0048],
        "rest_to_motion_rad_s": [0.0, 0.0, -0.0086]})
    assert np.allclose(wide.rest_std(), wide.std) and np.allclose(wide.std, MEMS_BIAS_BOUND)
    assert np.allclose(measured.rest_std(), [BIAS_SPREAD_FLOOR, math.hypot(0.0037, 0.0034),
                                             math.sqrt(0.0049 ** 2 + 0.0048 ** 2 + 0.0086 ** 2)])
    t, g, a = steady(20.0, 40.0, rate=0.1)
    for prior, turn_refused in ((wide, False), (measured, True)):
        est = still_bias(t, g, a, replace(BIAS_SETTINGS, gravity=G, prior=prior))
        assert est.gyro_bias is not None and np.all(np.abs(est.gyro_bias - BIAS) < 5e-4) == turn_refused
        assert bool(est.refused) == turn_refused


def test_refine_keeps_the_profiles_bias_on_a_steady_turn(tmp_path, capsys):
    from imu_learn.cli.refine import main

    t, g, a = steady(0.0, 60.0)
    src = write_asl(tmp_path / "in", t, g, a)
    prof = profile(tmp_path / "profile.json")
    for method in ("still", "auto"):
        out = tmp_path / f"{method}.csv"
        assert main(["--profile", str(prof), "--input", str(src / IMU_REL), "--out", str(out), "--bias", method]) == 0
        entry = json.loads((tmp_path / f"{method}.csv.summary.json").read_text())["bias"]
        still = entry if method == "still" else entry["still"]
        assert still["gyro_bias_rad_s"] is None and still["refused_as_turning"], still
        assert still["detector"]["prior"]["std_rad_s"] == [BIAS_SPREAD_FLOOR] * 3
        _, g_out, _ = core.read_asl_imu(str(out))
        if method == "still":  # nothing subtracted: the floor's (here the identity's) bias kept
            assert not entry["applied"] and entry["bound"]["decision"] == "none"
            assert np.allclose(g_out, g, atol=1e-6)
        else:  # gravity consistency alone: it cannot see the rate about gravity, which stays at the prior's
            assert entry["used"] == ["gravity"] and entry["still"]["bound"]["decision"] == "none"
            assert np.allclose(g_out[:, 2], g[:, 2], atol=1e-4)
    assert "refused by the still rule" in capsys.readouterr().err


def test_refine_says_when_it_refused_a_turn_and_used_the_rest_beside_it(tmp_path, capsys):
    """A rest, then a steady turn as quiet as rest: the bias comes from the rest, and one warning names the
    refused turn (it passed in silence, only the summary's refused_as_turning said so)."""
    from imu_learn.cli.refine import main

    t, g, a = steady(20.0, 40.0)
    src = write_asl(tmp_path / "in", t, g, a)
    prof = profile(tmp_path / "profile.json")
    out = tmp_path / "still.csv"
    assert main(["--profile", str(prof), "--input", str(src / IMU_REL), "--out", str(out), "--bias", "still"]) == 0
    entry = json.loads((tmp_path / "still.csv.summary.json").read_text())["bias"]
    assert entry["applied"] and entry["refused_as_turning"]
    err = [ln for ln in capsys.readouterr().err.splitlines() if "warning" in ln]
    assert len(err) == 1 and "1 quiet stretch(es)" in err[0] and "refused as a steady turn" in err[0], err


def test_refine_applies_a_real_rest(tmp_path):
    from imu_learn.cli.refine import main

    t, g, a = steady(20.0, 40.0)
    src = write_asl(tmp_path / "in", t, g, a)
    out = tmp_path / "o.csv"
    assert main(["--profile", str(profile(tmp_path / "p.json")), "--input", str(src / IMU_REL), "--out", str(out),
                 "--bias", "still", "--quiet"]) == 0
    entry = json.loads((tmp_path / "o.csv.summary.json").read_text())["bias"]
    assert entry["applied"] and entry["bound"]["decision"] == "applied" and entry["bound"]["z_sigmas"] < 3
    _, g_out, _ = core.read_asl_imu(str(out))
    assert np.allclose(g - g_out, np.asarray(entry["gyro_bias_rad_s"]), atol=1e-6)


def estimate(b, std, method="still"):
    return BiasEstimate(method, np.asarray(b, float), info_diag(np.asarray(std, float)), {})


def test_the_bound_applies_shrinks_or_rejects():
    prior = BiasPrior((0.0, 0.0, 0.0), (0.005, 0.005, 0.005), "test")
    v = bound(estimate([0.01, 0.0, 0.0], [0.001] * 3), prior)  # 2 sigma: as estimated
    assert v.decision == "applied" and np.allclose(v.gyro_bias, [0.01, 0.0, 0.0])
    v = bound(estimate([0.02, 0.0, 0.0], [0.001] * 3), prior)  # 0.02 / sqrt(0.005^2 + 0.001^2) = 3.9 sigma
    assert v.decision == "shrunk" and abs(v.z - 0.02 / math.hypot(0.005, 0.001)) < 1e-9
    w0, w = 1 / 0.005 ** 2, 1 / 0.001 ** 2
    assert np.allclose(v.gyro_bias, [w * 0.02 / (w0 + w), 0.0, 0.0])  # precision-weighted toward the prior's zero
    v = bound(estimate([0.0, 0.0, 0.3], [0.001] * 3), prior)  # the steady turn's 0.3 rad/s: 59 sigma
    assert v.decision == "rejected" and v.gyro_bias is None and "rejected" in v.why
    # an unobserved direction (zero information) is neither tested nor moved
    e = BiasEstimate("gravity", np.array([0.001, 0.0, 0.0]), np.diag([1e6, 1e6, 0.0]), {})
    assert np.allclose(e.unobserved(), np.diag([0.0, 0.0, 1.0]))
    assert bound(e, prior).decision == "applied"


def test_auto_combines_by_information():
    prior = BiasPrior((0.0, 0.0, 0.0), (0.01, 0.01, 0.01), "test")
    a = estimate([0.004, 0.004, 0.004], [0.002] * 3, "still")
    b = BiasEstimate("gravity", np.array([0.002, 0.002, 0.0]), np.diag([1 / 0.001 ** 2, 1 / 0.001 ** 2, 0.0]), {})
    far = estimate([0.5, 0.0, 0.0], [0.001] * 3, "learned")  # rejected: left out
    c = combine([a, b, far], prior)
    L0, La, Lb = 1 / 0.01 ** 2, 1 / 0.002 ** 2, 1 / 0.001 ** 2
    assert c.detail["used"] == ["still", "gravity"] and c.detail["learned"]["bound"]["decision"] == "rejected"
    want_xy = (La * 0.004 + Lb * 0.002) / (La + Lb)
    assert np.allclose(c.gyro_bias, [want_xy, want_xy, 0.004])  # z: the still estimate alone saw it
    c = combine([a, b, far], prior, with_prior=True)  # the prior averaged in everywhere
    want_xy = (La * 0.004 + Lb * 0.002) / (L0 + La + Lb)
    assert np.allclose(c.gyro_bias, [want_xy, want_xy, La * 0.004 / (L0 + La)])
    # nothing observes z: the prior's mean there
    c = combine([b], BiasPrior((0.0, 0.0, 0.001), (0.01, 0.01, 0.01), "test"))
    assert np.allclose(c.gyro_bias, [0.002, 0.002, 0.001])


def test_the_registry_lists_every_name_the_command_line_accepts():
    from imu_learn.cli import navigate as nav_cli
    from imu_learn.cli import refine

    p = argparse.ArgumentParser()
    refine.add_arguments(p)
    refine_choices = next(a.choices for a in p._actions if a.dest == "bias")
    nav_choices = next(a.choices for a in nav_cli.parser()._actions if a.dest == "bias")
    assert tuple(refine_choices) == choices() and tuple(nav_choices) == choices(navigate=True)
    assert set(refine_choices) == {"none", *REGISTRY} and "auto" in nav_choices and "learned" not in nav_choices
    assert {"auto", "still", "gravity", "still+gravity", "learned"} <= set(REGISTRY)


def test_navigate_keeps_the_device_bias_where_still_plus_gravity_saw_nothing():
    """No still stretch (a level device shaken, never at rest): still+gravity is gravity consistency
    alone, which cannot see the rate about gravity; the checkpoint's device bias must stay along it
    (it was dropped whole when the directions were looked for at the entry's top level)."""
    from imu_learn.fuse.navigate import NavigateOptions, own_bias, unobserved

    t, g, a = shaking()
    g_out, entry = own_bias(NavigateOptions(bias="still+gravity"), t, g, a, "shaken")
    assert entry["applied"] and entry["still"]["gyro_bias_rad_s"] is None
    assert np.abs((g - g_out).mean(0)[:2] - BIAS[:2]).max() < 5e-4
    P = unobserved(entry)
    assert np.allclose(P @ np.array([0.1, 0.2, 0.3]), [0.0, 0.0, 0.3], atol=1e-3)
    # the still stretches see every axis: nothing kept
    t, g, a = steady(20.0, 40.0)
    _, entry = own_bias(NavigateOptions(bias="still+gravity"), t, g, a, "rest")
    assert np.allclose(unobserved(entry), 0.0, atol=1e-9)
