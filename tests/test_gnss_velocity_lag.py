"""GNSS velocities that lag their positions (fuse/factors/velocity.py): the lag measured from a
solution alone (velocity_lag) on synthetic tracks with a known lag, and the velocity factor at
``t_epoch - lag`` between two keyframes checked against its closed form."""
from __future__ import annotations

import numpy as np
import pytest

from imu_learn.errors import InvalidInputError
from imu_learn.fuse.aiding import rtklib
from imu_learn.fuse.aiding.types import GnssFixes
from imu_learn.fuse.factors.velocity import interpolated_velocity_factor, velocity_callback, velocity_lag

T0 = 1_752_003_258_499_000_000


def track(t: np.ndarray):
    """A car-like horizontal track [m] and its velocity [m/s]: a weave with changing speed."""
    p = np.stack([8.0 * t + 3.0 * np.sin(0.7 * t), 6.0 * np.cos(0.45 * t) + 0.4 * t ** 1.5, 0.1 * np.sin(0.3 * t)], 1)
    v = np.stack([8.0 + 2.1 * np.cos(0.7 * t), -2.7 * np.sin(0.45 * t) + 0.6 * t ** 0.5, 0.03 * np.cos(0.3 * t)], 1)
    return p, v


def solution(lag_s: float, seconds: float = 120.0, hz: float = 4.0, pos_noise: float = 0.0, seed: int = 0,
             vel=True) -> rtklib.RtkSolution:
    t = np.arange(0.0, seconds, 1.0 / hz) + 1.0
    p, _ = track(t)
    _, v = track(t - lag_s)  # each epoch's velocity is the track's lag_s earlier
    p = p + np.random.default_rng(seed).normal(0.0, pos_noise, p.shape)
    m = len(t)
    return rtklib.RtkSolution("synthetic.pos", T0 + np.round(t * 1e9).astype(np.int64), p, np.full((m, 3), 0.01),
                              v if vel else None, np.ones(m, dtype=np.int8), np.arange(m) + 2, (40.0, -105.0, 1600.0),
                              "llh")


@pytest.mark.parametrize("lag", [0.0, 0.125, 0.2])
def test_velocity_lag_recovers_a_known_lag(lag):
    got = velocity_lag(solution(lag))
    assert got.lag_s == pytest.approx(lag, abs=3e-3)
    assert got.rms_after_mps < 0.02
    if lag > 0:
        assert got.rms_after_mps < 0.2 * got.rms_before_mps


def test_velocity_lag_with_position_noise_and_mask():
    sol = solution(0.125, seconds=300.0, pos_noise=0.01, seed=3)
    got = velocity_lag(sol)
    assert got.lag_s == pytest.approx(0.125, abs=0.02)
    use = np.ones(len(sol.t_ns), bool)
    use[100:] = False  # only the first 25 s
    sub = velocity_lag(sol, use=use)
    assert sub.epochs == 98 and sub.epochs < got.epochs
    sol.q[::2] = 2  # every other epoch float: no fixed epoch has both neighbours fixed
    with pytest.raises(InvalidInputError, match="too few"):
        velocity_lag(sol)


def test_velocity_lag_refuses_a_solution_without_velocities_or_motion():
    with pytest.raises(InvalidInputError, match="no velocity columns"):
        velocity_lag(solution(0.1, vel=False))
    sol = solution(0.1)
    t = (sol.t_ns - sol.t_ns[0]) * 1e-9
    still = rtklib.RtkSolution(sol.path, sol.t_ns, np.stack([2.0 * t, 0 * t, 0 * t], 1), sol.sigma_enu,
                               np.tile([2.0, 0.0, 0.0], (len(t), 1)), sol.q, sol.lines, sol.origin_llh, "llh")
    with pytest.raises(InvalidInputError, match="never accelerates"):
        velocity_lag(still)


