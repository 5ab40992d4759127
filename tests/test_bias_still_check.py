"""Gravity consistency checked against the recording's own still stretches (docs/refine.md, "The
recording's own bias"): two estimates of one gyro bias that disagree beyond their uncertainties cannot
both hold, and the still stretches measure it directly; gravity consistency's estimate is kept out of
``--bias gravity``, ``still+gravity`` and ``auto`` where it lies more than ACCEPT_SIGMAS combined sigmas
from the still stretches' along a direction it observed. The distance is checked against its closed
form; the synthetic recording's biases are the ones injected (the oracle)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from floors import turning_robot
from imu_learn.core import bias_gravity
from imu_learn.core.still import BiasPrior
from imu_learn.infer import bias as B

G = 9.81
REST_BIAS = np.array([0.0, 0.0, 0.004])
MOVING_BIAS = np.array([0.003, -0.002, 0.0])
PRIOR = BiasPrior.from_bias_std([0.01] * 3, "test")


def estimate(method, b, std):
    """A BiasEstimate with bias ``b`` and independent axes of standard deviation ``std`` (inf: not observed)."""
    std = np.asarray(std, dtype=np.float64)
    info = np.diag(np.where(np.isfinite(std), 1.0 / np.where(np.isfinite(std), std, 1.0) ** 2, 0.0))
    return B.BiasEstimate(method, np.asarray(b, dtype=np.float64), info, {})


@pytest.mark.parametrize("dx, kept", [(0.009, True), (0.010, False)])
def test_the_distance_is_the_largest_over_gravitys_observed_directions_in_combined_sigmas(dx, kept):
    still = estimate("still", [0.0, 0.0, 0.0], [0.003] * 3)
    grav = estimate("gravity", [dx, 0.002, 0.5], [0.001, 0.001, math.inf])  # z unobserved: never compared
    z = B.disagreement(grav, still)
    assert z == pytest.approx(dx / math.sqrt(0.001 ** 2 + 0.003 ** 2), rel=1e-12)
    out = B.still_checked(grav, still)
    assert (out.gyro_bias is not None) is kept
    assert out.detail["still_check"]["kept"] is kept
    if not kept:
        assert "sigma from the still stretches" in out.missing
    assert B.disagreement(grav, B.BiasEstimate("still", None, np.zeros((3, 3)), {})) is None


def fake_gravity(b):
    """gravity_bias replaced by one that returns ``b`` with x and y observed to 1 mrad/s, z not."""
    def run(t_ns, gyro, acc, settings=bias_gravity.GravitySettings()):
        return bias_gravity.GravityBias(np.asarray(b, dtype=np.float64), np.array([0.001, 0.001, 0.01]), np.eye(3),
                                        np.array([0.001, 0.001, 0.01]), np.array([0.0, 0.0, 1.0]), 0.1, 1, 4,
                                        40.0, settings)
    return run


def run(method, monkeypatch, grav_b):
    monkeypatch.setattr(B, "gravity_bias", fake_gravity(grav_b))
    t, g, a = turning_robot(REST_BIAS, MOVING_BIAS, 0, 100.0, 5.0, 40.0, G)
    sink = {}
    out, _, _ = B.bias_step(method, G, sink, prior=PRIOR)(t, g, a)
    return g, out, sink


FAR = MOVING_BIAS + np.array([0.03, 0.0, 0.0])  # 30 mrad/s off across gravity: about 9.5 combined sigmas


def test_gravity_far_from_the_still_stretches_is_kept_out_of_gravity(monkeypatch):
    g, out, sink = run("gravity", monkeypatch, FAR)
    assert np.array_equal(out, g)  # nothing subtracted beyond the profile
    assert sink["bound"].decision == "none"
    assert sink["gravity"].detail["still_check"]["kept"] is False
    entry, line = B.bias_entry("gravity", sink, "the recording")
    assert "sigma from the still stretches" in line and "no bias subtracted" in line


def test_still_gravity_falls_back_to_the_still_stretches(monkeypatch):
    g, out, sink = run("still+gravity", monkeypatch, FAR)
    est = sink["still+gravity"]
    assert est.detail["still_check"]["kept"] is False
    assert est.gyro_bias == pytest.approx(sink["still+gravity"].detail["still"]["gyro_bias_rad_s"], abs=1e-12)
    assert est.gyro_bias == pytest.approx(REST_BIAS, abs=0.0005)


def test_auto_combines_the_still_stretches_without_it(monkeypatch):
    _, _, sink = run("auto", monkeypatch, FAR)
    assert sink["auto"].detail["used"] == ["still"]


def test_gravity_that_agrees_with_the_still_stretches_is_used(monkeypatch):
    near = np.array([0.001, -0.001, 0.0])  # within a sigma of the rest's zero across gravity
    g, out, sink = run("gravity", monkeypatch, near)
    assert sink["gravity"].detail["still_check"]["kept"] is True
    assert sink["bound"].decision == "applied"
    assert np.allclose(g - out, near, atol=1e-12)
    _, _, sink = run("auto", monkeypatch, near)
    assert sink["auto"].detail["used"] == ["still", "gravity"]
