"""The named ``--bias`` options admitted as ``auto`` admits its parts (docs/refine.md, "The recording's
own bias"): where the profile's ``bias_prior`` says an estimator lay no closer to the bias while moving
than the profile alone on the device's training recordings, ``--bias still`` (``gravity``, each part of
``still+gravity``) subtracts nothing beyond the profile's floor and says so; where it lay closer, or the
profile has no figure, it is applied as before. The synthetic recording's biases are the ones injected
(the oracle), independent of the estimators."""
from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from floors import refine_identity_floor, turning_robot
from imu_learn.core.still import BiasPrior
from imu_learn.infer.bias import GATE_RULE, bias_entry, bias_step

RATE = 100.0
G = 9.81
REST_S, MOVE_S = 5.0, 40.0
REST_BIAS = np.array([0.0, 0.0, 0.004])  # what the rest reads [rad/s]
MOVING_BIAS = np.array([0.003, -0.002, 0.0])  # the bias while turning: across gravity only


def robot(seed=0):
    """A level robot at rest (gyro: REST_BIAS), then turning about gravity (gyro: MOVING_BIAS;
    :func:`floors.turning_robot`)."""
    return turning_robot(REST_BIAS, MOVING_BIAS, seed, RATE, REST_S, MOVE_S, G)


def measured(**figures):
    """A profile's ``bias_prior`` with only ``rms_rad_s``: name -> (its RMS error, the profile alone's)."""
    return {"rms_rad_s": {k: {"error": e, "profile_alone": p} for k, (e, p) in figures.items()}}


def prior_of(m):
    return BiasPrior.from_bias_std([0.005] * 3, "test", measured=m)


def run(method, m):
    """(the gyro out, the summary's bias entry, the log line) of ``--bias method`` with ``bias_prior`` m."""
    t, g, a = robot()
    sink = {}
    out, _, _ = bias_step(method, G, sink, prior=prior_of(m))(t, g, a)
    entry, line = bias_entry(method, sink, "the recording")
    return g, out, entry, line


def test_still_further_than_the_profile_alone_subtracts_nothing_and_says_so():
    g, out, entry, line = run("still", measured(still=(0.0046, 0.0020)))
    # the rest was found and read (within the bound): only the gate keeps it out
    assert abs(entry["gyro_bias_rad_s"][2] - REST_BIAS[2]) < 0.0005
    assert np.array_equal(out, g)
    assert not entry["applied"] and entry["bound"]["decision"] == "gated"
    assert entry["bound"]["subtracted_rad_s"] is None
    gate = entry["gate"]
    assert gate["entered"] is False and gate["training_rms_error_rad_s"] == 0.0046
    assert gate["training_rms_profile_alone_rad_s"] == 0.0020 and gate["rule"] == GATE_RULE
    assert line.startswith("--bias still:") and "4.60 mrad/s not below the profile alone's 2.00" in line
    assert "nothing subtracted" in line


def test_still_closer_than_the_profile_alone_is_applied_as_before():
    g, out, entry, line = run("still", measured(still=(0.0010, 0.0020)))
    sub = (g - out).mean(0)
    assert entry["applied"] and entry["bound"]["decision"] == "applied" and line is None
    assert np.allclose(sub, entry["gyro_bias_rad_s"], atol=1e-12)
    assert abs(sub[2] - REST_BIAS[2]) < 0.0005  # the rest's bias, the oracle
    assert entry["gate"]["entered"] is True and entry["gate"]["training_rms_error_rad_s"] == 0.0010


@pytest.mark.parametrize("m", [None, measured(gravity=(0.001, 0.002))])
def test_still_without_a_figure_is_applied_and_says_not_measured(m):
    g, out, entry, _ = run("still", m)
    assert entry["applied"] and abs((g - out).mean(0)[2] - REST_BIAS[2]) < 0.0005
    assert entry["gate"]["measured"] is False and "not measured" in entry["gate"]["rule"]


def test_gravity_kept_out():
    g, out, entry, line = run("gravity", measured(gravity=(0.0003, 0.0003)))  # a tie is not closer
    assert entry["gyro_bias_rad_s"] is not None and np.array_equal(out, g)
    assert entry["bound"]["decision"] == "gated" and "--bias gravity:" in line


def test_still_gravity_gates_each_part():
    """Still kept out: gravity consistency's estimate alone (across gravity: the moving bias, nothing
    of the rest's z); gravity kept out: the still estimate alone; both: nothing, and it says which."""
    _, out_g, grav, _ = run("gravity", None)
    g, out, entry, _ = run("still+gravity", measured(still=(0.005, 0.002), gravity=(0.001, 0.002)))
    sub = (g - out).mean(0)
    assert entry["gate"]["still"]["entered"] is False and entry["gate"]["gravity"]["entered"] is True
    assert np.allclose(sub, (g - out_g).mean(0), atol=1e-12)
    assert np.allclose(sub[:2], MOVING_BIAS[:2], atol=0.0007) and abs(sub[2]) < 0.001
    # the still part kept out, its own summary kept (it read the rest)
    assert abs(entry["still"]["gyro_bias_rad_s"][2] - REST_BIAS[2]) < 0.0005

    g, out, entry, _ = run("still+gravity", measured(still=(0.001, 0.002), gravity=(0.003, 0.002)))
    sub = (g - out).mean(0)
    assert entry["gate"]["gravity"]["entered"] is False
    assert np.allclose(sub, entry["still"]["gyro_bias_rad_s"], atol=1e-12)

    g, out, entry, line = run("still+gravity", measured(still=(0.005, 0.002), gravity=(0.003, 0.002)))
    assert np.array_equal(out, g) and not entry["applied"] and entry["bound"]["decision"] == "none"
    assert "after the gate" in line and "5.00 mrad/s not below" in line and "3.00 mrad/s not below" in line


def test_refine_says_so(tmp_path, caplog):
    """``imu-learn refine --profile P --bias still`` with P's ``bias_prior`` keeping it out: the output
    is the floor's (identity) input, one warning line, the summary's bias entry with the figures."""
    t, g, a = robot(seed=3)
    with caplog.at_level(logging.WARNING):
        entry, g_out = refine_identity_floor(tmp_path, t, g, a, "still", measured(still=(0.0046, 0.0020)), 0.005,
                                             RATE, G)
    assert np.abs(g - g_out).max() < 1e-6
    assert entry["method"] == "still" and not entry["applied"] and entry["gate"]["entered"] is False
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("--bias still:")]
    assert len(lines) == 1 and "kept out" in lines[0]


def test_refine_says_no_bias_was_subtracted_when_the_gate_keeps_it_out(tmp_path, capsys):
    """The command's closing line and the summary's ``applied`` say what was done, not what was asked: a
    gated ``--bias still`` subtracts nothing, so neither names the still stretches' bias as removed."""
    t, g, a = robot()
    entry, g_out = refine_identity_floor(tmp_path, t, g, a, "still", measured(still=(0.0046, 0.0020)), 0.005)
    assert not entry["applied"] and np.allclose(g_out, g, atol=1e-6)
    printed = capsys.readouterr().out
    summary = json.loads((tmp_path / "o.csv.summary.json").read_text())
    for said in (printed, "; ".join(summary["applied"])):
        assert "--bias still: no bias subtracted" in said and "still stretches removed" not in said
