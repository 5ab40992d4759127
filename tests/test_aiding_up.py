"""Position aiding's world must be z up: checked against the accelerometer's specific-force norm
(imu_learn.fuse.start.gravity) before any fusion, on a closed-form trajectory; and navigate refuses
a real VO's camera-frame positions given as position aiding."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.fuse.start.gravity import MAX_TILT_DEG, check_gravity

G = 9.81


def _track(seconds: float = 60.0, imu_hz: float = 200.0, aid_hz: float = 20.0, body_turn: bool = True):
    """Positions p(t) (closed form, m) and the specific force f = R^T (p'' + g up) of a body turning about
    every axis: an accelerometer that needs no integration."""
    ti = np.arange(0.0, seconds, 1.0 / imu_hz)
    w = np.array([0.9, 0.7, 1.3])
    amp = np.array([1.0, 0.8, 0.4])

    def acc(t):
        return -(amp * w ** 2) * np.sin(np.outer(t, w))

    rot = Rotation.from_rotvec(np.c_[0.3 * np.sin(0.5 * ti), 0.2 * np.cos(0.3 * ti), 0.4 * ti] if body_turn
                               else np.zeros((len(ti), 3)))
    f = rot.inv().apply(acc(ti) + [0.0, 0.0, G])
    ta = np.arange(0.0, seconds, 1.0 / aid_hz)
    p = amp * np.sin(np.outer(ta, w))
    return (ti * 1e9).astype(np.int64), f, (ta * 1e9).astype(np.int64), p


def test_a_z_up_world_passes_and_a_tilted_one_is_found():
    ti, f, ta, p = _track()
    ok = check_gravity(ti, f, ta, p, G)
    assert ok.verdict == "ok" and ok.tilt_deg < 4.0, ok  # the sphere's grid is about 3 degrees
    for deg in (30.0, 90.0, 180.0):
        R = Rotation.from_euler("x", deg, degrees=True).as_matrix()
        bad = check_gravity(ti, f, ta, p @ R.T, G)
        assert bad.verdict == "refused" and abs(bad.tilt_deg - deg) < 4.0, (deg, bad)
    small = check_gravity(ti, f, ta, p @ Rotation.from_euler("x", MAX_TILT_DEG / 2, degrees=True).as_matrix().T, G)
    assert small.verdict == "ok"  # within the rule's tolerance: not refused


def test_positions_in_millimetres_are_named():
    ti, f, ta, p = _track()
    check = check_gravity(ti, f, ta, p * 1000.0, G)
    assert check.verdict == "refused" and check.scale == 1e-3 and "x1000" in check.why and "millimetres" in check.why
    assert check_gravity(ti, f, ta, p, G).scale == 1.0


def test_too_few_rows_are_not_checked():
    ti, f, ta, p = _track(seconds=2.0)
    assert check_gravity(ti, f, ta, p, G).verdict == "not checked"


def test_navigate_refuses_camera_frame_positions_before_fusing(shared, tmp_path):
    vo = shared / "euroc-vo/orbslam2_stereo/trial0/MH01.txt"
    r = subprocess.run([sys.executable, "-m", "imu_learn.cli", "navigate", "--input", str(shared / "euroc/MH_01_easy"),
                        "--aiding", str(vo), "--aiding-kind", "position", "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 2, r.stderr[-2000:]
    assert "world is not z up" in r.stderr and "--aiding-kind pose" in r.stderr
    assert not (tmp_path / "out").exists()
