"""A bias that moves (imu_learn.core.bias_gravity.moving_gravity_bias, ``--bias moving``), without ground
truth: on a synthetic device turning through many attitudes whose gyro bias ramps over the recording,
with still stretches at its start and end, the per-sample estimate follows the ramp within its own
uncertainty (a constant estimate cannot: the ramp is many of its sigmas long); the registry's
``moving`` subtracts the per-sample bias and is gated by a profile's measured figures (``auto``'s constant where they keep it out)."""
from __future__ import annotations

import logging

import numpy as np

from imu_learn.core.bias_gravity import MovingSettings, hat_weights, moving_gravity_bias
from imu_learn.core.integration import preintegrate
from imu_learn.core.quat import quat_conj, quat_rotate
from imu_learn.core.still import BiasPrior
from imu_learn.infer.bias import Context, bias_step, moving_raw

RATE = 100.0
G = np.array([0.0, 0.0, 9.81])
B0 = np.array([0.002, -0.001, 0.003])
RAMP = np.array([0.008, 0.006, -0.008])  # rad/s over the recording


def ramping(seconds=300.0, rest_s=8.0, seed=0):
    """At rest for ``rest_s`` at both ends, turning smoothly through many attitudes between; its gyro
    bias B0 + RAMP * t / T, white noise on both sensors."""
    n = int(seconds * RATE)
    t = (np.arange(n) * 1e9 / RATE).astype(np.int64)
    s = np.arange(n) / RATE
    moving = ((s > rest_s) & (s < seconds - rest_s)).astype(float)
    w = np.stack([0.5 * np.sin(0.3 * s), 0.4 * np.cos(0.21 * s + 1), 0.6 * np.sin(0.13 * s)], 1) * moving[:, None]
    q = preintegrate(t, w, np.zeros((n, 3))).dq_wxyz
    f = quat_rotate(quat_conj(q), np.tile(G, (n, 1)))
    b = B0 + RAMP * (s / seconds)[:, None]
    rng = np.random.default_rng(seed)
    return t, w + b + rng.normal(0, 0.003, (n, 3)), f + rng.normal(0, 0.05, (n, 3)), b


