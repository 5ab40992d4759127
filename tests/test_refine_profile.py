"""``imu-learn refine --profile``: the floor ``evaluate`` fits (traditional+timing) written as a
device profile and applied by refine gives the model the profile's conventions document (the numpy
oracle of test_calibrate_profile) and evaluate's own samples bit for bit, in the recording's own
format (with set parameters; with parameters fitted on the MH_01 crop, slow)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from floors import set_floor, write_broad_trial
from imu_learn import _imu_core as core
from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.traditional import TraditionalTiming
from imu_learn.calib.profile import Affine, Profile
from imu_learn.cli.refine import main as refine_main
from imu_learn.data.types import Segment, sample_rate_hz
from test_calibrate_profile import assert_documented

REPO = Path(__file__).resolve().parent.parent
MH04 = REPO / "datasets" / "euroc" / "MH_04_difficult"
IMU_REL = Path("mav0") / "imu0" / "data.csv"


def as_profile(m: TraditionalTiming, rate: float, device: str) -> Profile:
    fl = m.to_dict()
    return Profile(device=device, sample_rate_hz=rate, time_offset_s=float(fl["time_offset"]) / rate,
                   time_offset_s_std=math.nan, gyro=Affine(np.asarray(fl["M_g"]), np.asarray(fl["b_g"]), "rad/s"),
                   acc=Affine(np.asarray(fl["M_a"]), np.asarray(fl["b_a"]), "m/s^2"),
                   g_sensitivity=np.asarray(fl["G"]), gravity_mps2=9.81, gravity_mps2_std=math.nan, floor=fl)


def refined_as_evaluate(m: TraditionalTiming, tmp_path: Path, capsys) -> None:
    """``m`` as a profile through ``imu-learn refine --profile`` on the MH_04 crop: its ASL output is
    the documented model (an independent numpy oracle) and ``m.refine`` of the recording's whole
    IMU, bit for bit."""
    t, g, a = core.read_asl_imu(str(MH04 / IMU_REL))
    prof = as_profile(m, sample_rate_hz(t), "euroc")  # 200.0026 Hz: the offset in seconds as calibrate writes it
    prof.save(tmp_path / "profile.json")
    out = tmp_path / "MH_04_floor"
    assert refine_main(["--profile", str(tmp_path / "profile.json"), "--input", str(MH04), "--out", str(out),
                        "--format", "euroc"]) == 0
    cap = capsys.readouterr()
    assert cap.err == "" and "recording at 200 Hz" in cap.out
    t2, g2, a2 = core.read_asl_imu(str(out / IMU_REL))
    n = len(t)
    want_g, want_a = m.refine(Segment("MH_04", t, g, a, np.zeros((n, 3)), np.zeros((n, 3)),
                                      np.tile([1.0, 0, 0, 0], (n, 1))))
    assert np.array_equal(t2, t)
    assert_documented(prof, t, g, a, g2, a2)
    assert np.array_equal(g2, want_g) and np.array_equal(a2, want_a)  # shortest round-trip text: exact
    assert np.abs(g2 - g).max() > 1e-3


def test_refine_with_a_profile_is_the_floors_refine_bit_for_bit(tmp_path, capsys):
    refined_as_evaluate(set_floor((30.0, 15.0), 0.54), tmp_path, capsys)


@pytest.mark.slow
def test_refine_with_a_profile_is_evaluates_fitted_floor_bit_for_bit(crop_split, tmp_path, capsys):
    train, val = crop_split  # the MH_01 crop
    m = TraditionalTiming()
    m.fit([train], [val], FitSettings(seed=0))
    assert abs(m.params.time_offset) > 0.01 and sample_rate_hz(train.t_ns) == pytest.approx(200.0, rel=1e-3)
    refined_as_evaluate(m, tmp_path, capsys)


def test_a_broad_trial_takes_a_profile_on_its_nominal_stamps_and_one_without_a_rate_is_refused(tmp_path, capsys):
    """A BROAD trial stores its rate, not stamps: refine applies a profile's time offset on the stamps of that
    rate, as evaluate reads the trial (the shipped BROAD profile was refused on every trial); a .mat with no
    rate has no stamps and is refused (one line, nothing written)."""
    scipy_io = pytest.importorskip("scipy.io")
    src = write_broad_trial(tmp_path / "01_trial.mat", scipy_io)
    m = set_floor((30.0, 15.0), 0.54)
    prof = as_profile(m, 286.0, "broad")
    prof.save(tmp_path / "profile.json")
    assert refine_main(["--profile", str(tmp_path / "profile.json"), "--input", str(src), "--out",
                        str(tmp_path / "out.mat"), "--quiet"]) == 0
    capsys.readouterr()
    back = scipy_io.loadmat(str(tmp_path / "out.mat"))
    mat = scipy_io.loadmat(str(src))
    g, a = mat["imu_gyr"], mat["imu_acc"]
    t = np.round(np.arange(len(g)) * (1e9 / 286.0)).astype(np.int64)
    want_g, want_a = m.refine(Segment("t", t, g, a, np.zeros_like(g), np.zeros_like(g), np.tile([1.0, 0, 0, 0], (len(g), 1))))
    assert np.array_equal(back["imu_gyr"], want_g) and np.array_equal(back["imu_acc"], want_a)
    assert not np.allclose(back["imu_gyr"], g)
    bare = tmp_path / "02_bare.mat"
    scipy_io.savemat(bare, {"imu_gyr": g, "imu_acc": a})
    assert refine_main(["--profile", str(tmp_path / "profile.json"), "--input", str(bare), "--out",
                        str(tmp_path / "out2.mat"), "--format", "broad"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no stamps" in err, err
    assert not (tmp_path / "out2.mat").exists()


@pytest.mark.parametrize("option, given, names", [
    ("--profile", "models/euroc_adis16448.pt", "give it with --checkpoint"),
    ("--profile", "models/profiles/euroc_adis16448", "it holds profile.json: give that"),
    ("--profile", "models/profiles/euroc_adis16448/imu.yaml", "give the profile.json beside it"),
    ("--checkpoint", "models/profiles/euroc_adis16448/profile.json", "apply it with --profile"),
])
def test_a_file_given_for_the_other_option_is_one_line_naming_the_right_one(tmp_path, capsys, option, given, names):
    """A checkpoint given as --profile ended in a UnicodeDecodeError traceback (exit 1); a profile given as
    --checkpoint pasted torch's advice to load with weights_only=False. Each is one line, exit 2, nothing
    written, naming the option or file that takes it."""
    out = tmp_path / "out"
    assert refine_main([option, str(REPO / given), "--input", str(MH04), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and names in err[0] and "weights_only" not in err[0], err
    assert not out.exists()


def test_a_noise_only_profile_says_the_readings_pass_unchanged(tmp_path, capsys):
    """A profile of calibrate --imu-only holds no floor: refine writes the readings as they were, and says so
    (a BROAD user's refined file was the input byte for byte under "refined IMU (the floor of profile ...)")."""
    from imu_learn.calib.profile import noise_only

    t, g, a = core.read_asl_imu(str(MH04 / IMU_REL))
    noise_only("euroc", sample_rate_hz(t), {}).save(tmp_path / "profile.json")
    out = tmp_path / "MH_04_noise"
    assert refine_main(["--profile", str(tmp_path / "profile.json"), "--input", str(MH04), "--out", str(out),
                        "--format", "euroc"]) == 0
    cap = capsys.readouterr()
    assert "holds the noise only" in cap.err and "pass unchanged" in cap.err
    assert "no floor" in cap.out and "holds noise only" in cap.out and "the floor of" not in cap.out
    t2, g2, a2 = core.read_asl_imu(str(out / IMU_REL))
    assert np.array_equal(t2, t) and np.array_equal(g2, g) and np.array_equal(a2, a)