def test_interpolated_velocity_factor_error_is_the_closed_form():
    import gtsam
    from gtsam.symbol_shorthand import V

    rng = np.random.default_rng(1)
    v_meas, sigma = np.array([3.0, -1.0, 0.2]), 0.05
    for alpha in (0.0, 0.3, 0.75, 1.0):
        f = interpolated_velocity_factor(4, 5, alpha, v_meas, sigma)
        for _ in range(3):
            v0, v1 = rng.normal(0, 3, 3), rng.normal(0, 3, 3)
            vals = gtsam.Values()
            vals.insert(V(4), v0)
            vals.insert(V(5), v1)
            r = ((1 - alpha) * v0 + alpha * v1 - v_meas) / sigma
            assert f.error(vals) == pytest.approx(0.5 * float(r @ r), rel=1e-9)


class FakeFusion:
    """What the callback reads of an IncrementalFusion: the stamps and the keyframes' samples."""

    def __init__(self, t_ns, kf_idx):
        self.t_ns, self.kf_idx = np.asarray(t_ns, dtype=np.int64), np.asarray(kf_idx)


def test_velocity_callback_ties_the_velocity_to_its_instant():
    import gtsam
    from gtsam.symbol_shorthand import V

    t = T0 + np.arange(0, 200) * 10_000_000  # 100 Hz
    kf = np.arange(0, 200, 10)  # 10 Hz keyframes
    sol = solution(0.0, seconds=10.0)
    sol = rtklib.RtkSolution(sol.path, np.array([t[50], t[75]]), sol.enu[:2], sol.sigma_enu[:2],
                             np.array([[1.0, 2.0, 0.0], [4.0, 5.0, 0.0]]), np.array([1, 2], dtype=np.int8),
                             sol.lines[:2], sol.origin_llh, "llh")
    fixes = GnssFixes(np.array([50, 75]), sol.enu, 0.01, np.zeros(3), "gnss", sigmas=sol.sigma_enu, q=sol.q,
                      epoch=np.array([0, 1]))
    inc = FakeFusion(t, kf)
    plain = velocity_callback(fixes, sol, 0.05, 2.0)
    assert plain(inc, 5, 49) == []
    (f,) = plain(inc, 5, 50)
    assert list(f.keys()) == [V(5)]
    lagged = velocity_callback(fixes, sol, 0.05, 2.0, lag_s=0.125)
    (f,) = lagged(inc, 5, 50)  # epoch at sample 50 (0.5 s): its velocity at 0.375 s, between keyframes 3 and 4
    assert sorted(f.keys()) == sorted([V(3), V(4)])
    vals = gtsam.Values()
    vals.insert(V(3), np.zeros(3))
    vals.insert(V(4), np.array([2.0, 4.0, 0.0]))
    r = (0.25 * np.zeros(3) + 0.75 * np.array([2.0, 4.0, 0.0]) - np.array([1.0, 2.0, 0.0])) / 0.05
    assert f.error(vals) == pytest.approx(0.5 * float(r @ r))
    (f2,) = lagged(inc, 8, 75)  # a float epoch: sigma x float_gain; 0.75 - 0.125 = 0.625 s, keyframes 6 and 7
    vals2 = gtsam.Values()
    vals2.insert(V(6), np.array([4.0, 5.0, 0.0]))
    vals2.insert(V(7), np.array([4.0, 5.0, 1.0]))
    r2 = 0.25 * np.array([0.0, 0.0, 1.0]) / 0.1
    assert f2.error(vals2) == pytest.approx(0.5 * float(r2 @ r2))
    early = velocity_callback(fixes, sol, 0.05, 2.0, lag_s=0.6)  # before the first keyframe: skipped
    assert early(inc, 5, 50) == []
    with pytest.raises(InvalidInputError, match=">= 0"):
        velocity_callback(fixes, sol, 0.05, 2.0, lag_s=-0.1)


def test_config_checks_the_timing_sources():
    from imu_learn.errors import ConfigError
    from imu_learn.fuse.experiments import gnss

    cfg = gnss.GnssRunConfig(imu="a.csv", pos="b.pos")
    gnss.check(cfg)
    for key, bad, msg in (("velocity_lag_from", "fit", "velocity_lag_from"), ("delay_from", "imu", "delay_from"),
                          ("velocity_lag_s", -0.1, "velocity_lag_s")):
        with pytest.raises(ConfigError, match=msg):
            gnss.apply_override(cfg, f"{key}={bad!r}".replace("'", '"'))
            gnss.check(cfg)
        cfg = gnss.GnssRunConfig(imu="a.csv", pos="b.pos")
