"""The off-metric rule (imu_learn.calib.metric_scale.ScaleFit.off): a scale is applied (calibrate) or
refused (navigate) only where the fit with a constant accelerometer bias and the fit without it both read
it off metric, the same way. EuRoC's Vicon-room flights read 1.056 with the bias (V2_01) and 1.021
without: a motion-capture reference, metric, whose scale was applied before the rule."""
from __future__ import annotations

import pytest

from imu_learn.calib.metric_scale import SIGMAS, TOLERANCE, ScaleFit


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
