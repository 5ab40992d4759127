"""docs/your-device.md cannot rot: its ```bash blocks are run, in order, in a folder holding what the
page says the user has: ``my_imu.csv`` (the shipped MH_04 crop at the Fetch robot's 100 Hz, exported
with semicolons, other names, a temperature column, deg/s, g and float seconds) and ``vio.tum`` (its
reference at 20 Hz); then what the page says each step writes is checked."""
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


def test_the_page_has_the_four_steps():
    blocks = bash_blocks(PAGE.read_text())
    assert [b.split()[0:2] for b in blocks] == [["imu-learn", "calibrate"], ["cat", "calib/imu.yaml"],
                                                ["imu-learn", "refine"], ["imu-learn", "navigate"]]
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
    assert s["imu_noise"]["source"] == "profile calib/profile.json" and s["profile_floor"] is True
    assert (tmp_path / "nav" / "smoothed.tum").is_file() and s["keyframes"] > 100
