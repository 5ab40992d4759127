"""``imu-learn navigate`` on GNSS/IMU logs (the ``gnss-imu`` IMU format: CSV + RTKLIB ``.tag``;
RTKLIB ``.pos`` position aiding), with the mounting rotation, logging delay, lever arm and the
non-holonomic constraint: a synthetic car written in those formats (tiny writers below), and the
first minute of the real drive when the data is on this machine. No ground truth at run time: the
synthetic truth is only compared afterwards."""
from __future__ import annotations

import json
import math
import os
import struct
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_learn.cli import main
from imu_learn.data import formats
from imu_learn.data.formats import gnss_imu
from imu_learn.fuse.aiding import rtklib
from imu_learn.fuse.score import score_against_fixes
from imu_learn.fuse.start.delay import imu_delay

G_UNIT = 9.80665
START_S = 1752003261  # the tag's start [s, GPST since 1970]
LAT0, LON0, H0 = 40.0, -105.0, 1600.0
RPY = (180.0, 0.0, 90.0)  # mounting: roll, pitch, yaw of the body frame relative to the IMU frame
DELAY_S = 0.1  # the IMU's stamps are this late: --imu-delay-s -0.1
LEVER = np.array([0.3, -0.2, 0.5])  # the antenna from the IMU, body frame [m]
POS_HEADER = ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  "
              "sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)")


# --- tiny writers ----------------------------------------------------------------------------------

