"""A recording's own gyro bias from its still stretches (imu_learn.core.still), without ground truth:
recovered within its white-noise error on a synthetic recording of known bias, close to the bias
fitted against ground truth on the MH_01 crop, and applied by ``imu-learn refine --bias still``."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from floors import write_broad_trial
from imu_learn import _imu_core as core
from imu_learn.core.still import StillSettings, still_bias, still_stretches
from imu_learn.data import synthetic
from imu_learn.data.loading import load_sequence
from imu_learn.score.metrics import fit_startup_bias

REPO = Path(__file__).resolve().parent.parent
MH01 = REPO / "datasets" / "euroc" / "MH_01_easy"
IMU_REL = Path("mav0") / "imu0" / "data.csv"
BIAS = np.array([0.01, -0.02, 0.005])
SIGMA_G, SIGMA_A = 0.002, 0.02


def recording(still_s=(8.0, 8.0), spin_s=10.0, seed=0):
    """Still, a spin at 0.7 rad/s about a tilted axis, still again (at the spin's last attitude):
    the exact IMU plus ``BIAS`` and white noise."""
    n_still = [int(s * synthetic.RATE) for s in still_s]
    spin = synthetic.spin(spin_s, 0.7)
    gyro = np.vstack([np.zeros((n_still[0], 3)), spin.gyro, np.zeros((n_still[1], 3))])
    acc = np.vstack([np.tile(spin.acc[0], (n_still[0], 1)), spin.acc, np.tile(spin.acc[-1], (n_still[1], 1))])
    t = synthetic.stamps(len(gyro) / synthetic.RATE)[: len(gyro)]
    rng = np.random.default_rng(seed)
    return t, gyro + BIAS + rng.normal(0, SIGMA_G, gyro.shape), acc + rng.normal(0, SIGMA_A, acc.shape)


def test_the_gyro_bias_is_recovered_within_its_noise():
    t, g, a = recording()
    est = still_bias(t, g, a, StillSettings(gravity=synthetic.G))
    assert len(est.stretches) == 2 and est.still_s > 13.5  # 8 s each, less the trims and the window's reach
    assert np.all(np.abs(est.gyro_bias - BIAS) < 4 * SIGMA_G / np.sqrt(est.samples))
    assert np.allclose(est.gyro_bias_std, SIGMA_G / np.sqrt(est.samples), rtol=0.1)
    assert abs(est.acc_norm_minus_gravity) < 0.01
    # the spin is quiet in the gyro (a constant rate) but not in the accelerometer: never still
    i0 = int(8.0 * synthetic.RATE)
    assert all(b <= i0 or a >= i0 + 10 * synthetic.RATE for a, b in est_ranges(t, g, a))


def est_ranges(t, g, a):
    return still_stretches(t, g, a, StillSettings(gravity=synthetic.G))


def test_without_a_still_stretch_there_is_no_estimate():
    t, g, a = recording(still_s=(0.5, 0.5))
    est = still_bias(t, g, a, StillSettings(gravity=synthetic.G))
    assert est.gyro_bias is None and est.still_s == 0.0 and est.to_dict()["gyro_bias_rad_s"] is None


def test_the_gravity_check_rejects_a_smooth_acceleration():
    t, g, a = recording()
    a = a * 1.1  # every still sample 1 m/s^2 off gravity: a steady push, not rest
    assert still_bias(t, g, a, StillSettings(gravity=synthetic.G)).gyro_bias is None
    assert still_bias(t, g, a, StillSettings()).gyro_bias is not None  # calibrate's detector has no such check


def test_the_mh01_crop_still_bias_is_near_the_ground_truth_fit():
    """MH_01's crop rests for about 10 s (two stretches after the hand-held excitation); the bias
    fitted against ground truth over its first 10 s agrees within 1.5e-3 rad/s per axis (0.09 deg/s;
    the two differ by the reference's own error and the bias's drift between the spans)."""
    t, g, a = core.read_asl_imu(str(MH01 / IMU_REL))
    est = still_bias(t, g, a)
    assert est.still_s > 8.0
    fitted, _ = fit_startup_bias(load_sequence(MH01)[0], seconds=10.0)
    assert np.all(np.abs(est.gyro_bias - fitted) < 1.5e-3), (est.gyro_bias, fitted)
    assert abs(est.acc_norm_minus_gravity) < 0.1


def write_asl(folder: Path, t, g, a) -> Path:
    f = folder / IMU_REL
    f.parent.mkdir(parents=True)
    core.write_asl_imu(str(f), t, g, a, "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                       "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
    return folder


@pytest.mark.parametrize("still_s", [(8.0, 8.0), (0.5, 0.5)])
def test_refine_bias_still_subtracts_the_estimate_and_writes_it_into_the_summary(tmp_path, capsys, still_s):
    pytest.importorskip("torch")
    import json

    from imu_learn.cli.refine import main

    t, g, a = recording(still_s)
    src = write_asl(tmp_path / "in", t, g, a)
    model = REPO / "models" / "euroc_adis16448.pt"
    for bias, out in (("none", tmp_path / "plain"), ("still", tmp_path / "still")):
        assert main(["--checkpoint", str(model), "--input", str(src), "--out", str(out), "--bias", bias, "--quiet",
                     "--device", "cpu"]) == 0
    err = capsys.readouterr().err
    _, g_plain, _ = core.read_asl_imu(str(tmp_path / "plain" / IMU_REL))
    _, g_still, a_still = core.read_asl_imu(str(tmp_path / "still" / IMU_REL))
    summary = json.loads((tmp_path / "still" / "summary.json").read_text())["bias"]
    assert summary["method"] == "still" and "observable" in summary
    if still_s[0] > 2:
        est = np.array(summary["gyro_bias_rad_s"])
        assert summary["applied"] and len(summary["stretches"]) == 2
        assert np.allclose(g_still, g_plain - est, atol=1e-9)  # after the model: the bias it leaves
        assert "no still stretch" not in err
    else:
        assert not summary["applied"] and summary["gyro_bias_rad_s"] is None
        assert np.array_equal(g_still, g_plain)
        assert err.count("no still stretch") == 1


def test_refine_with_a_profile_removes_the_bias_without_torch_and_its_statistics_guard_it(tmp_path, capsys):
    """A profile (here one without a floor: the identity) with --bias still: the output is the input
    minus the estimate; statistics a profile carries are checked like a model's."""
    import json
    import math

    from imu_learn.calib.profile import Affine, Profile
    from imu_learn.cli.refine import main
    from imu_learn.infer.guard import training_inputs

    t, g, a = recording()
    src = write_asl(tmp_path / "in", t, g, a)
    eye = Affine(np.eye(3), np.zeros(3), "rad/s")
    prof = Profile(device="synthetic", sample_rate_hz=200.0, time_offset_s=0.0, time_offset_s_std=math.nan, gyro=eye,
                   acc=Affine(np.eye(3), np.zeros(3), "m/s^2"), g_sensitivity=np.zeros((3, 3)), gravity_mps2=synthetic.G,
                   gravity_mps2_std=math.nan, floor={}, inputs=training_inputs([("synthetic", t, g, a)]))
    prof.save(tmp_path / "profile.json")
    assert Profile.load(tmp_path / "profile.json").inputs["recordings"][0]["name"] == "synthetic"
    out = tmp_path / "out.csv"
    assert main(["--profile", str(tmp_path / "profile.json"), "--input", str(src / IMU_REL), "--out", str(out),
                 "--bias", "still"]) == 0
    assert capsys.readouterr().err == ""
    summary = json.loads((tmp_path / "out.csv.summary.json").read_text())
    assert summary["guard"]["verdict"] == "like the training data"
    est = np.array(summary["bias"]["gyro_bias_rad_s"])
    assert np.all(np.abs(est - BIAS) < 4 * SIGMA_G / np.sqrt(summary["bias"]["samples"]))
    _, g_out, a_out = core.read_asl_imu(str(out))
    assert np.allclose(g_out, g - est, atol=1e-12) and np.array_equal(a_out, a)


def test_bias_still_on_a_recording_without_stamps_is_one_line(tmp_path, capsys):
    pytest.importorskip("torch")
    scipy_io = pytest.importorskip("scipy.io")
    from imu_learn.cli.refine import main

    # a BROAD-layout .mat without its sampling_rate: no stamps at all (a trial with its rate has the nominal ones)
    trial = scipy_io.loadmat(str(write_broad_trial(tmp_path / "01_trial.mat", scipy_io)))
    src = tmp_path / "02_bare.mat"
    scipy_io.savemat(src, {"imu_gyr": trial["imu_gyr"], "imu_acc": trial["imu_acc"]})
    model = REPO / "models" / "broad_handheld.pt"
    assert main(["--checkpoint", str(model), "--input", str(src), "--out", str(tmp_path / "out"), "--bias", "still",
                 "--device", "cpu", "--format", "broad"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no stamps" in err and "--bias still" in err, err
