"""The GNSS outage experiment's start at rest (fuse/start/track.py ``start_at = "still"``) and its gyro
bias prior from the still start (fuse/experiments/gnss.py ``bias_prior = "still"``, ``still_se_k``):
the heading the track gives carried back to the still start, the still mean's standard error over
distinct rows, the prior the graph is handed, and the refusal of an outage before the heading is
known."""
from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from imu_learn.data.formats import gnss_imu
from imu_learn.errors import ConfigError, InvalidInputError
from imu_learn.fuse.aiding import rtklib
from imu_learn.fuse.start.track import GnssStartSettings, gnss_start
from test_gnss_imu import pos_line, write_pos, write_tag

G = 9.8


def turning_start(fs: float = 100.0, bias=(0.0, 0.0, 0.0), repeat: bool = False):
    """In memory: 3 s at rest, a 90 deg turn about z in 2 s, then 5 s of motion along 30 deg (east
    towards north) at 1.5 m/s; the IMU level, ``bias`` [rad/s] on the gyro; GNSS at 4 Hz. With
    ``repeat`` every other row of the still start repeats the one before (a logger faster than its
    sensor)."""
    n = int(10 * fs)
    t = np.arange(n) / fs
    gyro = np.tile(np.asarray(bias, dtype=np.float64), (n, 1))
    turn = (t >= 3.0) & (t < 5.0)
    gyro[turn, 2] += math.radians(45.0)
    rng = np.random.default_rng(0)
    gyro += rng.normal(0.0, 1e-4, gyro.shape)
    acc = np.tile([0.0, 0.0, G], (n, 1))
    if repeat:
        still = np.flatnonzero(t < 3.0)
        gyro[still[1::2]] = gyro[still[0::2][:len(still[1::2])]]
    t_ns = (t * 1e9).astype(np.int64) + 10**18
    te = np.arange(0.0, 10.0, 0.25)
    psi = math.radians(30.0)
    vel = np.where(te[:, None] >= 5.0, 1.5 * np.array([math.cos(psi), math.sin(psi), 0.0]), 0.0)
    enu = np.cumsum(vel * 0.25, axis=0)
    sol = SimpleNamespace(t_ns=(te * 1e9).astype(np.int64) + 10**18, enu=enu, vel_enu=vel,
                          q=np.ones(len(te), np.int8), path="synthetic.pos")
    return SimpleNamespace(t_ns=t_ns, gyro=gyro, acc=acc), sol


def yaw_deg(R: np.ndarray) -> float:
    return math.degrees(math.atan2(R[1, 0], R[0, 0]))


def test_still_start_carries_the_tracks_heading_back_to_rest():
    imu, sol = turning_start(bias=(0.0, 0.0, 0.01))
    track = gnss_start(imu, sol, G, GnssStartSettings(level_s=2.0, yaw_min_speed_mps=1.0))
    still = gnss_start(imu, sol, G, GnssStartSettings(level_s=2.0, yaw_min_speed_mps=1.0, start_at="still"))
    assert track["s0"] == 500 and abs(yaw_deg(track["R0"]) - 30.0) < 0.5
    # at rest, before the 90 deg turn: 30 - 90 deg, level, at the first fix with zero velocity
    assert still["s0"] == 0 and still["start_at"] == "still"
    assert abs(yaw_deg(still["R0"]) + 60.0) < 0.5
    np.testing.assert_allclose(still["R0"][2], [0.0, 0.0, 1.0], atol=1e-3)
    np.testing.assert_allclose(still["v0"], 0.0)
    np.testing.assert_allclose(still["p0"], sol.enu[0], atol=1e-9)
    assert still["heading_s_after_first_epoch"] == pytest.approx(5.0, abs=0.01)
    # the still start's gyro mean is the bias
    np.testing.assert_allclose(still["gyro_still"], [0.0, 0.0, 0.01], atol=1e-4)
    with pytest.raises(InvalidInputError, match="start_at"):
        gnss_start(imu, sol, G, GnssStartSettings(level_s=2.0, start_at="moving"))


