"""The off-metric rule (imu_learn.calib.metric_scale.ScaleFit.off): a scale is applied (calibrate) or
refused (navigate) only where the fit with a constant accelerometer bias and the fit without it both read
it off metric, the same way. EuRoC's Vicon-room flights read 1.056 with the bias (V2_01) and 1.021
without: a motion-capture reference, metric, whose scale was applied before the rule. And the cause an
implausible scale is given (imu_learn.calib.plausible): a unit only where the scale reads like one."""
from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from imu_learn.calib.metric_scale import SIGMAS, TOLERANCE, ScaleFit
from imu_learn.calib.reference import FrameFit, frame_lines
from imu_learn.fuse.navigate import NavigateOptions, Sources, check_scale


def fit(scale: float, std: float = 0.005, without: float = None) -> ScaleFit:
    other = None if without is None else ScaleFit(without, std, 1000, 0.5)
    return ScaleFit(scale, std, 1000, 0.5, "", other)


@pytest.mark.parametrize("scale, without, off", [
    (1.056, 1.021, False),  # V2_01's motion capture: the bias and the scale trade
    (0.9446, 0.9476, True),  # ORB-SLAM2's positions x0.93 on four flights: both off
    (2.50, 2.52, True),  # a monocular VO x0.4
    (1.08, 0.93, False),  # off both ways: not one scale
    (1.03, 1.20, False),  # the fit with the bias within tolerance: never off
    (1.08, None, True),  # no bias fitted (navigate): the one reading decides
])
def test_a_scale_is_off_metric_only_where_both_readings_say_so(scale, without, off):
    assert fit(scale, without=without).off is off


def test_the_second_reading_needs_its_own_standard_errors():
    noisy = ScaleFit(1.08, 0.005, 1000, 0.5, "", ScaleFit(1.07, (0.07 - 1e-3) / SIGMAS, 1000, 0.5))
    assert TOLERANCE < 0.07 and noisy.off
    noisier = ScaleFit(1.08, 0.005, 1000, 0.5, "", ScaleFit(1.07, (0.07 + 1e-3) / SIGMAS, 1000, 0.5))
    assert not noisier.off


@pytest.mark.parametrize("sensor, diag, cause", [
    ("accelerometer", 9.81, "an acc unit off (g read as m/s^2: 9.8x)"),
    ("accelerometer", 12.0, "an acc unit off"),  # g read as m/s^2 with a scale error on top
    ("accelerometer", 0.78, "not a unit mistake (that reads x9.81 or x0.102)"),  # one flight's V2_01
    ("gyroscope", 57.0, "a gyro unit off (deg/s read as rad/s: 57x)"),
    ("gyroscope", 0.55, "not a unit mistake (that reads x57.3 or x0.0175)"),  # Fetch's x scale, one recording
])
def test_an_implausible_scale_names_a_unit_only_where_it_reads_like_one(sensor, diag, cause):
    import numpy as np

    from imu_learn.baselines.affine import TraditionalParams
    from imu_learn.calib.plausible import parameter_findings

    p = TraditionalParams.identity()
    m = np.eye(3)
    m[1, 1] = diag
    p = TraditionalParams.from_dict({**p.to_dict(), ("M_a" if sensor == "accelerometer" else "M_g"): m.tolist()})
    found = [f for f in parameter_findings(p, None) if f.field == f"{sensor}.matrix[1][1]"]
    assert len(found) == 1 and cause in found[0].message


def test_a_scale_the_data_cannot_tell_is_said_not_passed_over(caplog):
    """navigate (the poses' scale) and calibrate (the reference's) say where the metric-scale check saw too
    little (Fetch's motion capture with its dropouts: no triple of rows): a unit mistake would pass there."""
    blind = ScaleFit(None, None, 0, 0.5, "0 reference triples over 0.5 s; 50 needed")
    with caplog.at_level(logging.WARNING, logger="imu_learn.fuse.navigate"):
        check_scale(Sources(Path("rec"), Path("mocap.csv")), NavigateOptions(aiding_kind="pose"), blind)
    assert any("metric scale is not checked (0 reference triples" in r.getMessage() for r in caplog.records)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="imu_learn.fuse.navigate"):
        check_scale(Sources(Path("rec"), Path("mocap.csv")), NavigateOptions(aiding_kind="pose"), fit(1.0))
    assert not caplog.records
    frame = FrameFit(np.eye(3), 0.1, 0.01, 0.01, 1.0, 0.0, 0.9, np.zeros(3), 1.01, 0.02, np.zeros(3), np.zeros(3), 0.5,
                     np.array([[0, 0, 9.81]]), 100.0, scale_not_observed=blind.reason)
    lines = frame_lines(frame)
    assert any("from the joint fit alone, not applied (the metric-scale check did not observe it: 0 reference" in x
               for x in lines), lines
    assert "did not observe it" in frame.to_dict()["scale_from"]
    assert not any("joint fit alone" in x for x in frame_lines(replace(frame, scale_not_observed="")))