def stills_of(t, g, rest_s=8.0):
    out = []
    for a, c in ((10, int(rest_s * RATE) - 10), (len(t) - int(rest_s * RATE) + 10, len(t) - 10)):
        out.append((int((t[a] + t[c - 1]) // 2), g[a:c].mean(0), g[a:c].std(0, ddof=1) / np.sqrt(c - a)))
    return out


def test_the_ramp_is_recovered_within_its_uncertainty():
    t, g, a, b = ramping()
    est = moving_gravity_bias(t, g, a, stills_of(t, g), MovingSettings(random_walk=1e-4, rest_sigma=(5e-4,) * 3))
    bt, sd = est.at(t)
    z = np.abs(bt - b) / sd
    assert np.all(z < 4.0), z.max(axis=0)
    # the estimate moves as the bias does: its own change start to end is the ramp's, to 25 %
    assert np.all(np.abs((bt[-1] - bt[0]) - RAMP) < 0.25 * np.abs(RAMP)), bt[-1] - bt[0]
    # and a constant (its own time average) lies far outside that uncertainty at the ends
    const = np.abs(est.mean - b[[0, -1]]) / sd[[0, -1]]
    assert np.all(const.max(axis=0) > 6.0), const
    assert est.stills == 2 and est.windows > 20


def test_without_stills_gravity_consistency_alone_follows_the_ramp():
    t, g, a, b = ramping(rest_s=0.0)
    est = moving_gravity_bias(t, g, a, [], MovingSettings())
    bt, sd = est.at(t)
    assert np.all(np.abs(bt - b) < 4 * sd), (np.abs(bt - b) / sd).max(axis=0)
    i, j = len(t) // 4, 3 * len(t) // 4  # its change over the middle half is the ramp's, to 50 %
    assert np.all(np.abs((bt[j] - bt[i]) - (b[j] - b[i])) < 0.5 * np.abs(b[j] - b[i])), bt[j] - bt[i]


def test_hat_weights_interpolate_and_sum_to_one():
    k = np.array([0, 10, 30], dtype=np.int64)
    W = hat_weights(np.array([-5, 0, 5, 10, 20, 30, 40]), k)
    assert np.allclose(W.sum(1), 1.0)
    assert np.allclose(W @ np.array([0.0, 1.0, 3.0]), [0.0, 0.0, 0.5, 1.0, 2.0, 3.0, 3.0])


def test_the_registry_subtracts_per_sample_and_the_gate_keeps_it_out(caplog):
    t, g, a, b = ramping()
    ctx = Context(9.81, BiasPrior.from_bias_std([0.01] * 3, "test"))
    est = moving_raw(ctx, t, g, a)
    assert est.per_sample.shape == g.shape and est.detail["stills"] == 2
    sink = {}
    out, _, _ = bias_step("moving", 9.81, sink, prior=ctx.prior)(t, g, a)
    assert sink["bound"].decision == "applied"
    assert np.allclose(g - out, est.per_sample)  # nothing shrunk: the per-sample bias itself
    assert np.std((g - out)[:, 0]) > 1e-3  # it moves
    # a profile whose training recordings measured it farther than the still estimate: auto's constant
    measured = {"rms_rad_s": {"moving": {"error": 0.002, "profile_alone": 0.004},
                              "still": {"error": 0.001, "profile_alone": 0.004}}}
    worse = BiasPrior.from_bias_std([0.01] * 3, "test", measured=measured)
    sink, sink_auto = {}, {}
    with caplog.at_level(logging.WARNING):
        out, _, _ = bias_step("moving", 9.81, sink, prior=worse)(t, g, a)
    said = [r.getMessage() for r in caplog.records if r.getMessage().startswith("--bias moving:")]
    assert len(said) == 1 and "than still (1)" in said[0] and "auto's constant estimate" in said[0], said
    auto, _, _ = bias_step("auto", 9.81, sink_auto, prior=worse)(t, g, a)
    assert np.array_equal(out, auto) and np.ptp((g - out)[:, 0]) < 1e-12  # constant
    assert sink["moving"].detail["moving_gate"]["entered"] is False
    # measured closer than both: its own, moving
    measured["rms_rad_s"]["moving"]["error"] = 0.0005
    sink = {}
    out, _, _ = bias_step("moving", 9.81, sink, prior=BiasPrior.from_bias_std([0.01] * 3, "test", measured=measured))(t, g, a)
    assert sink["moving"].detail["gate"]["entered"] is True and np.std((g - out)[:, 0]) > 1e-3


def _gate(measured):
    """``--bias moving`` on the ramping device under a profile whose ``bias_prior`` holds ``measured``:
    (its sink, the gyro it gives, ``--bias auto``'s gyro under the same profile)."""
    t, g, a, _ = ramping()
    prior = BiasPrior.from_bias_std([0.01] * 3, "test", measured=measured)
    sink = {}
    out, _, _ = bias_step("moving", 9.81, sink, prior=prior)(t, g, a)
    auto, _, _ = bias_step("auto", 9.81, {}, prior=prior)(t, g, a)
    return sink, g, out, auto


def test_the_gate_keeps_moving_out_where_auto_was_closer_on_the_training_recordings():
    """Training figures where moving beats the profile alone and the still estimate but not auto: the old
    gate (profile alone and still only) admitted it; now auto's estimate, the figures in the summary."""
    measured = {"rms_rad_s": {"moving": {"error": 0.0008, "profile_alone": 0.004},
                              "still": {"error": 0.001, "profile_alone": 0.004},
                              "auto": {"error": 0.0005, "profile_alone": 0.004}}}
    sink, g, out, auto = _gate(measured)
    gate = sink["moving"].detail["moving_gate"]
    assert gate["entered"] is False and gate["compared_with_auto"] is True
    assert gate["training_rms_rad_s"] == {"moving": 0.0008, "profile_alone": 0.004, "still": 0.001, "auto": 0.0005}
    assert sink["moving"].method == "auto" and np.array_equal(out, auto) and np.ptp((g - out)[:, 0]) < 1e-12
    # auto measured farther than moving: moving's own, per sample
    measured["rms_rad_s"]["auto"]["error"] = 0.0009
    sink, g, out, auto = _gate(measured)
    assert sink["moving"].detail["gate"]["entered"] is True and sink["moving"].method == "moving"
    assert np.std((g - out)[:, 0]) > 1e-3 and not np.array_equal(out, auto)


def test_an_old_prior_without_the_auto_figure_keeps_the_old_gate_and_says_so():
    """A profile fitted before auto was measured: moving judged against the profile alone and the still
    estimate only (it enters where it beat both), the summary saying the auto figure is missing."""
    measured = {"rms_rad_s": {"moving": {"error": 0.0008, "profile_alone": 0.004},
                              "still": {"error": 0.001, "profile_alone": 0.004}}}
    sink, g, out, _ = _gate(measured)
    gate = sink["moving"].detail["gate"]
    assert gate["entered"] is True and gate["compared_with_auto"] is False
    assert "no auto figure" in gate["rule"] and "auto" not in gate["training_rms_rad_s"]
    assert sink["moving"].method == "moving" and np.std((g - out)[:, 0]) > 1e-3
    measured["rms_rad_s"]["still"]["error"] = 0.0006  # and kept out where the still estimate was closer, as before
    sink, _, out, auto = _gate(measured)
    assert sink["moving"].detail["moving_gate"]["entered"] is False and np.array_equal(out, auto)
    assert "no auto figure" in sink["moving"].detail["rule"]
