"""``imu-learn navigate --bias still|gravity``: the recording's own gyro bias estimated on the IMU as
fused (refine's estimator) and subtracted before the fusion, the estimate in summary.json; without
--bias nothing changes. On the shipped MH_04 crop, camera poses made from its ground truth."""
from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("gtsam")

from crops import CROP, SHIPPED  # noqa: E402
from imu_learn.cli import main  # noqa: E402
from imu_learn.core.still import BIAS_SETTINGS, still_bias  # noqa: E402
from imu_learn.data.formats.extrinsics import read_t_bs  # noqa: E402
from imu_learn.data.loading import read_imu  # noqa: E402
from imu_learn.fuse.aiding.tum import read_tum  # noqa: E402
from test_navigate import CAM0_YAML, GT_REL, camera_trajectory_from_groundtruth, write  # noqa: E402


@pytest.fixture(scope="module")
def crop(tmp_path_factory):
    root = tmp_path_factory.mktemp("navbias")
    rec = root / "MH_04_difficult"
    shutil.copytree(SHIPPED / CROP / "mav0" / "imu0", rec / "mav0" / "imu0")
    yaml = write(root / "cam0_sensor.yaml", CAM0_YAML)
    tum = camera_trajectory_from_groundtruth(SHIPPED / CROP / GT_REL, read_t_bs(yaml), root / "cam0.tum")
    return rec, tum, yaml


def run(crop, out, *extra):
    rec, tum, yaml = crop
    assert main(["navigate", "--input", str(rec), "--aiding", str(tum), "--aiding-kind", "relative-pose",
                 "--extrinsics", str(yaml), "--out", str(out), "--quiet", *extra]) == 0
    return json.loads((out / "summary.json").read_text())


def test_navigate_bias_writes_the_estimate_and_none_changes_nothing(crop, tmp_path, capsys):
    plain = run(crop, tmp_path / "plain")
    none = run(crop, tmp_path / "none", "--bias", "none")
    assert plain["bias"] == none["bias"] == {"method": "none"}
    assert (tmp_path / "plain" / "smoothed.tum").read_text() == (tmp_path / "none" / "smoothed.tum").read_text()
    capsys.readouterr()
    # the MH_04 crop never rests 2 s: one warning line, nothing subtracted, the same trajectory
    s = run(crop, tmp_path / "still", "--bias", "still")
    assert s["bias"]["method"] == "still" and not s["bias"]["applied"] and s["options"]["bias"] == "still"
    assert capsys.readouterr().err.count("no still stretch") == 1
    assert (tmp_path / "plain" / "smoothed.tum").read_text() == (tmp_path / "still" / "smoothed.tum").read_text()
    # 60 s: six windows of 10 s for gravity consistency
    g = run(crop, tmp_path / "gravity", "--bias", "gravity")["bias"]
    assert g["method"] == "gravity" and g["applied"] and g["windows"] == 6 and len(g["gyro_bias_rad_s"]) == 3
    assert len(read_tum(tmp_path / "gravity" / "smoothed.tum")) == len(read_tum(tmp_path / "plain" / "smoothed.tum"))


def reference_rest_bias(seconds=(21.5, 29.5)) -> np.ndarray:
    """The MH_01 crop's gyro bias from its ground truth, independent of the still detector: over a
    stretch where the ground truth rests (moves < 1 mm), the mean gyro minus the reference's mean
    body rate there (Log(q0* q1) / T, numpy quaternions)."""
    from crops import load_easy
    from imu_learn.data.synthetic import qconj, qmul

    s = load_easy()
    t = (s.t_ns - s.t_ns[0]) * 1e-9
    k0, k1 = np.searchsorted(t, seconds)
    d = qmul(qconj(s.q_wxyz[k0]), s.q_wxyz[k1])
    d = d * np.sign(d[0])
    n = np.linalg.norm(d[1:])
    rate = 2 * np.arctan2(n, d[0]) * d[1:] / n / (t[k1] - t[k0])
    assert np.linalg.norm(s.p[k1] - s.p[k0]) < 1e-3 and np.linalg.norm(rate) < 1e-3
    return s.gyro[k0:k1].mean(0) - rate


def test_own_bias_on_a_resting_crop_is_refines_still_estimate():
    """The MH_01 crop rests about 10 s: navigate's step subtracts the bias its ground truth gives
    (within 0.5 mrad/s; EuRoC's is 0.08 rad/s on z), and exactly what refine's estimator finds."""
    from imu_learn.fuse.navigate import NavigateOptions, own_bias

    imu = read_imu(SHIPPED / "euroc" / "MH_01_easy")
    g, entry = own_bias(NavigateOptions(bias="still"), imu.t_ns, imu.gyro, imu.acc, "MH_01")
    assert entry["applied"] and entry["still_s"] >= 2.0 and len(entry["stretches"]) == 2
    want = reference_rest_bias()
    assert np.abs(np.asarray(entry["gyro_bias_rad_s"]) - want).max() < 5e-4, (entry["gyro_bias_rad_s"], want)
    assert np.abs((imu.gyro - g) - want).max() < 5e-4  # subtracted, not added
    est = still_bias(imu.t_ns, imu.gyro, imu.acc, replace(BIAS_SETTINGS, gravity=NavigateOptions().gravity))
    assert np.allclose(entry["gyro_bias_rad_s"], est.gyro_bias, atol=0)
    assert np.allclose(g, imu.gyro - est.gyro_bias, atol=0)
    assert own_bias(NavigateOptions(), imu.t_ns, imu.gyro, imu.acc, "MH_01")[1] == {"method": "none"}


def test_the_prior_keeps_the_device_bias_only_where_the_estimate_saw_nothing():
    from imu_learn.fuse.navigate import unobserved

    assert np.array_equal(unobserved({"method": "still", "applied": True}), np.zeros((3, 3)))
    P = unobserved({"directions_body": [[0, 0, 1], [1, 0, 0], [0, 1, 0]], "direction_observed": [False, True, True]})
    assert np.array_equal(P @ np.array([0.1, 0.2, 0.3]), [0, 0, 0.3])
