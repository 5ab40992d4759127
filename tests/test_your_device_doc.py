"""docs/your-device.md cannot rot: its ```bash blocks are run, in order, in a folder holding what the
page says the user has: ``my_imu.csv`` (the shipped MH_04 crop at the Fetch robot's 100 Hz, exported
with semicolons, other names, a temperature column, deg/s, g and float seconds) and ``vio.tum`` (its
reference at 20 Hz); then what the page says each step writes is checked, and checked against the
crop's ground truth (its gyro bias, its rotation over 1 s, its positions), which the commands never
see beyond the 20 Hz poses."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_learn import _imu_core as core
from imu_learn.data.formats.groundtruth import read_groundtruth

REPO = Path(__file__).resolve().parent.parent
PAGE = REPO / "docs" / "your-device.md"
CROP = REPO / "datasets" / "euroc" / "MH_04_difficult" / "mav0"
SECONDS = 30.0  # of the crop: calibrate's fit dominates the test's time
STATE = CROP / "state_groundtruth_estimate0" / "data.csv"


def bash_blocks(text: str):
    return re.findall(r"^```bash\n(.*?)^```", text, flags=re.S | re.M)


def write_user_files(folder: Path) -> None:
    t, g, a = core.read_asl_imu(str(CROP / "imu0" / "data.csv"))
    keep = t < t[0] + int(SECONDS * 1e9)
    t, g, a = t[keep][::2], g[keep][::2], a[keep][::2]
    lines = ["time_s;temp_C;wx_dps;wy_dps;wz_dps;ax_g;ay_g;az_g"]
    for k in range(len(t)):
        lines.append(";".join([f"{t[k] // 10**9}.{t[k] % 10**9:09d}", "31.5", *(f"{x:.6f}" for x in np.degrees(g[k])),
                               *(f"{x:.7f}" for x in a[k] / 9.80665)]))
    (folder / "my_imu.csv").write_text("\n".join(lines) + "\n")
    gt = read_groundtruth(CROP / "state_groundtruth_estimate0" / "data.csv")
    rows = [k for k in range(0, len(gt.t_ns), 10) if gt.t_ns[k] <= t[-1]]  # 200 Hz -> 20 Hz
    q = gt.q_wxyz
    (folder / "vio.tum").write_text("".join(
        f"{gt.t_ns[k] // 10**9}.{gt.t_ns[k] % 10**9:09d} {gt.p[k, 0]:.5f} {gt.p[k, 1]:.5f} {gt.p[k, 2]:.5f} "
        f"{q[k, 1]:.7f} {q[k, 2]:.7f} {q[k, 3]:.7f} {q[k, 0]:.7f}\n" for k in rows))


def read_user_csv(path: Path):
    """(t [ns], gyro [rad/s]) of a file in my_imu.csv's form, read back in plain numpy."""
    x = np.loadtxt(path, delimiter=";", skiprows=1)
    return np.round(x[:, 0] * 1e9).astype(np.int64), np.radians(x[:, 2:5])  # float64: stamps to 0.25 us


def nearest(t_ref: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index of the stamp in t_ref nearest each of t."""
    k = np.clip(np.searchsorted(t_ref, t), 1, len(t_ref) - 1)
    return np.where(np.abs(t_ref[k - 1] - t) <= np.abs(t_ref[k] - t), k - 1, k)


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, av, bw, bv = a[..., :1], a[..., 1:], b[..., :1], b[..., 1:]
    return np.concatenate([aw * bw - (av * bv).sum(-1, keepdims=True), aw * bv + bw * av + np.cross(av, bv)], -1)


def rotation_error_1s(t_ns: np.ndarray, gyro: np.ndarray, gt) -> float:
    """Mean angle [rad] between the gyro's rotation over 1 s windows (zero-order hold, a window
    starting every 0.5 s) and the ground truth's over the same stamps: an oracle of its own (numpy
    quaternions), not the package's integration."""
    k_gt = nearest(gt.t_ns, t_ns)
    assert np.abs(gt.t_ns[k_gt] - t_ns).max() < 1_000_000  # the IMU and its ground truth share stamps
    q_gt = gt.q_wxyz[k_gt]
    rate = 1e9 / np.median(np.diff(t_ns))
    n, step = int(round(rate)), int(round(rate / 2))
    starts = np.arange(0, len(t_ns) - n, step)
    q = np.tile([1.0, 0, 0, 0], (len(starts), 1))
    for j in range(n):
        k = starts + j
        dth = gyro[k] * ((t_ns[k + 1] - t_ns[k]) * 1e-9)[:, None]
        ang = np.linalg.norm(dth, axis=1, keepdims=True)
        axis = dth / np.maximum(ang, 1e-300)
        q = qmul(q, np.concatenate([np.cos(ang / 2), np.sin(ang / 2) * axis], 1))
    want = qmul(q_gt[starts] * [1, -1, -1, -1], q_gt[starts + n])
    d = qmul(want * [1, -1, -1, -1], q)
    return float(np.mean(2 * np.arccos(np.clip(np.abs(d[:, 0]), 0, 1))))


