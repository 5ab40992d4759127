"""The timing floor's search cost in the core (core.integration.offset_rotation_angles) against its
numpy oracle: the gyro resampled by ``timing.resample`` (np.interp), integrated by ``integrate_windows``
and compared by ``quat.rotation_angle``; on jittered stamps, offsets inside and beyond the ends."""
from __future__ import annotations

import numpy as np
import pytest

from imu_learn.baselines.timing import RotationWindows, resample
from imu_learn.core.integration import (
    PAPER_FRACTIONS,
    integrate_windows,
    offset_rotation_angles,
    preintegrate,
    window_labels,
)
from imu_learn.core.quat import rotation_angle
from imu_learn.data.types import Segment, median_period_ns
from imu_learn.errors import InvalidInputError


def recording(n: int = 6000, seed: int = 0) -> Segment:
    """A jittered 200 Hz recording; its reference the integral of 0.9 x the gyro (a scale error)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.integers(4_900_000, 5_100_000, n)).astype(np.int64) + 10**15
    g, a = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    pre = preintegrate(t, 0.9 * g, np.zeros_like(g))
    return Segment("rec", t, g, a, np.zeros((n, 3)), np.zeros((n, 3)), pre.dq_wxyz)


def oracle(s: Segment, lab, tau: float, per: float) -> np.ndarray:
    g = resample(s.t_ns, s.gyro, tau, per)
    inc = integrate_windows(Segment(s.name, s.t_ns, g, s.acc, s.p, s.v, s.q_wxyz), lab.starts, lab.horizons)
    return rotation_angle(lab.dq_wxyz, inc.dq_wxyz).ravel()


@pytest.mark.parametrize("tau", [0.0, 0.5, -0.37, 1e-9, 2.9, -3.0, 7000.0, -7000.0])
def test_the_core_cost_equals_resample_integrate_and_compare_in_numpy(tau):
    s = recording()
    lab = window_labels(s, 10, 7, PAPER_FRACTIONS, 9.81)
    per = median_period_ns(s.t_ns)
    ref = oracle(s, lab, tau, per)
    got = offset_rotation_angles(s.t_ns, s.gyro, lab, tau, per)
    assert got.shape == ref.shape and np.max(ref) > 1e-3
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-15)


def test_the_search_cost_is_the_numpy_one_at_every_offset():
    """RotationWindows.cost (the offset search) through the core, against the oracle's Huber mean."""
    segs = [recording(4000, 1), recording(3000, 2)]
    w = RotationWindows(segs, 10, 500)
    for tau in (0.0, 0.5, -1.25):
        a = np.concatenate([oracle(s, lab, tau, per) for s, per, lab in w.items])
        huber = float(np.mean(np.where(a <= 0.01, 0.5 * a * a, 0.01 * (a - 0.005))))
        assert w.cost(tau, 0.01) == pytest.approx(huber, rel=1e-12)


def test_bad_inputs_are_named():
    s = recording(200)
    lab = window_labels(s, 10, 7, PAPER_FRACTIONS, 9.81)
    per = median_period_ns(s.t_ns)
    with pytest.raises(InvalidInputError, match="dq_ref"):
        offset_rotation_angles(s.t_ns, s.gyro, type(lab)(**{**lab.__dict__, "dq_wxyz": lab.dq_wxyz[:-1]}), 0.5, per)
    with pytest.raises(InvalidInputError, match="finite"):
        offset_rotation_angles(s.t_ns, s.gyro, lab, float("nan"), per)
    with pytest.raises(InvalidInputError):
        offset_rotation_angles(s.t_ns[::-1].copy(), s.gyro, lab, 0.5, per)


@pytest.mark.parametrize("kind", ["many", "two", "half", "outliers"])
def test_the_sample_period_is_numpys_median_with_few_or_many_distinct_periods(kind):
    """median_period_ns's shortcut (a candidate that holds both middle ranks) against np.median: periods
    drawn from many values, from two (EuRoC's 4999936/5000192 ns) in any share, exactly half and half (an
    even count: the median is their mean), one period with outliers; short and long, alone and pooled."""
    rng = np.random.default_rng(len(kind))
    for trial in range(300):
        n = int(rng.integers(2, 40)) if trial % 3 else int(rng.integers(40, 5000))
        if kind == "many":
            d = rng.integers(4_000_000, 6_000_000, n)
        elif kind == "two":
            d = np.where(rng.random(n) < rng.random(), 4_999_936, 5_000_192)
        elif kind == "half":
            n += n % 2
            d = rng.permutation(np.repeat([4_999_936, 5_000_192], n // 2))
        else:
            d = np.where(rng.random(n) < 0.02, 10_000_000, 5_000_000)
        t = np.concatenate(([0], np.cumsum(d))).astype(np.int64)  # its periods are d
        parts = (t[: n // 3], t[n // 3:]) if trial % 2 else (t,)
        want = np.median(np.concatenate([np.diff(p) for p in parts if len(p) > 1]))
        assert median_period_ns(*parts) == want, (trial, n)
    assert median_period_ns(t[:1]) == 0.0 and median_period_ns() == 0.0
