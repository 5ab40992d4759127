"""``imu-learn navigate --nhc`` through a GNSS gap, and what the NHC costs the solvers.

A synthetic car (written in the gnss-imu and RTKLIB formats) whose accelerometer gains a sideways
bias when the fixes stop (``--gaps``): only the non-holonomic constraint sees that error
there, so the drift at the gap's end tells a working constraint from a weak one (the same run with the
NHC's sigmas 1000x larger drifts as far as without it). And the cost structure that keeps ``--nhc``
near the run without it: the causal solver holds each NHC factor linearised once (no Python call
inside iSAM2) and updates for NHC factors alone at most every ``update_every_s``; the batch pass
linearises each NHC factor once per iteration."""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

gtsam = pytest.importorskip("gtsam")

from imu_learn.cli import main  # noqa: E402
from imu_learn.fuse import graph as graph_mod  # noqa: E402
from imu_learn.fuse import navigate as nav  # noqa: E402
from imu_learn.fuse.aiding import PositionFixes, rtklib  # noqa: E402
from imu_learn.fuse.factors import nhc  # noqa: E402
from imu_learn.fuse.noise import ImuNoise  # noqa: E402
from imu_learn.fuse.settings import FusionSettings  # noqa: E402
from test_navigate_gnss import H0, LAT0, START_S, write_imu_csv, write_pos, write_tag  # noqa: E402

G_UNIT = 9.80665
FS = 50  # [Hz] IMU
GAP = (22.0, 15.0)  # [s] from the first IMU sample: start, duration
BIAS = np.array([0.0, 0.15, 0.0])  # [m/s^2] body frame (sideways), from the gap's start on