def write_tag(path: Path, start_s: int, frac: float, end_ms: int) -> None:
    head = b"TIMETAG RTKLIB demo5".ljust(60, b"\0") + struct.pack("<IId", 0, start_s, frac)
    path.write_bytes(head + struct.pack("<II", end_ms // 2, 0) + struct.pack("<II", end_ms, 100))


def write_imu_csv(path: Path, acc_g: np.ndarray, gyro_dps: np.ndarray, counter_ms: np.ndarray) -> None:
    rows = "".join(f"{a[0]:.7f},{a[1]:.7f},{a[2]:.7f},{w[0]:.6f},{w[1]:.6f},{w[2]:.6f},{int(c)}\n"
                   for a, w, c in zip(acc_g, gyro_dps, counter_ms))
    path.write_text("0.11,-0.2\n" + rows + "0.0,0.01")  # a cut first line and a cut last line, as logged


def write_pos(path: Path, t_s: np.ndarray, enu: np.ndarray, vel: np.ndarray, q: np.ndarray) -> None:
    x0 = rtklib.llh_to_ecef(LAT0, LON0, H0)
    Rn = rtklib.ecef_to_enu_rotation(LAT0, LON0)
    lines = []
    for tk, p, v, qk in zip(t_s, enu, vel, q):
        lat, lon, h = rtklib.ecef_to_llh(x0 + Rn.T @ p)
        whole = int(math.floor(tk))
        ms = int(round((tk - whole) * 1000))
        stamp = np.datetime_as_string(np.datetime64(whole, "s")).replace("-", "/").replace("T", " ") + f".{ms:03d}"
        sd = 0.01 if qk == 1 else 0.1
        lines.append(f"{stamp} {lat:.9f} {lon:.9f} {h:.4f} {qk} 20 {sd:.4f} {sd:.4f} {sd:.4f} 0.0 0.0 0.0 0.0 0.0 "
                     f"{v[1]:.4f} {v[0]:.4f} {v[2]:.4f}")
    path.write_text("% program   : RTKPOST\n" + POS_HEADER + "\n" + "\n".join(lines) + "\n")


def synthetic_car(folder: Path, seconds: float = 24.0):
    """A level car (body x forward, z up, ENU): still 4 s, 1 m/s^2 for 4 s, a 1 rad left turn at
    4 m/s from 10 s to 15 s, straight on; never sideways (the NHC holds). IMU at 100 Hz mounted with
    ``RPY``, stamps ``DELAY_S`` late; fixes at 4 Hz of the antenna (``LEVER``), Q = 1 except a float
    stretch. Returns (imu csv, pos file, truth: t [s since START_S], IMU positions (N, 3))."""
    fs, sub = 100, 10
    tt = np.arange(int(seconds * fs * sub)) / (fs * sub)  # a fine grid for the truth
    acc_t = np.where((tt >= 4) & (tt < 8), 1.0, 0.0)
    speed = np.clip(tt - 4.0, 0.0, 4.0)
    rate = np.where((tt >= 10) & (tt < 15), 0.2, 0.0)
    psi = np.radians(30.0) + np.concatenate([[0.0], np.cumsum((rate[1:] + rate[:-1]) / 2) / (fs * sub)])
    vel = np.stack([speed * np.cos(psi), speed * np.sin(psi), np.zeros_like(tt)], axis=1)
    pos = np.concatenate([np.zeros((1, 3)), np.cumsum((vel[1:] + vel[:-1]) / 2, axis=0) / (fs * sub)])
    g = rtklib.normal_gravity(LAT0, H0)
    f_body = np.stack([acc_t, speed * rate, np.full_like(tt, g)], axis=1)  # tangential, centripetal, up
    w_body = np.stack([np.zeros_like(tt), np.zeros_like(tt), rate], axis=1)
    i = np.arange(0, len(tt), sub)
    M = gnss_imu.mounting_rotation(RPY)  # body = M imu
    imu = folder / "imu_0001.csv"
    n = len(i)
    write_imu_csv(imu, f_body[i] @ M / G_UNIT, np.degrees(w_body[i] @ M), 5000 + 10 * np.arange(n))
    write_tag(imu.with_name(imu.name + ".tag"), START_S, DELAY_S, 10 * (n - 1))
    k = np.arange(0, len(tt) - sub, 250)  # 4 Hz
    R = Rotation.from_euler("z", psi[k][:, None]).as_matrix()
    ant = pos[k] + R @ LEVER
    q = np.where((tt[k] > 18) & (tt[k] < 20), 2, 1)
    pos_file = folder / "gnss_0001.pos"
    write_pos(pos_file, START_S + tt[k] + 0.002, ant, vel[k], q)
    return imu, pos_file, (tt[i], pos[i])


def run(argv, capsys):
    rc = main(["navigate", *map(str, argv)])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def read_tum(path: Path) -> np.ndarray:
    return np.loadtxt(path, ndmin=2)


# --- the format ------------------------------------------------------------------------------------

def test_gnss_imu_is_an_imu_format_detected_by_its_tag(tmp_path):
    imu, _pos, (t, _p) = synthetic_car(tmp_path)
    assert formats.detect_format(imu) == "gnss-imu"
    assert formats.FORMATS["gnss-imu"] is gnss_imu
    assert gnss_imu.find_recordings(tmp_path) == [imu]
    src = formats.read_imu_source(imu, "gnss-imu")
    assert src.fmt == "gnss-imu" and len(src.t_ns) == len(t)  # the cut first and last lines left out
    assert src.t_ns[0] == (START_S + DELAY_S) * 10**9
    # SI units, in the IMU frame: gravity along the IMU's -z for roll 180 (body z up = IMU -z)
    assert np.linalg.norm(src.acc[0]) == pytest.approx(rtklib.normal_gravity(LAT0, H0), abs=1e-4)
    assert src.acc[0, 2] < -9.7
    # written back in its own layout: units, counter, cut lines and the tag kept
    out = tmp_path / "out" / "refined.csv"
    out.parent.mkdir()
    formats.write_imu(src, out, src.gyro * 2, src.acc)
    back = formats.read_imu_source(out)
    np.testing.assert_array_equal(back.t_ns, src.t_ns)
    np.testing.assert_allclose(back.gyro, src.gyro * 2, atol=1e-7)
    np.testing.assert_allclose(back.acc, src.acc, atol=1e-6)
    assert out.read_text().splitlines()[0] == "0.11,-0.2"
    # a lone CSV (no tag beside it) is not claimed
    lone = tmp_path / "lone.csv"
    lone.write_text(imu.read_text())
    assert not gnss_imu.detect(lone)


# --- the synthetic car through imu-learn navigate --------------------------------------------------

def test_with_nhc_a_mounting_the_track_contradicts_is_refused_unless_forced(tmp_path, capsys):
    """The drive with its yaw 90 deg off fused with a warning only (causal RMS 11.6 m against 0.54 m, exit 0):
    now one line naming the estimated mounting, exit 2, nothing written; --force fuses it with the warning."""
    imu, pos, _ = synthetic_car(tmp_path)
    turned = (RPY[0], RPY[1], RPY[2] + 90.0)
    base = ["--input", imu, "--format", "gnss-imu", "--aiding", pos, "--aiding-kind", "position",
            "--aiding-format", "rtklib", "--imu-rotation-rpy-deg", ",".join(map(str, turned)),
            "--imu-delay-s", -DELAY_S, "--lever-arm", ",".join(map(str, LEVER)),
            "--imu-noise", "1e-4,1e-3,1e-5,1e-4", "--keyframe-hz", 4, "--nhc", "--quiet"]
    rc, _out, err = run(base + ["--out", tmp_path / "nav"], capsys)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1, err
    assert "is 90 deg from the one the track shows" in lines[0] and "--force" in lines[0]
    assert not (tmp_path / "nav").exists()
    rc, _out, err = run(base + ["--out", tmp_path / "forced", "--force"], capsys)
    assert rc == 0 and "fused as given (--force)" in err, err


def test_simulated_outages_are_scored_against_the_fixes_the_run_withheld(tmp_path, capsys):
    """--groundtruth rover.pos: the RTK-fixed rows score a GNSS-aided run's antenna in its ENU world, with
    each --gaps window's error at the fixes withheld there (a GNSS user has no other truth; it was refused)."""
    imu, pos, _ = synthetic_car(tmp_path)
    base = ["--input", imu, "--format", "gnss-imu", "--aiding", pos, "--aiding-kind", "position",
            "--aiding-format", "rtklib", "--imu-rotation-rpy-deg", ",".join(map(str, RPY)),
            "--imu-delay-s", -DELAY_S, "--lever-arm", ",".join(map(str, LEVER)),
            "--imu-noise", "1e-4,1e-3,1e-5,1e-4", "--keyframe-hz", 4, "--quiet"]
    rc, out, err = run(base + ["--gaps", "20:5", "--groundtruth", pos, "--out", tmp_path / "nav"], capsys)
    assert rc == 0, err
    sc = json.loads((tmp_path / "nav" / "summary.json").read_text())["scores"]
    assert sc["aligned"] is False and "RTK-fixed rows (Q = 1)" in sc["truth"]
    for kind in ("causal", "smoothed"):
        assert sc[kind]["outside_gaps_rmse_m"] < 0.05, sc[kind]  # the fixes the run fused: the antenna on them
        gap = sc[kind]["gaps"][0]
        assert gap["start_s"] == 20.0 and gap["rmse_m"] is not None and gap["max_m"] >= gap["rmse_m"]
    assert sc["causal"]["gaps"][0]["max_m"] > sc["causal"]["outside_gaps_rmse_m"]  # it coasts there
    assert "causal at the gaps' ends" in out
    # the rows before the graph's start (the levelling and heading) are counted apart from the fused ones
    before = json.loads((tmp_path / "nav" / "summary.json").read_text())["fixes_before_start"]
    assert before > 0 and f"position rows ({before} before the start, for its attitude;" in out


def test_synthetic_car_navigated_with_mounting_delay_lever_and_nhc(tmp_path, capsys):
    imu, pos, (t_true, p_true) = synthetic_car(tmp_path)
    base = ["--input", imu, "--format", "gnss-imu", "--aiding", pos, "--aiding-kind", "position",
            "--aiding-format", "rtklib", "--imu-rotation-rpy-deg", ",".join(map(str, RPY)),
            "--imu-delay-s", -DELAY_S, "--lever-arm", ",".join(map(str, LEVER)),
            "--imu-noise", "1e-4,1e-3,1e-5,1e-4", "--keyframe-hz", 4]
    rc, out, err = run(base + ["--nhc", "--out", tmp_path / "nav"], capsys)
    assert rc == 0, err
    assert "imu_0001.csv" in out and "position rows" in out
    s = json.loads((tmp_path / "nav" / "summary.json").read_text())
    assert s["counts"]["extra_factors"] > 0  # the NHC factors
    assert s["lever_arm_m"] == pytest.approx(LEVER.tolist())
    assert s["options"]["gravity"] == pytest.approx(rtklib.normal_gravity(LAT0, H0), abs=1e-5)
    for name in ("causal.tum", "smoothed.tum", "plot.png", "summary.json"):
        assert (tmp_path / "nav" / name).is_file(), name
    for kind, tol in (("smoothed", 0.03), ("causal", 0.1)):
        d = read_tum(tmp_path / "nav" / f"{kind}.tum")
        ts = d[:, 0] - START_S
        p = np.stack([np.interp(ts, t_true, p_true[:, k]) for k in range(3)], axis=1)
        origin = p_true[np.searchsorted(t_true, 0.0)] + Rotation.from_euler("z", 30, degrees=True).apply(LEVER)
        # the ENU origin is the first fix (the antenna at rest): truth shifted onto it
        err3 = np.linalg.norm(d[:, 1:4] - (p - origin), axis=1)
        assert np.sqrt(np.mean(err3 ** 2)) < tol, (kind, np.sqrt(np.mean(err3 ** 2)))
    # the heading after the turn: 30 + 57.3 deg, body x forward
    d = read_tum(tmp_path / "nav" / "smoothed.tum")
    yaw = Rotation.from_quat(d[-1, 4:8]).as_euler("ZYX", degrees=True)[0]
    assert yaw == pytest.approx(30.0 + math.degrees(1.0), abs=1.0)


def test_navigator_option_errors(tmp_path, capsys):
    imu, pos, _ = synthetic_car(tmp_path, seconds=10.0)
    base = ["--input", imu, "--aiding", pos, "--aiding-kind", "position", "--aiding-format", "rtklib"]
    rc, _out, err = run(base + ["--imu-rotation-rpy-deg", "180,0"], capsys)
    assert rc == 2 and "ConfigError: --imu-rotation-rpy-deg: expected 3 comma-separated" in err
    rc, _out, err = run(["--input", imu, "--aiding", pos, "--aiding-kind", "pose", "--lever-arm", "0,0,1"], capsys)
    assert rc == 2 and "--lever-arm is the antenna's: only with --aiding-kind position" in err
    rc, _out, err = run(["--input", imu, "--aiding", pos, "--aiding-kind", "position", "--aiding-format", "tum",
                         "--imu-delay-s", "auto"], capsys)
    assert rc == 2 and "--imu-delay-s auto measures the delay against GNSS fixes" in err
    for wrong in (["--config", "configs/fuse_euroc.toml"], ["--set", "a=1"]):  # the experiments' options
        with pytest.raises(SystemExit):
            run(base + wrong, capsys)


# --- the real drive, first minute ------------------------------------------------------------------

DATA = Path(os.environ["IMU_LEARN_DATA"]) if os.environ.get("IMU_LEARN_DATA") else \
    Path(__file__).resolve().parents[1].parent / "shared" / "data"
DRIVE = DATA / "gnss-imu" / "drive_0708"


def crop_drive(folder: Path, seconds: float) -> Path:
    """The drive's IMU log cut after ``seconds`` (its tag's end moved with it)."""
    src = DRIVE / "imu_1934.csv"
    lines = src.read_text().splitlines(keepends=True)
    c0 = float(lines[1].split(",")[6])
    keep = [ln for ln in lines[1:] if float(ln.split(",")[6]) - c0 <= seconds * 1000]
    out = folder / "imu_1934.csv"
    out.write_text(lines[0] + "".join(keep))
    tag = (DRIVE / "imu_1934.csv.tag").read_bytes()
    end_ms = int(round(float(keep[-1].split(",")[6]) - c0))
    out.with_name(out.name + ".tag").write_bytes(tag[:76] + struct.pack("<II", end_ms, 0))
    return out


@pytest.mark.skipif(not (DRIVE / "imu_1934.csv").is_file(), reason="the gnss-imu drive is not on this machine "
                    "(set IMU_LEARN_DATA to the data root)")
def test_real_drive_first_minute(tmp_path, capsys):
    imu = crop_drive(tmp_path, 75.0)
    pos = DRIVE / "gnss_1934_sf.pos"
    rc, out, err = run(["--input", imu, "--format", "gnss-imu", "--aiding", pos, "--aiding-kind", "position",
                        "--aiding-format", "rtklib", "--imu-rotation-rpy-deg", "180,-6.79,185.35", "--imu-delay-s",
                        "-0.125", "--nhc", "--gnss-velocity-sigma", "0", "--out", tmp_path / "nav"], capsys)
    assert rc == 0, err
    s = json.loads((tmp_path / "nav" / "summary.json").read_text())
    assert s["counts"]["extra_factors"] > 0
    assert s["gnss_velocities"] == {"used": False, "why": "--gnss-velocity-sigma 0: positions only"}
    sol = rtklib.read_pos(pos)
    d = read_tum(tmp_path / "nav" / "smoothed.tum")
    t = np.round(d[:, 0] * 1e9).astype(np.int64)
    m = (sol.q == 1) & (sol.t_ns >= t[0]) & (sol.t_ns <= t[-1])
    assert m.sum() > 100
    x = (sol.t_ns[m] - t[0]) * 1e-9
    p = np.stack([np.interp(x, (t - t[0]) * 1e-9, d[:, 1 + k]) for k in range(3)], axis=1)
    h = np.linalg.norm(p[:, :2] - sol.enu[m, :2], axis=1)
    assert np.sqrt(np.mean(h ** 2)) < 0.1, np.sqrt(np.mean(h ** 2))  # cm level where fixed (2.6 cm on the whole drive)


def test_imu_delay_auto_is_measured_against_the_fixes(tmp_path, capsys):
    """``--imu-delay-s auto``: the delay the fixes give (:func:`imu_learn.fuse.start.delay.imu_delay`, tested on
    its own in test_imu_gnss_delay.py) is the one added to the IMU's stamps and named in the summary. The
    level synthetic car barely shows its delay in the specific force's norm (its accelerations are
    horizontal: |f| - g = a^2 / 2g, 0.05 m/s^2), so the estimate is only bounded here."""
    imu, pos, _ = synthetic_car(tmp_path)
    base = ["--input", imu, "--aiding", pos, "--imu-rotation-rpy-deg", ",".join(map(str, RPY)),
            "--lever-arm", ",".join(map(str, LEVER)), "--imu-noise", "1e-4,1e-3,1e-5,1e-4", "--keyframe-hz", 4,
            "--quiet"]
    rc, _, err = run(base + ["--imu-delay-s", "auto", "--out", tmp_path / "auto"], capsys)
    assert rc == 0, err
    d = json.loads((tmp_path / "auto" / "summary.json").read_text())["imu_delay"]
    src = formats.read_imu_source(imu, "gnss-imu")
    want = imu_delay(np.asarray(src.t_ns), np.asarray(src.acc), rtklib.read_pos(pos), rtklib.normal_gravity(LAT0, H0))
    assert d["from"] == "fixes" and d["delay_s"] == pytest.approx(want.delay_s, abs=1e-4) and d["epochs"] == want.epochs
    assert -0.2 < d["delay_s"] < 0.0 and d["rms_mps2"] < d["rms_at_zero_mps2"]
    rc, _, err = run(base + ["--imu-delay-s", str(-DELAY_S), "--out", tmp_path / "given"], capsys)
    given = json.loads((tmp_path / "given" / "summary.json").read_text())["imu_delay"]
    assert rc == 0 and given == {"delay_s": -DELAY_S, "from": "--imu-delay-s"}
    rc, _, err = run(base + ["--imu-delay-s", "soon", "--out", tmp_path / "x"], capsys)
    assert rc == 2 and "--imu-delay-s: seconds (e.g. -0.2) or 'auto'" in err


def test_no_imu_delay_given_is_measured_and_applied_where_clearly_better(tmp_path, capsys, monkeypatch):
    """No --imu-delay-s with GNSS fixes: the delay ``auto`` finds, applied where its fit is clearly better
    than at zero (one warning line), else none with the measured value in the summary (the drive: -0.20 s
    applied, 116 m less at its first outage's end; the walk: -0.03 s, 0.407 against 0.413, not applied).
    --imu-delay-s 0 keeps the stamps as they are."""
    from imu_learn.fuse import navigate as nav

    imu, pos, _ = synthetic_car(tmp_path)
    base = ["--input", imu, "--aiding", pos, "--imu-rotation-rpy-deg", ",".join(map(str, RPY)),
            "--lever-arm", ",".join(map(str, LEVER)), "--imu-noise", "1e-4,1e-3,1e-5,1e-4", "--keyframe-hz", 4]
    rc, _, err = run(base + ["--out", tmp_path / "unset"], capsys)
    assert rc == 0, err
    d = json.loads((tmp_path / "unset" / "summary.json").read_text())["imu_delay"]
    # the level car bounds its delay only (test_imu_delay_auto_is_measured_against_the_fixes): closer to it than 0
    assert d["from"].startswith("fixes (no --imu-delay-s") and abs(d["delay_s"] + DELAY_S) < DELAY_S
    assert d["rms_mps2"] <= nav.CLEAR_DELAY_FIT * d["rms_at_zero_mps2"] and "s off the GNSS fixes'" in err
    rc, _, err = run(base + ["--imu-delay-s", "0", "--out", tmp_path / "zero", "--quiet"], capsys)
    assert json.loads((tmp_path / "zero" / "summary.json").read_text())["imu_delay"] == \
        {"delay_s": 0.0, "from": "--imu-delay-s"}
    monkeypatch.setattr(nav, "CLEAR_DELAY_FIT", 0.1)  # a fit not clearly better: measured, not applied
    rc, _, err = run(base + ["--out", tmp_path / "unclear", "--quiet"], capsys)
    d = json.loads((tmp_path / "unclear" / "summary.json").read_text())["imu_delay"]
    assert rc == 0 and d["delay_s"] == 0.0 and abs(d["measured_s"] + DELAY_S) < DELAY_S
    assert "not clearly better" in d["from"] and "s off the GNSS fixes'" not in err


@pytest.mark.skipif(not (DRIVE / "imu_1934.csv").is_file(), reason="the gnss-imu drive is not on this machine "
                    "(set IMU_LEARN_DATA to the data root)")
def test_real_drive_parked_start_and_velocities_without_options(tmp_path, capsys):
    """The drive as a user runs it (no mounting, delay or noise given) through the peer's first 15 s outage, which
    begins 0.4 s after the track gives the heading. The car is parked 34 s with its engine running (0.7-2.7
    deg/s of vibration: no IMU still rule passes): levelled over the rest its RTK track shows, the gyro's mean
    there carrying the attitude to the start (the first 2 s and a zero bias carried it 34 s before: 47.8 m at the
    outage's end); the fixes' velocities used at their measured 0.12 s lag; the white noise raised to the
    IMU's at that rest."""
    imu = crop_drive(tmp_path, 90.0)
    pos = DRIVE / "gnss_1934_sf.pos"
    rc, out, err = run(["--input", imu, "--aiding", pos, "--gaps", "36.77:15", "--groundtruth", pos,
                        "--out", tmp_path / "nav"], capsys)
    assert rc == 0, err
    s = json.loads((tmp_path / "nav" / "summary.json").read_text())
    assert s["init"]["attitude_source"].startswith("at rest as the position track shows it"), s["init"]
    v = s["gnss_velocities"]
    assert v["used"] and abs(v["lag"]["lag_s"] - 0.123) < 0.01 and v["lag"]["rms_after_mps"] < 0.5 * v["lag"]["rms_before_mps"]
    assert "raised to what the IMU shows at rest over the rest the GNSS track shows" in s["imu_noise"]["source"]
    assert s["imu_noise"]["gyroscope_noise_density"] > 2e-3
    end = s["scores"]["causal"]["gaps"][0]["end_m"]
    assert end < 25.0, end


def test_gap_scores_against_fixes_give_the_horizontal_error_beside_the_3d_one():
    """GNSS/INS filters are judged by the horizontal error when the fixes return: a track 0.3 m east, 0.4 m
    north and 1.2 m up of every fix scores 1.3 m 3-D and 0.5 m horizontally in each gap (the 3-D figure
    alone was compared with the peers' horizontal one)."""
    t_ns = np.arange(0, 60_000_000_000, 200_000_000, dtype=np.int64)
    enu = np.stack([np.linspace(0.0, 300.0, len(t_ns)), np.zeros(len(t_ns)), np.zeros(len(t_ns))], axis=1)
    fixes = rtklib.RtkSolution("rover.pos", t_ns, enu, np.full_like(enu, 0.01), None, np.ones(len(t_ns), int),
                               np.arange(1, len(t_ns) + 1), (40.0, -105.0, 1600.0), "llh")
    kf_t = np.arange(0, 60_000_000_000, 100_000_000, dtype=np.int64)
    p = np.stack([np.interp(kf_t, t_ns, enu[:, k]) for k in range(3)], axis=1) + [0.3, 0.4, 1.2]
    R = np.repeat(np.eye(3)[None], len(kf_t), axis=0)
    res = SimpleNamespace(causal_p=p, causal_R=R, smoothed_p=p, smoothed_R=R)
    sc = score_against_fixes(fixes, kf_t, res, np.zeros(3), fixes.origin_llh, 0, gaps=[(20.0, 10.0), (40.0, 5.0)])
    for gap in sc["causal"]["gaps"]:
        assert gap["end_m"] == pytest.approx(1.3, abs=1e-6) and gap["rmse_m"] == pytest.approx(1.3, abs=1e-6)
        assert gap["horizontal"]["end_m"] == pytest.approx(0.5, abs=1e-6)
        assert gap["horizontal"]["max_m"] == pytest.approx(0.5, abs=1e-6)