def test_still_mean_standard_error_counts_distinct_rows():
    imu, sol = turning_start()
    imu_r, _ = turning_start(repeat=True)
    a = gnss_start(imu, sol, G, GnssStartSettings(level_s=2.0))
    b = gnss_start(imu_r, sol, G, GnssStartSettings(level_s=2.0))
    assert a["still_distinct_rows"] == 200 and b["still_distinct_rows"] == 100
    np.testing.assert_allclose(a["gyro_still_se"], 1e-4 / math.sqrt(200), rtol=0.15)
    # repeated rows add no information: the standard error grows by sqrt(2)
    np.testing.assert_allclose(b["gyro_still_se"] / a["gyro_still_se"], math.sqrt(2), rtol=0.2)


def turning_drive(tmp_path: Path, bias_dps=(0.3, -0.2, 0.5), scale_z: float = 1.02, seconds: float = 40.0) -> Path:
    """Still for 5 s, then along 30 deg at 0.5 m/s^2 up to 5 m/s, a 240 deg left turn at 20 deg/s from
    8 s to 20 s, straight after; a level IMU at 100 Hz whose gyro reads ``bias_dps`` [deg/s] more than
    the truth and its z axis ``scale_z`` times the rate (a scale error the graph does not model); fixes
    and velocities at 4 Hz."""
    g = rtklib.normal_gravity(40.0, 1600.0)
    fs, n = 100, int(seconds * 100)
    tt = np.arange(n) / fs
    speed = np.clip(0.5 * (tt - 5.0), 0.0, 5.0)
    a_fwd = np.where((tt > 5.0) & (speed < 5.0), 0.5, 0.0)
    rate = np.where((tt >= 8.0) & (tt < 20.0), math.radians(20.0), 0.0)
    psi = math.radians(30.0) + np.cumsum(rate) / fs
    f_body = np.stack([a_fwd, speed * rate, np.full(n, g)], axis=1)  # forward, centripetal, up
    gyro_dps = np.degrees(np.stack([np.zeros(n), np.zeros(n), scale_z * rate], axis=1)) + np.asarray(bias_dps)
    d = tmp_path / "rec"
    d.mkdir(parents=True)
    text = "".join(f"{f[0] / 9.80665:.6f},{f[1] / 9.80665:.6f},{f[2] / 9.80665:.6f},{w[0]:.4f},{w[1]:.4f},"
                   f"{w[2]:.4f},{5000 + 10 * i}\n" for i, (f, w) in enumerate(zip(f_body, gyro_dps)))
    (d / "imu.csv").write_text("0.5,1\n" + text)
    start_s = 1752003261
    write_tag(d / "imu.csv.tag", end_ms=10 * (n - 1), start_s=start_s, frac=0.0)
    vel = np.stack([speed * np.cos(psi), speed * np.sin(psi), np.zeros(n)], axis=1)
    pos = np.cumsum(vel, axis=0) / fs
    x0 = rtklib.llh_to_ecef(40.0, -105.0, 1600.0)
    Rn = rtklib.ecef_to_enu_rotation(40.0, -105.0)
    lines = []
    for k in range(int((seconds - 0.3) * 4)):
        i = 25 * k
        llh = rtklib.ecef_to_llh(x0 + Rn.T @ pos[i])
        stamp = f"{np.datetime_as_string(np.datetime64(start_s + i // 100, 's')).replace('-', '/').replace('T', ' ')}" \
                f".{(i % 100) * 10:03d}"
        lines.append(pos_line(stamp, *llh, q=1, sd=(0.01, 0.01, 0.01), v=(vel[i, 1], vel[i, 0], 0.0)))
    write_pos(d / "gnss.pos", lines)
    return d


class Captured(Exception):
    pass