def weaving_car(folder: Path, seconds: float = 45.0):
    """A level car (body x forward, z up, ENU, IMU = body): still 3 s, 2 m/s^2 for 4 s, then weaving
    at 8 m/s (yaw rate 0.15 sin(0.4 t) rad/s); the accelerometer off by ``BIAS`` from ``GAP``'s start
    on; RTKLIB fixes at 5 Hz (sigma 0.02 m). Returns (imu csv, pos file, t [s], positions (N, 3))."""
    sub = 10
    tt = np.arange(int(seconds * FS * sub)) / (FS * sub)
    acc_t = np.where((tt >= 3) & (tt < 7), 2.0, 0.0)
    speed = np.clip(2.0 * (tt - 3.0), 0.0, 8.0)
    rate = np.where(tt >= 7, 0.15 * np.sin(0.4 * (tt - 7)), 0.0)
    psi = np.radians(20.0) + np.concatenate([[0.0], np.cumsum((rate[1:] + rate[:-1]) / 2) / (FS * sub)])
    vel = np.stack([speed * np.cos(psi), speed * np.sin(psi), np.zeros_like(tt)], axis=1)
    pos = np.concatenate([np.zeros((1, 3)), np.cumsum((vel[1:] + vel[:-1]) / 2, axis=0) / (FS * sub)])
    g = rtklib.normal_gravity(LAT0, H0)
    f_body = np.stack([acc_t, speed * rate, np.full_like(tt, g)], axis=1) + (tt >= GAP[0])[:, None] * BIAS
    i = np.arange(0, len(tt), sub)
    imu = folder / "imu_0001.csv"
    n = len(i)
    write_imu_csv(imu, f_body[i] / G_UNIT, np.degrees(np.stack([0 * tt, 0 * tt, rate], axis=1)[i]),
                  5000 + (1000 // FS) * np.arange(n))
    write_tag(imu.with_name(imu.name + ".tag"), START_S, 0.0, (1000 // FS) * (n - 1))
    k = np.arange(0, len(tt) - sub, FS * sub // 5)
    q = np.ones(len(k), dtype=int)
    pos_file = folder / "gnss_0001.pos"
    write_pos(pos_file, START_S + tt[k] + 0.002, pos[k], vel[k], q)
    return imu, pos_file, tt[i], pos[i]


def gap_drift(folder: Path, t: np.ndarray, p: np.ndarray, extra: list, name: str, capsys) -> float:
    """The causal estimate's horizontal error [m] at its last keyframe inside the gap."""
    imu, pos = folder / "imu_0001.csv", folder / "gnss_0001.pos"
    out = folder / name
    rc = main(["navigate", "--quiet", "--input", str(imu), "--format", "gnss-imu", "--aiding", str(pos),
               "--imu-noise", "1e-4,1e-3,1e-5,1e-4", "--keyframe-hz", "5",
               "--gaps", f"{GAP[0]:g}:{GAP[1]:g}", "--out", str(out), *extra])
    assert rc == 0, capsys.readouterr().err
    d = np.loadtxt(out / "causal.tum", ndmin=2)
    ts = d[:, 0] - START_S
    inside = np.flatnonzero(ts < GAP[0] + GAP[1] - 0.05)[-1]
    truth = np.array([np.interp(ts[inside], t, p[:, k]) for k in range(3)])
    return float(np.linalg.norm(d[inside, 1:3] - truth[:2]))


def test_nhc_holds_the_drift_through_a_gnss_gap_and_a_1000x_weaker_one_does_not(tmp_path, capsys, monkeypatch):
    _imu, _pos, t, p = weaving_car(tmp_path)
    raw = gap_drift(tmp_path, t, p, [], "raw", capsys)
    with_nhc = gap_drift(tmp_path, t, p, ["--nhc"], "nhc", capsys)
    # 15 s of 0.15 m/s^2 sideways: 16 m unaided; the NHC holds the sideways velocity (4.1 m)
    assert raw > 8.0, raw
    assert with_nhc < 0.4 * raw, (with_nhc, raw)
    # the same constraint 1000x weaker (sigmas 100 m/s): the bound above fails
    real = nav.NhcSettings
    monkeypatch.setattr(nav, "NhcSettings", lambda lat, vert, **kw: real(1000 * lat, 1000 * vert, **kw))
    weak = gap_drift(tmp_path, t, p, ["--nhc"], "weak", capsys)
    assert weak > 0.9 * raw, (weak, with_nhc, raw)  # (16 m: as without it)


# --- cost structure ------------------------------------------------------------------------------

def drive(seconds: float = 30.0, fs: int = 100):
    """A level car at 10 m/s weaving (yaw rate 0.1 sin(0.3 t)); exact IMU, fixes at 2 Hz."""
    t = np.arange(int(seconds * fs)) / fs
    rate = 0.1 * np.sin(0.3 * t)
    psi = np.concatenate([[0.0], np.cumsum((rate[1:] + rate[:-1]) / 2) / fs])
    vel = 10.0 * np.stack([np.cos(psi), np.sin(psi), 0 * t], axis=1)
    pos = np.concatenate([np.zeros((1, 3)), np.cumsum((vel[1:] + vel[:-1]) / 2, axis=0) / fs])
    acc = np.stack([0 * t, 10.0 * rate, np.full_like(t, 9.81)], axis=1)
    gyro = np.stack([0 * t, 0 * t, rate], axis=1)
    idx = np.arange(0, len(t), fs // 2)
    fixes = PositionFixes(idx=idx, p=pos[idx], sigma_m=0.05, lever=np.zeros(3), label="fix")
    return np.round(t * 1e9).astype(np.int64), gyro, acc, fixes, (np.eye(3), pos[0], vel[0])


def test_the_nhc_is_linearised_once_per_factor_causally_and_once_per_iteration_smoothing(monkeypatch):
    t_ns, gyro, acc, fixes, start = drive()
    noise = ImuNoise(gyro_noise_density=1e-4, acc_noise_density=1e-3, gyro_random_walk=1e-5, acc_random_walk=1e-4)
    settings = FusionSettings(noise=noise, gravity=9.81, keyframe_hz=10.0)
    calls = {"n": 0}
    real = nhc.nhc_jacobians
    monkeypatch.setattr(nhc, "nhc_jacobians", lambda R, v: calls.__setitem__("n", calls["n"] + 1) or real(R, v))
    runs = {}
    for name, hook in (("raw", None), ("nhc", nhc.nhc_callback(nhc.NhcSettings(0.1, 0.1), gyro))):
        inc = graph_mod.IncrementalFusion(t_ns, start, [fixes], settings, predict_between=False, extra_factors=hook)
        calls["n"] = 0
        graph_mod.feed(inc, graph_mod.samples_of(gyro, acc))
        runs[name] = dict(inc.counts, causal_calls=calls["n"])
        ticks = []
        calls["n"] = 0
        inc.smooth(progress=ticks.append)
        runs[name].update(smooth_calls=calls["n"], ticks=len(ticks))
    n_nhc = runs["nhc"]["extra_factors"]
    assert n_nhc == runs["nhc"]["imu_factors"] + 1  # one at every keyframe
    assert runs["nhc"]["causal_calls"] == n_nhc  # held at its keyframe's prediction: no call inside iSAM2
    # NHC factors alone update at most every update_every_s (0.5 s), on top of the 2 Hz fixes' updates
    assert runs["nhc"]["isam2_updates"] <= runs["raw"]["isam2_updates"] + math.ceil(30.0 / 0.5)
    # the batch pass: each NHC factor linearised once per iteration (plus the true error's calls: none
    # need Jacobians), and a progress tick per iteration
    assert runs["nhc"]["ticks"] >= 1 and runs["raw"]["ticks"] >= 1
    assert runs["nhc"]["smooth_calls"] == n_nhc * runs["nhc"]["ticks"]


def test_update_every_s_is_checked():
    with pytest.raises(Exception, match="update_every_s"):
        nhc.NhcSettings(update_every_s=-1.0)
    assert replace(nhc.NhcSettings(), update_every_s=0.0).update_every_s == 0.0


def test_summary_counts_the_nhc_factors(tmp_path, capsys):
    _imu, _pos, _t, _p = weaving_car(tmp_path, seconds=12.0)
    out = tmp_path / "nav"
    rc = main(["navigate", "--quiet", "--input", str(tmp_path / "imu_0001.csv"), "--format", "gnss-imu", "--aiding",
               str(tmp_path / "gnss_0001.pos"), "--imu-noise", "1e-4,1e-3,1e-5,1e-4", "--nhc", "--gnss-velocity-sigma", "0", "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    s = json.loads((out / "summary.json").read_text())
    assert s["counts"]["extra_factors"] == s["keyframes"]
    q = np.loadtxt(out / "smoothed.tum", ndmin=2)[:, 4:8]
    assert np.all(np.isfinite(Rotation.from_quat(q).as_euler("ZYX")))