def test_the_page_has_the_five_steps():
    blocks = bash_blocks(PAGE.read_text())
    assert [b.split()[0:2] for b in blocks] == [["imu-learn", "calibrate"], ["cat", "calib/imu.yaml"],
                                                ["imu-learn", "refine"], ["imu-learn", "navigate"],
                                                ["imu-learn", "groundtruth"]]
    assert "[your-device.md](your-device.md)" in (REPO / "docs" / "README.md").read_text()


@pytest.mark.slow
def test_the_pages_commands_run_on_a_users_csv(tmp_path):
    write_user_files(tmp_path)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
               OMP_NUM_THREADS="1")
    for block in bash_blocks(PAGE.read_text()):
        r = subprocess.run(["bash", "-euo", "pipefail", "-c", block], cwd=tmp_path, env=env, capture_output=True,
                           text=True, timeout=900)
        assert r.returncode == 0, f"{block}\n{r.stdout}\n{r.stderr}"
    # 1. the profile, its noise file and plot
    prof = json.loads((tmp_path / "calib" / "profile.json").read_text())
    assert prof["device"] == "my-imu" and abs(prof["sample_rate_hz"] - 100.0) < 1.0
    for name in ("imu.yaml", "calibration.png"):
        assert (tmp_path / "calib" / name).is_file(), name
    # 2. Kalibr's four figures and the rate
    yaml = (tmp_path / "calib" / "imu.yaml").read_text()
    for key in ("gyroscope_noise_density", "gyroscope_random_walk", "accelerometer_noise_density",
                "accelerometer_random_walk", "update_rate"):
        assert re.search(rf"^{key}: [0-9.e+-]+", yaml, flags=re.M), key
    # 3. the refined stream keeps the user's header, columns and text columns
    old = (tmp_path / "my_imu.csv").read_text().splitlines()
    new = (tmp_path / "my_imu_refined.csv").read_text().splitlines()
    assert new[0] == old[0] and len(new) == len(old)
    assert [r.split(";")[:2] for r in new[1:]] == [r.split(";")[:2] for r in old[1:]]
    assert new[1:] != old[1:]
    # 4. the trajectory, with the profile's noise and floor
    s = json.loads((tmp_path / "nav" / "summary.json").read_text())
    assert s["imu_noise"]["source"].startswith("profile calib/profile.json") and s["profile_floor"] is True
    assert (tmp_path / "nav" / "smoothed.tum").is_file() and s["keyframes"] > 100

    # against the ground truth, which the commands never read beyond vio.tum's 20 Hz poses
    gt = read_groundtruth(STATE)
    state = np.loadtxt(STATE, delimiter=",", comments="#")
    t_raw, g_raw = read_user_csv(tmp_path / "my_imu.csv")
    in_span = (gt.t_ns >= t_raw[0]) & (gt.t_ns <= t_raw[-1])
    # 1. the gyro bias the profile removes (w = M_g (w_m - b_g) - G a at the recording's mean specific
    # force: b_g + M_g^-1 G mean(a)) is the ground truth's estimate (EuRoC's b_w columns; 0.077 rad/s on z)
    b_w = state[in_span, 11:14].mean(0)
    acc_mean = np.loadtxt(tmp_path / "my_imu.csv", delimiter=";", skiprows=1)[:, 5:8].mean(0) * 9.80665
    M_g, G = np.asarray(prof["gyroscope"]["matrix"]), np.asarray(prof["g_sensitivity_rad_s_per_mps2"])
    removed = np.asarray(prof["gyroscope"]["bias"]) + np.linalg.solve(M_g, G @ acc_mean)
    assert np.abs(removed - b_w).max() < 1.5e-3, (removed, b_w)
    # the time offset is the zero-order hold's half sample (+5 ms at 100 Hz: the IMU and the ground
    # truth share a clock, and a sample holds the rate at its start over the interval after it)
    assert abs(prof["time_offset_s"] - 0.005) < 1e-3, prof["time_offset_s"]
    # 3. the refined stream turns as the ground truth does: its rotation error over 1 s is no worse than
    # the raw stream's with the ground truth's own bias removed (the raw stream's is 100 times that)
    t_ref, g_ref = read_user_csv(tmp_path / "my_imu_refined.csv")
    assert np.abs(t_ref - t_raw).max() < 1000
    raw_err, refined_err = rotation_error_1s(t_raw, g_raw, gt), rotation_error_1s(t_ref, g_ref, gt)
    oracle_err = rotation_error_1s(t_raw, g_raw - b_w, gt)
    assert raw_err > 0.05 and refined_err < 1.25 * oracle_err, (raw_err, refined_err, oracle_err)
    # 4. the smoothed trajectory is where the ground truth is
    nav = np.loadtxt(tmp_path / "nav" / "smoothed.tum", comments="#")
    k = nearest(gt.t_ns, np.round(nav[:, 0] * 1e9).astype(np.int64))
    rms = float(np.sqrt(np.mean(np.sum((nav[:, 1:4] - gt.p[k]) ** 2, axis=1))))
    assert rms < 0.03, rms
