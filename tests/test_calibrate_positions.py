"""A device profile from positions only (imu_learn.fuse.calibrate_positions): attitude a latent state of the
navigator's smoother, the bias-only floor fitted against its smoothed trajectory and iterated.

Fast: a synthetic car (turns, grades, an IMU mounted upside down and yawed, constant gyro and acc
biases, white noise) with 10 Hz position fixes (+2 cm noise) written as an ASL recording and a TUM
positions file; the biases must come back. Slow (``-m slow``): ``imu-learn calibrate`` on the real car
drive with its RTKLIB ``.pos`` file."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_learn.calib.profile import Profile
from imu_learn.cli import main
from imu_learn.data.formats.gnss_imu import mounting_rotation
from imu_learn.fuse import calibrate_positions as P

G = 9.81
B_G = np.array([0.004, -0.003, 0.005])  # rad/s, IMU frame
B_A = np.array([0.12, -0.08, 0.15])  # m/s^2, IMU frame
RPY = (180.0, 0.0, 90.0)  # the IMU's mounting: body (x forward, z up) = M imu
T0_NS = 1_000_000_000_000


def synthetic_drive(folder: Path, seconds: float = 90.0, seed: int = 0, imu_late_s: float = 0.0,
                    tilt: float = 1.0, cruise: float = 8.0):
    """ASL recording ``folder/car`` (IMU with biases and noise; its stamps ``imu_late_s`` late, a logging
    delay) and ``folder/fixes.tum`` (positions). ``tilt`` scales the pitch and roll rates (the roll the
    track cannot tell wanders to tens of degrees at 1); ``cruise`` the mean speed [m/s] (a walker's 1.5)."""
    rng = np.random.default_rng(seed)
    fs, sub = 100, 10
    dt = 1.0 / (fs * sub)
    tt = np.arange(int(seconds * fs * sub) + 1) * dt
    moving = np.clip((tt - 3.0) / 5.0, 0.0, 1.0)  # still for 3 s, then speeding up over 5 s
    speed = moving * cruise * (1.0 + 0.25 * np.sin(0.3 * tt))
    dspeed = np.gradient(speed, dt)
    w = np.stack([tilt * 0.04 * np.sin(2 * np.pi * tt / 5.0), tilt * 0.05 * np.sin(2 * np.pi * tt / 9.0),
                  0.3 * np.sin(2 * np.pi * tt / 20.0) + 0.15 * np.sin(2 * np.pi * tt / 7.0)], axis=1) * moving[:, None]
    R = np.empty((len(tt), 3, 3))
    R[0] = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    steps = Rotation.from_rotvec(0.5 * (w[1:] + w[:-1]) * dt).as_matrix()
    for k in range(1, len(tt)):
        R[k] = R[k - 1] @ steps[k - 1]
    v = R[:, :, 0] * speed[:, None]
    p = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (v[1:] + v[:-1]) * dt, axis=0)])
    f_body = np.cross(w, np.stack([speed, 0 * speed, 0 * speed], 1)) + np.stack([dspeed, 0 * speed, 0 * speed], 1)
    f_body += np.einsum("nji,j->ni", R, np.array([0.0, 0.0, G]))
    i = np.arange(0, len(tt), sub)
    M = mounting_rotation(RPY)
    gyro = w[i] @ M + B_G + rng.normal(0, 1e-3 * np.sqrt(fs), (len(i), 3))
    acc = f_body[i] @ M + B_A + rng.normal(0, 1e-2 * np.sqrt(fs), (len(i), 3))
    t_ns = T0_NS + np.round((tt[i] + imu_late_s) * 1e9).astype(np.int64)
    rec = folder / "car"
    (rec / "mav0" / "imu0").mkdir(parents=True)
    with open(rec / "mav0" / "imu0" / "data.csv", "w") as fh:
        fh.write("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                 "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n")
        for t, g, a in zip(t_ns, gyro, acc):
            fh.write(f"{t},{g[0]:.9f},{g[1]:.9f},{g[2]:.9f},{a[0]:.9f},{a[1]:.9f},{a[2]:.9f}\n")
    k = np.arange(0, len(tt), fs * sub // 10)  # fixes at 10 Hz
    noisy = p[k] + rng.normal(0, 0.02, (len(k), 3))
    fixes = folder / "fixes.tum"
    fixes.write_text("".join(f"{(T0_NS * 1e-9 + tt[j]):.6f} {x:.4f} {y:.4f} {z:.4f}\n" for j, (x, y, z) in zip(k, noisy)))
    return rec, fixes


def test_positions_reference_is_recognised(tmp_path):
    rec, fixes = synthetic_drive(tmp_path, seconds=12.0)
    assert P.is_positions_reference(fixes)
    six = tmp_path / "pose.tum"
    six.write_text("".join(f"{i * 0.1:.1f} 0 0 0 {np.sin(i * 0.05):.6f} 0 0 {np.cos(i * 0.05):.6f}\n" for i in range(50)))
    assert not P.is_positions_reference(six)
    const = tmp_path / "const.tum"  # positions written as TUM with a constant quaternion
    const.write_text("".join(f"{i * 0.1:.1f} {i:.1f} 0 0 0 0 0 1\n" for i in range(50)))
    assert P.is_positions_reference(const)


def test_forward_axis_from_the_track(tmp_path):
    rec, fixes = synthetic_drive(tmp_path, seconds=60.0)
    from imu_learn.data import formats
    from imu_learn.fuse.mounting import forward_mounting

    src = formats.read_imu_source(rec)
    t, p, g, fmt = P.read_fixes(fixes)
    est = forward_mounting(src.t_ns, src.acc, t, p, g)
    M = mounting_rotation(RPY)
    fwd = np.asarray(est["forward_imu"])
    assert np.degrees(np.arccos(np.clip(fwd @ M[0], -1, 1))) < 3.0  # the body x-axis in the IMU frame
    assert np.degrees(np.arccos(np.clip(np.asarray(est["up_imu"]) @ M[2], -1, 1))) < 3.0


def test_a_given_mounting_is_checked_against_the_tracks_forward_axis(tmp_path):
    """navigate --nhc's check (fuse.mounting.mounting_check): the true mounting agrees with the track's
    forward axis within a few degrees; one turned 90 deg about the vertical, or none (the IMU's own axes),
    is named (the real drive: 0.5 deg with the docs' mounting, 89.7 turned 90, 171 without one)."""
    from imu_learn.data import formats
    from imu_learn.fuse.mounting import MOUNT_TOL_DEG, mounting_check

    rec, fixes = synthetic_drive(tmp_path, seconds=60.0)
    src = formats.read_imu_source(rec)
    t, p, g, fmt = P.read_fixes(fixes)
    good = mounting_check(src.t_ns, src.acc, t, p, mounting_rotation(RPY), g)
    assert good["checked"] and good["ok"] and good["angle_deg"] < 3.0
    turned = mounting_check(src.t_ns, src.acc, t, p, mounting_rotation((RPY[0], RPY[1], RPY[2] + 90.0)), g)
    assert turned["checked"] and not turned["ok"] and abs(turned["angle_deg"] - 90.0) < 5.0
    none = mounting_check(src.t_ns, src.acc, t, p, None, g)
    assert none["ok"] == (np.degrees(np.arccos(np.clip(mounting_rotation(RPY)[0, 0], -1, 1))) <= MOUNT_TOL_DEG)
    slow = mounting_check(src.t_ns, src.acc, t[:10], p[:10], None, g)  # too few fast fixes: not checked
    assert not slow["checked"] and "--imu-rotation-rpy-deg" in slow["why"]


def test_a_slow_track_gives_the_mounting_above_1_mps(tmp_path):
    """calibrate's mounting from a walker's track (fuse.mounting.mounting_from_track): no fix over 3 m/s,
    so the forward axis the track shows over 1 m/s (navigate's rule), up from the start (the real walk
    was refused, "0 fixes faster than 3 m/s"); a track that shows no forward axis leaves the IMU's own
    axes, refused where --nhc needs one."""
    from imu_learn.data import formats
    from imu_learn.errors import InvalidInputError
    from imu_learn.fuse.mounting import forward_mounting, mounting_from_track

    rec, fixes = synthetic_drive(tmp_path, seconds=60.0, cruise=1.5)
    src = formats.read_imu_source(rec)
    t, p, g, fmt = P.read_fixes(fixes)
    with pytest.raises(InvalidInputError, match="faster than 3 m/s"):
        forward_mounting(src.t_ns, src.acc, t, p, g)
    est = mounting_from_track(src.t_ns, src.acc, t, p, g)
    assert "over 1 m/s" in est["from"], est["from"]
    M, E = mounting_rotation(RPY), mounting_rotation(est["rpy_deg"])
    assert np.degrees(np.arccos(np.clip(E[0] @ M[0], -1, 1))) < 5.0, est  # forward
    assert np.degrees(np.arccos(np.clip(E[2] @ M[2], -1, 1))) < 3.0, est  # up
    fast = mounting_from_track(*synthetic_fast_fixes(tmp_path / "fast"), g)
    assert "over 3 m/s" in fast["from"]
    # a still track: no forward axis; the IMU's own axes, or refused for --nhc
    none = mounting_from_track(src.t_ns, src.acc, t, p * 0.0, g)
    assert none["rpy_deg"] == [0.0, 0.0, 0.0] and "own axes" in none["from"] and none["why"]
    with pytest.raises(InvalidInputError, match="nor over 1 m/s"):
        mounting_from_track(src.t_ns, src.acc, t, p * 0.0, g, need_forward=True)


def synthetic_fast_fixes(folder: Path):
    """(IMU stamps, specific force, fix stamps, fixes) of the 8 m/s car."""
    from imu_learn.data import formats

    folder.mkdir()
    rec, fixes = synthetic_drive(folder, seconds=40.0)
    src = formats.read_imu_source(rec)
    t, p, g, fmt = P.read_fixes(fixes)
    return src.t_ns, src.acc, t, p


def _causal_rms(out: Path, fixes: Path, window_s) -> float:
    """RMS [m] of navigate's causal track against the noisy fixes (2 cm) at the fixes' stamps inside
    ``window_s`` (from, to) [s from the recording's start]."""
    est = np.loadtxt(out / "causal.tum")
    ref = np.loadtxt(fixes)
    rel = ref[:, 0] - T0_NS * 1e-9
    keep = (ref[:, 0] >= est[0, 0]) & (ref[:, 0] <= est[-1, 0]) & (rel >= window_s[0]) & (rel <= window_s[1])
    p = np.stack([np.interp(ref[keep, 0], est[:, 0], est[:, k]) for k in (1, 2, 3)], axis=1)
    return float(np.sqrt(np.mean(np.sum((p - ref[keep, 1:4]) ** 2, axis=1))))


def test_navigate_heads_the_axis_the_track_moves_along(tmp_path, monkeypatch, capsys):
    """navigate with position aiding and no --imu-rotation-rpy-deg: the start's heading puts the axis the
    track shows as forward along the track (fuse.mounting.track_forward), not the IMU's x-axis (here the
    IMU's x points sideways and down: mounted 180, 0, 90). The real drive (IMU backwards) and walk (turned
    90 deg) ran 514 / 12.2 m off at their first outage's end heading the x-axis; now 118 / 4.9 m, as with
    their mounting given. With that axis along the track instead, the run starts that far off."""
    from imu_learn.fuse.aiding import kinds

    rec, fixes = synthetic_drive(tmp_path, seconds=40.0)
    args = ["navigate", "--input", str(rec), "--aiding", str(fixes), "--aiding-kind", "position", "--gaps", "6:10",
            "--imu-noise", "1e-3,1e-2,1e-5,1e-4", "--quiet"]
    assert main(args + ["--out", str(tmp_path / "found")]) == 0
    err = capsys.readouterr().err
    assert "deg from the axis the track moves along" in err and "--imu-rotation-rpy-deg" in err
    summary = json.loads((tmp_path / "found" / "summary.json").read_text())
    assert summary["init"]["forward_axis"]["used"] == "the track's forward axis"
    assert abs(summary["init"]["forward_axis"]["angle_from_x_deg"] - 90.0) < 5.0
    start = kinds.position_start
    monkeypatch.setattr(kinds, "position_start", lambda *a, **k: start(*a, **{**k, "body_x_forward": True}))
    assert main(args + ["--out", str(tmp_path / "x_axis")]) == 0
    found, x_axis = (_causal_rms(tmp_path / name, fixes, (6.0, 16.0)) for name in ("found", "x_axis"))  # the gap
    assert found < 0.5 * x_axis, (found, x_axis)


def test_a_drone_shows_no_forward_axis():
    """A body turning apart from its track (a drone yawing while it flies a line) shows no forward axis:
    the start keeps the x-axis (EuRoC's flights: gain 0.03-0.09 against a car's 1.05)."""
    from imu_learn.fuse.mounting import track_forward

    fs = 100
    t = np.arange(0, 60.0, 1 / fs)
    a_world = np.stack([1.5 * np.sin(0.7 * t), 1.0 * np.cos(0.45 * t), 0 * t], axis=1)
    v = np.cumsum(a_world, axis=0) / fs + np.array([3.0, 0.0, 0.0])
    p = np.cumsum(v, axis=0) / fs
    yaw = 0.8 * t + 0.5 * np.sin(0.3 * t)  # the body turns on its own
    R = Rotation.from_euler("z", yaw[:, None]).as_matrix()
    acc = np.einsum("nji,nj->ni", R, a_world + np.array([0.0, 0.0, G]))
    t_ns = T0_NS + np.round(t * 1e9).astype(np.int64)
    k = np.arange(0, len(t), 10)
    shown = track_forward(t_ns, acc, t_ns[k], p[k], G)
    assert not shown["shown"] and shown["gain"] < 0.25, shown


def test_biases_from_positions(tmp_path, monkeypatch):
    from imu_learn.calib.run import CalibOptions
    from imu_learn.data import formats

    rec, fixes = synthetic_drive(tmp_path, seconds=60.0)
    opts = P.PositionsOptions(imu_noise=(1e-3, 1e-2, 1e-5, 1e-4), max_iterations=2, max_windows=300,
                              imu_delay_s=0.0)  # given: this car's roll wanders (synthetic_drive's tilt)
    reads = []
    read = formats.read_imu_source
    monkeypatch.setattr(formats, "read_imu_source", lambda *a, **k: reads.append(a[0]) or read(*a, **k))
    res = P.calibrate_positions(rec, fixes, tmp_path / "cal", opts, CalibOptions(plot=False))
    assert reads == [rec], reads  # one read for every pass
    prof = Profile.load(tmp_path / "cal" / "profile.json")
    np.testing.assert_allclose(prof.gyro.bias, B_G, atol=5e-4)
    np.testing.assert_allclose(prof.acc.bias, B_A, atol=0.03)
    assert np.all(np.isfinite(prof.gyro.bias_std)) and np.all(prof.gyro.bias_std < 1e-3)
    np.testing.assert_array_equal(prof.gyro.matrix, np.eye(3))
    np.testing.assert_array_equal(prof.acc.matrix, np.eye(3))
    assert prof.floor["time_offset"] == 0.0 and prof.floor["cutoff_gyro"] is None
    assert prof.observed["gyroscope.bias"] == {"observed": True, "why": P.WHY}
    assert prof.observed["accelerometer.bias"]["observed"]
    for k in ("gyroscope.matrix", "accelerometer.matrix", "g_sensitivity", "cutoff_gyro", "cutoff_acc", "time_offset"):
        assert not prof.observed[k]["observed"], k
    assert prof.reference["kind"] == "positions" and prof.reference["passes"] == 2  # k > 0: a second pass
    assert prof.reference["navigator"]["imu_delay"] == {"s": 0.0, "std_s": None, "from": "given"}
    assert prof.checks and not prof.checks["failed"]  # calibrate's plausibility checks ran on it
    assert res.profile.floor == prof.floor and (tmp_path / "cal" / "imu.yaml").is_file()


def test_biases_from_positions_with_a_users_csv(tmp_path):
    """The same car's IMU as a CSV of one's own (seconds, deg/s, g; calibrate's --columns and units): the
    same biases from the same fixes (a positions reference read a recording's own layout only)."""
    rec, fixes = synthetic_drive(tmp_path, seconds=60.0)
    rows = np.loadtxt(rec / "mav0" / "imu0" / "data.csv", delimiter=",", comments="#")
    csv = tmp_path / "my_imu.csv"
    with open(csv, "w") as fh:
        fh.write("time_s,ax_g,ay_g,az_g,wx_dps,wy_dps,wz_dps\n")
        for r in rows:
            a, w = r[4:7] / 9.80665, np.degrees(r[1:4])
            fh.write(f"{int(r[0]) / 1e9:.9f},{a[0]:.9f},{a[1]:.9f},{a[2]:.9f},{w[0]:.9f},{w[1]:.9f},{w[2]:.9f}\n")
    argv = ["calibrate", "--input", str(csv), "--columns", "t,ax,ay,az,gx,gy,gz", "--time-unit", "s", "--gyro-unit",
            "deg/s", "--acc-unit", "g", "--groundtruth", str(fixes), "--imu-delay-s", "0", "--out", str(tmp_path / "cal"),
            "--no-plot", "--quiet"]
    from imu_learn.cli.calibrate import source_of

    src = source_of(calibrate_args(*argv[1:]))
    assert isinstance(src, P.PositionsSource) and src.opts.columns is not None and src.opts.columns.acc_unit == "g"
    src = P.PositionsSource(csv, fixes, P.PositionsOptions(columns=src.opts.columns, imu_noise=(1e-3, 1e-2, 1e-5, 1e-4),
                                                          max_iterations=2, max_windows=300, imu_delay_s=0.0))
    from imu_learn.calib.run import CalibOptions, calibrate

    calibrate(src.read(), tmp_path / "cal", CalibOptions(plot=False))
    prof = Profile.load(tmp_path / "cal" / "profile.json")
    np.testing.assert_allclose(prof.gyro.bias, B_G, atol=5e-4)
    np.testing.assert_allclose(prof.acc.bias, B_A, atol=0.03)
    assert prof.sources[0]["format"] == "csv-columns"


def test_biases_from_a_walkers_positions(tmp_path):
    """A walker's pace (1.5 m/s, no fix over 3 m/s), no mounting given: calibrate's navigator passes take
    the forward axis the track shows over 1 m/s and the biases come back (before: exit 2, "0 fixes faster
    than 3 m/s"; the real walk's fixes too)."""
    from imu_learn.calib.run import CalibOptions

    rec, fixes = synthetic_drive(tmp_path, seconds=60.0, cruise=1.5)
    opts = P.PositionsOptions(imu_noise=(1e-3, 1e-2, 1e-5, 1e-4), max_iterations=2, max_windows=300, imu_delay_s=0.0)
    P.calibrate_positions(rec, fixes, tmp_path / "cal", opts, CalibOptions(plot=False))
    prof = Profile.load(tmp_path / "cal" / "profile.json")
    np.testing.assert_allclose(prof.gyro.bias, B_G, atol=5e-4)
    np.testing.assert_allclose(prof.acc.bias, B_A, atol=0.03)
    assert "over 1 m/s" in prof.reference["navigator"]["mounting"]["from"]


def test_imu_delay_from_the_track(tmp_path):
    """A log written 0.12 s late: the estimate is -0.12 s in the navigator's convention (added to every IMU
    stamp), within 3 standard errors or 0.03 s; none: near 0."""
    from imu_learn.data import formats

    for late, name in ((0.12, "late"), (0.0, "on_time")):
        rec, fixes = synthetic_drive(tmp_path / name, seconds=60.0, imu_late_s=late, tilt=0.0)  # a level car: roll biases it (references.md)
        src = formats.read_imu_source(rec)
        t, p, g, _ = P.read_fixes(fixes)
        est = P.estimate_imu_delay(src.t_ns, src.acc, t, p, g)
        assert not est["at_edge"] and est["fixes_used"] > 400
        assert abs(est["imu_delay_s"] + late) < max(0.03, 3 * est["std_s"]), est
        assert 0 < est["std_s"] < 0.02 and len(est["blocks_s"]) == 4
        if late:
            assert est["residual_mps2"] < est["residual_at_zero_mps2"]


def calibrate_args(*argv: str):
    from imu_learn.cli.common import parser

    return parser("calibrate").parse_args(list(argv))


def test_navigator_options_reach_the_source(tmp_path):
    from imu_learn.cli.calibrate import source_of

    rec, fixes = synthetic_drive(tmp_path, seconds=12.0)
    args = calibrate_args("--input", str(rec), "--groundtruth", str(fixes), "--out", str(tmp_path / "cal"),
                          "--imu-rotation-rpy-deg", "180,-6.79,185.35", "--imu-delay-s", "-0.125",
                          "--lever-arm", "0,-0.05,0")
    src = source_of(args)
    assert isinstance(src, P.PositionsSource)
    assert src.opts.imu_rotation_rpy_deg == (180.0, -6.79, 185.35)
    assert src.opts.imu_delay_s == -0.125 and src.opts.lever_arm == (0.0, -0.05, 0.0)
    src = source_of(calibrate_args("--input", str(rec), "--groundtruth", str(fixes), "--out", str(tmp_path / "c2")))
    assert src.opts.imu_rotation_rpy_deg is None and src.opts.imu_delay_s is None and src.opts.lever_arm is None
    # the delay given reaches the profile's reference as given
    delay, info = P.imu_delay(src.opts.__class__(imu_delay_s=-0.125), None, None, None, 9.81)
    assert delay == -0.125 and info == {"s": -0.125, "std_s": None, "from": "given"}


@pytest.mark.parametrize("extra, kind", [(["--imu-delay-s", "0.1"], "poses"),
                                         (["--lever-arm", "0,0,0.1", "--imu-rotation-rpy-deg", "0,0,90"], "poses"),
                                         (["--imu-only", "--imu-delay-s", "0.1"], "none")])
def test_navigator_options_refused_with_another_reference(tmp_path, capsys, extra, kind):
    rec, fixes = synthetic_drive(tmp_path, seconds=12.0)
    six = tmp_path / "pose.tum"  # a 6-DoF reference: the poses kind
    six.write_text("".join(f"{1000 + i * 0.1:.1f} 0 0 0 {np.sin(i * 0.05):.6f} 0 0 {np.cos(i * 0.05):.6f}\n"
                           for i in range(50)))
    gt = [] if "--imu-only" in extra else ["--groundtruth", str(six)]
    rc = main(["calibrate", "--input", str(rec), *gt, "--out", str(tmp_path / "cal"), *extra])
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert rc == 2 and len(err) == 1, err
    assert f"not used with the {kind} reference kind" in err[0] and extra[-2] in err[0]
    assert not (tmp_path / "cal" / "profile.json").exists()


def test_another_recordings_fixes_are_refused_before_any_estimate(tmp_path, capsys):
    """Fixes a day off the IMU (another recording's): one line naming both spans, before the delay and
    mounting estimates (which would blame the track's speed), nothing written."""
    rec, fixes = synthetic_drive(tmp_path, seconds=12.0)
    late = tmp_path / "late.tum"
    late.write_text("".join(f"{float(r.split()[0]) + 86400:.6f} {' '.join(r.split()[1:])}\n"
                            for r in fixes.read_text().splitlines()))
    rc = main(["calibrate", "--input", str(rec), "--groundtruth", str(late), "--out", str(tmp_path / "cal")])
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert rc == 2 and len(err) == 1, err
    assert "AidingOverlapError" in err[0] and "do not overlap in time" in err[0] and "late.tum" in err[0]
    assert not (tmp_path / "cal" / "profile.json").exists()


def test_lever_arm_and_extrinsics_not_both(tmp_path):
    from imu_learn.errors import ConfigError

    rec, fixes = synthetic_drive(tmp_path, seconds=12.0)
    yaml = tmp_path / "sensor.yaml"
    yaml.write_text("T_BS:\n  cols: 4\n  rows: 4\n  data: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0.2, 0, 0, 0, 1]\n")
    args = calibrate_args("--input", str(rec), "--groundtruth", str(fixes), "--out", str(tmp_path / "cal"),
                          "--lever-arm", "0,0,0.1", "--extrinsics", str(yaml))
    with pytest.raises(ConfigError, match="--lever-arm and --extrinsics"):
        P.source_from_cli(args)


# --- the real drive ------------------------------------------------------------------------------

DATA = Path(os.environ["IMU_LEARN_DATA"]) if os.environ.get("IMU_LEARN_DATA") else \
    Path(__file__).resolve().parents[1].parent / "shared" / "data"
DRIVE = DATA / "gnss-imu" / "drive_0708"


@pytest.mark.slow
def test_calibrate_the_drive_from_its_rtk_fixes(tmp_path, capsys):
    if not (DRIVE / "imu_1934.csv").is_file():
        pytest.skip("the gnss-imu drive is not on this machine (set IMU_LEARN_DATA to the data root)")
    rc = main(["calibrate", "--input", str(DRIVE / "imu_1934.csv"), "--groundtruth", str(DRIVE / "gnss_1934_sf.pos"),
               "--out", str(tmp_path / "cal"), "--no-plot"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    # the reader's lines once, not again for each of the navigator's passes
    assert out.err.count("mapped onto the tag") == 1 and out.err.count("possibly cut line") == 1, out.err
    prof = Profile.load(tmp_path / "cal" / "profile.json")
    assert prof.reference["kind"] == "positions"
    assert prof.observed["gyroscope.bias"]["observed"] and prof.observed["accelerometer.bias"]["observed"]
    for k in ("gyroscope.matrix", "accelerometer.matrix", "g_sensitivity", "cutoff_gyro", "cutoff_acc", "time_offset"):
        assert not prof.observed[k]["observed"], k
    np.testing.assert_array_equal(prof.gyro.matrix, np.eye(3))
    assert prof.checks and not prof.checks["failed"]  # calibrate's plausibility checks ran and passed
    assert np.all(np.abs(prof.gyro.bias) < 0.02) and np.all(np.abs(prof.acc.bias) < 0.5)
    d = json.loads((tmp_path / "cal" / "profile.json").read_text())
    assert d["reference"]["passes"] >= 1
    delay = d["reference"]["navigator"]["imu_delay"]  # estimated: the log is about 0.125-0.19 s late
    assert delay["from"].startswith("estimated") and -0.25 < delay["s"] < -0.1 and 0 < delay["std_s"] < 0.05


def test_a_track_too_short_after_its_heading_is_one_line_not_a_traceback(tmp_path, capsys):
    """The navigator's smoothed trajectory starts where the track first gives the heading; a recording that
    moves late leaves too little to fit on: one line (exit 2) saying so, not a ValueError's traceback (exit 1)."""
    rec, fixes = synthetic_drive(tmp_path, seconds=5.0)
    rc = main(["calibrate", "--input", str(rec), "--groundtruth", str(fixes), "--imu-rotation-rpy-deg",
               ",".join(map(str, RPY)), "--imu-delay-s", "0", "--out", str(tmp_path / "cal"), "--no-plot"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err[-1].startswith("imu-learn calibrate: error: InvalidInputError: "), err[-3:]
    assert "shorter than the floor's window" in err[-1] and "starts" in err[-1]