def captured_prior(tmp_path: Path, monkeypatch, **kw):
    """The prior and bias mean the experiment hands the graph for ``turning_drive`` (the graph stubbed)."""
    from imu_learn.fuse.experiments import gnss as gnss_run

    seen = {}

    def stub(t, start_pose, aiding, settings, bias0, **_kw):
        seen.update(prior=settings.prior, bias0=bias0, R0=start_pose[0])
        raise Captured

    monkeypatch.setattr(gnss_run, "IncrementalFusion", stub)
    turning_drive(tmp_path)
    cfg = gnss_run.GnssRunConfig(name="turning", data_root=str(tmp_path), imu="rec/imu.csv", pos="rec/gnss.pos",
                                 level_s=3.0, earth_rate=False, variants=["raw"], prior_bias_gyro=0.05, **kw,
                                 outages=gnss_run.OutageCfg(first_s=20.0, duration_s=15.0, period_s=45.0,
                                                            end_margin_s=2.0))
    with pytest.raises(Captured):
        gnss_run.experiment(cfg)
    return seen


def test_gyro_bias_prior_from_the_still_mean(tmp_path, monkeypatch):
    """``bias_prior = "still"`` with ``still_se_k``: the gyro bias prior is the still start's mean gyro
    (the IMU's bias, 0.3, -0.2, 0.5 deg/s here) held to k standard errors of that mean; without
    ``still_se_k`` to ``prior_bias_gyro``; ``bias_prior = "zero"``: mean zero. ``prior_yaw_deg`` holds
    the heading apart from the tilt."""
    zero = captured_prior(tmp_path / "a", monkeypatch)
    assert zero["bias0"] is None and zero["prior"].bias_gyro == 0.05 and zero["prior"].yaw_rad is None
    loose = captured_prior(tmp_path / "b", monkeypatch, bias_prior="still")
    assert loose["prior"].bias_gyro == 0.05
    held = captured_prior(tmp_path / "c", monkeypatch, bias_prior="still", still_se_k=3.0, prior_yaw_deg=30.0,
                          start_at="still")
    from imu_learn.fuse.experiments import gnss as gnss_run

    np.testing.assert_allclose(held["bias0"][:3], np.radians([0.3, -0.2, 0.5]), atol=2e-5)
    # the CSV's rows are identical at rest: a standard error of zero, floored
    assert held["prior"].bias_gyro == gnss_run.MIN_BIAS_SIGMA
    assert held["prior"].yaw_rad == pytest.approx(math.radians(30.0))
    assert abs(yaw_deg(held["R0"]) - 30.0) < 0.5  # at rest, before the turn: the track's heading


def test_outage_before_the_heading_is_refused(tmp_path):
    from imu_learn.fuse.experiments import gnss as gnss_run

    turning_drive(tmp_path)
    cfg = gnss_run.GnssRunConfig(name="early", data_root=str(tmp_path), imu="rec/imu.csv", pos="rec/gnss.pos",
                                 level_s=3.0, earth_rate=False, start_at="still",
                                 outages=gnss_run.OutageCfg(first_s=4.0, duration_s=5.0, period_s=45.0,
                                                            end_margin_s=2.0))
    with pytest.raises(InvalidInputError, match="before the start's heading"):
        gnss_run.experiment(cfg)
    with pytest.raises(ConfigError, match="start_at"):
        gnss_run.check(gnss_run.GnssRunConfig(imu="a", pos="b", start_at="moving"))


def test_mounting_unchanged_by_still_start():
    """The still start's attitude is the levelled one turned about the vertical only: a tilted IMU
    keeps its tilt."""
    imu, sol = turning_start()
    M = gnss_imu.mounting_rotation([5.0, -3.0, 0.0])
    imu.acc = imu.acc @ M  # an IMU tilted by the mounting
    st = gnss_start(imu, sol, G, GnssStartSettings(level_s=2.0, start_at="still"))
    up_body = st["R0"].T @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(up_body, M.T @ np.array([0.0, 0.0, 1.0]), atol=1e-3)
