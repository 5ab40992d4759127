"""calibrate with the references users have, on the shipped EuRoC crop: its ground truth as given
(the oracle), the same poses in another frame, world and clock, and as a sparse 20 Hz reference; a
reference of another recording and a planar one are refused before any fit."""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from crops import EASY, SHIPPED
from imu_learn.calib.run import NOT_SELECTED
from imu_learn.calib.select import POSITION_ACC_LEVELS
from imu_learn.calib.sources import PosesSource
from imu_learn.cli import main
from imu_learn.core.quat import quat_from_matrix, quat_mul, wxyz_to_xyzw
from imu_learn.data.formats import read_recording

pytestmark = pytest.mark.slow

REC = SHIPPED / EASY
R_TRUE_AXIS, R_TRUE_DEG = np.array([1.0, 2.0, 3.0]), 119.0


def quat_axis_angle(axis: np.ndarray, deg: float) -> np.ndarray:
    a = math.radians(deg) / 2
    return np.r_[math.cos(a), math.sin(a) * axis / np.linalg.norm(axis)]


def write_reference(path: Path, rotate=True, world_deg=0.0, late_s=0.0, every=1) -> Path:
    """The crop's ground truth seen by a sensor rotated R_TRUE about the IMU (same origin), in a world
    turned ``world_deg`` about x, its stamps ``late_s`` late, every ``every``-th pose, as TUM."""
    _, gt = read_recording(REC)
    q = gt.q_wxyz
    if rotate:
        q = quat_mul(q, quat_axis_angle(R_TRUE_AXIS, R_TRUE_DEG)[None])
    qw = quat_axis_angle(np.array([1.0, 0, 0]), world_deg)
    q = quat_mul(qw[None], q)
    c, s = math.cos(math.radians(world_deg)), math.sin(math.radians(world_deg))
    p = gt.p @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T
    rows = np.column_stack([gt.t_ns * 1e-9 + late_s, p, wxyz_to_xyzw(q)])[::every]
    np.savetxt(path, rows, fmt="%.9f")
    return path


def calibrate(out: Path, *extra: str) -> dict:
    code = main(["calibrate", "--input", str(REC), "--out", str(out), "--no-plot", "--quiet", *extra])
    assert code == 0
    return json.loads((out / "profile.json").read_text())


@pytest.fixture(scope="module")
def oracle(tmp_path_factory) -> dict:
    return calibrate(tmp_path_factory.mktemp("oracle"), "--no-select")  # every term: the frames' oracle


def close(a, b, sa, sb, k=4.0, floor=0.0) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    tol = k * np.sqrt(np.nan_to_num(np.asarray(sa)) ** 2 + np.nan_to_num(np.asarray(sb)) ** 2) + floor
    return bool(np.all(np.abs(a - b) <= tol))


def test_a_reference_in_another_frame_and_world_gives_the_oracles_profile(tmp_path, oracle):
    ref = write_reference(tmp_path / "rotated.tum", world_deg=100.0)
    p = calibrate(tmp_path / "out", "--groundtruth", str(ref), "--no-select")
    r = p["reference"]
    assert r["applied"]["rotation"] and r["applied"]["level"] and not r["applied"]["lag"]
    angle = 2 * math.degrees(math.acos(min(1.0, abs(float(np.dot(
        quat_from_matrix(np.asarray(r["rotation_imu_from_reference"])), quat_axis_angle(R_TRUE_AXIS, R_TRUE_DEG)))))))
    assert angle < 0.3
    assert r["world_tilt_deg"] == pytest.approx(100.0, abs=1.0)
    g, og = p["gyroscope"], oracle["gyroscope"]
    assert close(g["bias"], og["bias"], g["bias_std"], og["bias_std"], floor=2e-4)
    assert close(g["matrix"], og["matrix"], g["matrix_std"], og["matrix_std"], floor=2e-3)
    # along gravity (the crop's IMU x points up) the acc bias is the oracle's; across gravity it trades with
    # the levelled world's tilt (0.1 m/s^2 per 0.6°), which a 60 s flight near level cannot tell apart
    a, oa = np.asarray(p["accelerometer"]["bias"]), np.asarray(oracle["accelerometer"]["bias"])
    assert abs(a[0] - oa[0]) < 0.03 and np.all(np.abs(a[1:] - oa[1:]) < 0.2)
    assert "along gravity" in p["observed"]["accelerometer.bias"]["partly"]
    assert p["time_offset_s"] == pytest.approx(oracle["time_offset_s"], abs=1e-3)
    assert all(v["observed"] for v in p["observed"].values())


def test_a_late_reference_is_moved_and_the_imus_offset_left_unobserved(tmp_path, oracle):
    ref = write_reference(tmp_path / "late.tum", rotate=False, late_s=0.1)
    p = calibrate(tmp_path / "out", "--groundtruth", str(ref), "--no-select")
    assert p["reference"]["applied"]["lag"] and p["reference"]["lag_s"] == pytest.approx(0.1, abs=0.006)
    # the IMU's own offset is not observable apart from the reference's lag: the prior, half a sample
    assert p["time_offset_s"] == pytest.approx(0.5 / p["sample_rate_hz"], rel=1e-6)
    assert not p["observed"]["time_offset"]["observed"]
    assert close(p["gyroscope"]["bias"], oracle["gyroscope"]["bias"], p["gyroscope"]["bias_std"],
                 oracle["gyroscope"]["bias_std"], floor=5e-4)


def test_a_20_hz_reference_fits_the_accelerometer_from_its_positions(tmp_path, oracle):
    """A 20 Hz reference's velocity cannot resolve accelerations (no low-pass chosen); its positions
    give the accelerometer's matrix and bias (calib.acc_positions), the oracle's within the two stated
    uncertainties; the reference's origin is the IMU's."""
    ref = write_reference(tmp_path / "vo.tum", world_deg=100.0, every=10)
    p = calibrate(tmp_path / "out", "--groundtruth", str(ref))
    assert not p["reference"]["resolves_acceleration"]
    assert "a poses reference" in p["selection"]["by_default"]  # its terms chosen by default
    assert p["selection"]["held_out"] == "four time blocks of one recording"
    assert p["floor"]["cutoff_gyro"] is None and p["floor"]["cutoff_acc"] is None
    # the low-pass is not observed, and neither are the terms the selection left at their prior: the one
    # recording's four time blocks held out in turn choose the accelerometer's level from the positions too
    unselected = set(NOT_SELECTED["gyro"].get(p["selection"]["gyro"], ()))
    acc_level = p["selection"]["acc"]
    assert acc_level in POSITION_ACC_LEVELS and set(p["selection"]["held_out_figures"]["acc"][acc_level]) == \
        {"block1", "block2", "block3", "block4"}
    acc_unselected = {"accelerometer.matrix"} if acc_level in ("offset", "bias") else set()
    assert {k for k, v in p["observed"].items() if not v["observed"]} == \
        {"cutoff_gyro", "cutoff_acc"} | unselected | acc_unselected
    assert all("not selected" in p["observed"][k]["why"] for k in (unselected | acc_unselected) - {"cutoff_gyro"})
    assert close(p["gyroscope"]["bias"], oracle["gyroscope"]["bias"], p["gyroscope"]["bias_std"],
                 oracle["gyroscope"]["bias_std"], floor=5e-4)
    a, oa = p["accelerometer"], oracle["accelerometer"]
    fit = p["reference"]["accelerometer_from_positions"]
    if acc_unselected:
        assert np.array_equal(a["matrix"], np.eye(3))
    else:
        assert "positions" in p["observed"]["accelerometer.matrix"]["how"]
        assert close(a["matrix"], oa["matrix"], fit["M_a_std"], oa["matrix_std"]), (a["matrix"], oa["matrix"])
        assert np.all(np.abs(np.diag(a["matrix"]) - np.diag(oa["matrix"])) < 0.01)  # the scales to 1 %
    assert np.all(np.abs(np.asarray(fit["lever_arm_m"])) <= 4 * np.asarray(fit["lever_arm_std_m"]) + 0.005)
    assert np.all(np.abs(np.asarray(a["bias"])) < 0.3)


def monocular(path: Path, drift: float) -> Path:
    """The 20 Hz poses' position steps x0.4, the scale constant or drifting linearly to x0.4(1 + drift)."""
    rows = np.loadtxt(path)
    t = rows[:, 0]
    s = 0.4 * (1 + drift * (t - t[0]) / (t[-1] - t[0]))
    start = 0.4 * rows[:1, 1:4]
    rows[:, 1:4] = np.vstack([start, start + np.cumsum(s[1:, None] * np.diff(rows[:, 1:4], axis=0), axis=0)])
    np.savetxt(path, rows, fmt="%.9f")
    return path


@pytest.fixture(scope="module")
def metric(tmp_path_factory):
    """The profile from the metric poses, every ``every``-th (one calibrate per ``every``)."""
    done = {}

    def of(every: int) -> dict:
        if every not in done:
            tmp = tmp_path_factory.mktemp(f"metric{every}")
            done[every] = calibrate(tmp / "out", "--groundtruth",
                                    str(write_reference(tmp / "vo.tum", world_deg=100.0, every=every)))
        return done[every]
    return of


@pytest.mark.parametrize("every,drift", [(10, 0.0), (10, 0.3), (1, 0.3)])
def test_a_monocular_scale_leaves_the_accelerometers_matrix_at_its_prior(tmp_path, metric, every, drift):
    """A monocular VO (a constant or a drifting scale; at 20 Hz, and at 200 Hz, where the velocity resolves
    accelerations): the scale calibrate estimates from this accelerometer and applies is a few per cent off,
    and the accelerometer's scales would take that error up, with the bias along the thrust axis (before, every
    term fitted at 20 Hz: acc x bias -0.10 and -0.55 m/s^2 against the metric poses' -0.01). The matrix is not
    observed (the identity, said so), the bias is the metric poses'."""
    ref = monocular(write_reference(tmp_path / "vo.tum", world_deg=100.0, every=every), drift)
    p = calibrate(tmp_path / "out", "--groundtruth", str(ref), "--no-select")
    assert p["reference"]["applied"]["scale"]
    assert np.array_equal(p["accelerometer"]["matrix"], np.eye(3))
    seen = p["observed"]["accelerometer.matrix"]
    assert not seen["observed"] and "scale was estimated from this accelerometer" in seen["why"]
    m = metric(every)
    a, ma = np.asarray(p["accelerometer"]["bias"]), np.asarray(m["accelerometer"]["bias"])
    assert np.array_equal(m["accelerometer"]["matrix"], np.eye(3))  # the metric poses' level: bias
    assert np.all(np.abs(a - ma) < 0.01), (a, ma)
    if drift and every > 1:  # the default (terms selected): the accelerometer's levels end at its bias
        p = calibrate(tmp_path / "selected", "--groundtruth", str(ref))
        assert p["selection"]["levels"]["acc"] == ["offset", "bias"]


def test_select_chooses_the_accelerometers_level_on_the_positions_of_each_recording_held_out(tmp_path):
    """`--select` with a 20 Hz reference on two crops: the accelerometer's level is chosen on the
    positions (each crop held out in turn, its residual per world axis recorded), the floor's matrix and
    bias are the positions' fit at that level (nothing outside it fitted), and the profile's reference
    entry is that fit."""
    from crops import CROP
    from imu_learn.calib.select import free_indices

    args = []
    for name in (EASY, CROP):
        _, gt = read_recording(SHIPPED / name)
        rows = np.column_stack([gt.t_ns * 1e-9, gt.p, wxyz_to_xyzw(gt.q_wxyz)])[::10]
        ref = tmp_path / f"{Path(name).name}.tum"
        np.savetxt(ref, rows, fmt="%.9f")
        args += ["--input", str(SHIPPED / name), "--groundtruth", str(ref)]
    out = tmp_path / "out"
    assert main(["calibrate", *args, "--out", str(out), "--no-plot", "--quiet", "--select"]) == 0
    p = json.loads((out / "profile.json").read_text())
    sel = p["selection"]
    assert sel["acc"] in POSITION_ACC_LEVELS and sel["levels"]["acc"] == list(POSITION_ACC_LEVELS)
    figs = sel["held_out_figures"]["acc"]
    assert set(figs) == set(POSITION_ACC_LEVELS) and all(len(figs[lv]) == 2 for lv in figs)
    m_a, fit = np.asarray(p["floor"]["M_a"]), p["reference"]["accelerometer_from_positions"]
    theta = np.r_[(m_a - np.eye(3)).ravel(), p["floor"]["b_a"]]
    fixed = np.setdiff1d(np.arange(12), free_indices("acc", sel["acc"]))
    assert np.all(theta[fixed] == 0.0)
    assert np.allclose(fit["M_a"], m_a) and np.allclose(fit["b_a"], p["floor"]["b_a"])


def test_another_recordings_reference_is_refused_before_any_fit(tmp_path, capsys):
    other = SHIPPED / "euroc/MH_04_difficult/mav0/state_groundtruth_estimate0/data.csv"
    _, gt = read_recording(SHIPPED / "euroc/MH_04_difficult", groundtruth=other)
    imu, _ = read_recording(REC)
    t = gt.t_ns - gt.t_ns[0] + imu.t_ns[0]  # on the crop's clock: the same span, another flight
    ref = tmp_path / "other.tum"
    np.savetxt(ref, np.column_stack([t * 1e-9, gt.p, wxyz_to_xyzw(gt.q_wxyz)]), fmt="%.9f")
    code = main(["calibrate", "--input", str(REC), "--groundtruth", str(ref), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "ReferenceFrameError" in err and "does not follow the IMU" in err
    assert len(err.strip().splitlines()) == 1 or "fitting the floor" not in err
    assert not (tmp_path / "out" / "profile.json").exists()


def test_references_on_different_clocks_are_refused_naming_each_lag(tmp_path, capsys):
    """One lag is applied to every recording of a run: two crops whose references disagree by 0.1 s
    (one on another clock) are refused before any fit, each recording's lag named, nothing written."""
    from crops import CROP

    args = []
    for name, late in ((EASY, 0.0), (CROP, 0.1)):
        _, gt = read_recording(SHIPPED / name)
        ref = tmp_path / f"{Path(name).name}.tum"
        np.savetxt(ref, np.column_stack([gt.t_ns * 1e-9 + late, gt.p, wxyz_to_xyzw(gt.q_wxyz)]), fmt="%.9f")
        args += ["--input", str(SHIPPED / name), "--groundtruth", str(ref)]
    out = tmp_path / "out"
    assert main(["calibrate", *args, "--out", str(out), "--no-plot", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "lags behind their IMUs disagree" in err and "+100 ms" in err and "+0 ms" in err, err
    assert not (out / "profile.json").exists()


@pytest.mark.parametrize("factor, unit", [(100.0, "centimetres"), (1000.0, "millimetres")])
def test_positions_in_cm_or_mm_are_refused_naming_the_unit(tmp_path, capsys, factor, unit):
    ref = write_reference(tmp_path / "ref.tum", rotate=False)
    rows = np.loadtxt(ref)
    rows[:, 1:4] *= factor
    np.savetxt(ref, rows, fmt="%.9f")
    code = main(["calibrate", "--input", str(REC), "--groundtruth", str(ref), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and f"positions in {unit}? give them in metres" in err
    assert f"x{factor:.4g}"[:3] in err  # the factor it read, e.g. x101.6 or x1016
    assert not (tmp_path / "out" / "profile.json").exists()


def test_navigate_turns_the_reference_poses_by_the_profiles_rotation(tmp_path, capsys):
    """A VIO's camera poses calibrated against, then navigated with the profile: the rotation calibrate
    estimated turns them into the IMU frame (your-device.md's step 4 was refused before, naming
    --extrinsics, although the profile held the rotation); without the profile they are refused."""
    ref = write_reference(tmp_path / "camera.tum", world_deg=100.0, every=10)
    p = calibrate(tmp_path / "cal", "--groundtruth", str(ref), "--no-select")
    assert p["reference"]["applied"]["rotation"]
    nav = ["navigate", "--input", str(REC), "--aiding", str(ref), "--aiding-kind", "pose", "--quiet"]
    capsys.readouterr()
    assert main(nav + ["--out", str(tmp_path / "without")]) == 2
    assert "--extrinsics" in capsys.readouterr().err
    assert main(nav + ["--profile", str(tmp_path / "cal" / "profile.json"), "--out", str(tmp_path / "nav")]) == 0
    err = capsys.readouterr().err
    assert "moved into the IMU frame by --profile's reference" in err
    turned = re.search(r"rotation ([0-9.]+) deg", err)
    assert turned and float(turned.group(1)) == pytest.approx(R_TRUE_DEG, abs=0.1), err  # the rotation put in
    # the reference's origin is the IMU's here: the accelerometer's estimate of it (used where it is tight) near 0
    origin = re.search(r"origin \(([^)]*)\)", err)
    assert origin and all(abs(float(x)) < 2.0 for x in origin.group(1).split(",")), err  # [cm]
    s = json.loads((tmp_path / "nav" / "summary.json").read_text())
    check = s["aiding_estimates"]["frame_check"]
    assert check["verdict"] == "same frame" and check["rotation_deg"] < 0.5, check


def test_the_profiles_reference_gives_navigate_its_extrinsic_and_origin():
    """profile.json's reference entry read back as T_BS: the rotation calibrate applied, the origin from the applied
    lever arm, else from the accelerometer's fit against the positions where within 2 cm, else zero; nothing where
    no rotation was applied."""
    from imu_learn.calib.reference import applied_extrinsic

    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    base = {"rotation_imu_from_reference": R.tolist(), "rotation_deg": 90.0, "lever_arm_m": [0.1, 0.2, 0.3],
            "applied": {"rotation": True, "lever_arm": True},
            "accelerometer_from_positions": {"fit_lever": True, "lever_arm_m": [-0.01, -0.06, 0.003],
                                             "lever_arm_std_m": [0.004, 0.005, 0.006]}}
    T, deg, where = applied_extrinsic(base)
    assert np.array_equal(T[:3, :3], R) and np.allclose(T[:3, 3], [0.1, 0.2, 0.3]) and deg == 90.0
    assert np.array_equal(T[3], [0, 0, 0, 1]) and "10.0, 20.0, 30.0" in where
    T, _, where = applied_extrinsic({**base, "applied": {"rotation": True, "lever_arm": False}})
    assert np.allclose(T[:3, 3], [-0.01, -0.06, 0.003]) and "from the accelerometer" in where
    loose = {**base, "applied": {"rotation": True}, "accelerometer_from_positions": {
        "fit_lever": True, "lever_arm_m": [-0.01, -0.06, 0.003], "lever_arm_std_m": [0.004, 0.03, 0.006]}}
    T, _, where = applied_extrinsic(loose)
    assert np.array_equal(T[:3, 3], np.zeros(3)) and "not estimated" in where
    assert applied_extrinsic({**base, "applied": {"rotation": False, "lever_arm": True}}) is None
    assert applied_extrinsic({}) is None


def test_a_refused_positions_fit_leaves_the_accelerometers_matrix_exactly_at_its_prior(tmp_path, monkeypatch):
    """A 20 Hz reference whose positions cannot tell the accelerometer's scale: the bias-only floor holds
    the matrix at the identity by a prior; the profile writes the identity itself (not 1 - 3e-11) with
    no spread, as its "kept at the prior" says."""
    def refused(self, inp, fit, progress=lambda s: None, uncertainty=True):
        self.acc_refused = "the motion leaves the accelerometer's scale uncertain (a test)"
        return fit

    monkeypatch.setattr(PosesSource, "acc_from_positions", refused)
    ref = write_reference(tmp_path / "vo.tum", world_deg=100.0, every=10)
    p = calibrate(tmp_path / "out", "--groundtruth", str(ref))
    assert p["accelerometer"]["matrix"] == np.eye(3).tolist()
    assert all(v is None for row in p["accelerometer"]["matrix_std"] for v in row)
    assert not p["observed"]["accelerometer.matrix"]["observed"]
    assert "the matrix at its prior (identity)" in p["selection"]["acc"]


def test_the_gyros_misalignment_rotation_goes_with_an_estimated_frame(tmp_path):
    """A gyro whose axes are turned 0.8° (about x) off the IMU frame the ground truth is in (below the frame
    check's 1°, which it leaves to the floor): against the ground truth as given the floor's M_g undoes the
    turn; against the same poses in an unknown frame, the frame's rotation is estimated from the same rates
    and takes the turn with it (the estimate 0.8° off the true rotation, M_g without the turn): profile.json
    says the matrix was observed only in part."""
    import shutil

    from scipy.spatial.transform import Rotation

    rec = tmp_path / "MH_01_turned"
    shutil.copytree(REC, rec)
    imu = rec / "mav0" / "imu0" / "data.csv"
    head = imu.read_text().splitlines()[0]
    rows = np.loadtxt(imu, delimiter=",", comments="#")
    turn = Rotation.from_rotvec(np.radians([0.8, 0.0, 0.0])).as_matrix()
    rows[:, 1:4] = rows[:, 1:4] @ turn.T  # what the gyro reads: its axes turned
    np.savetxt(imu, rows, delimiter=",", header=head.lstrip("#"), comments="#",
               fmt=["%d"] + ["%.12g"] * 6)

    def run(out: Path, *extra: str) -> dict:
        code = main(["calibrate", "--input", str(rec), "--out", str(out), "--no-plot", "--quiet", "--no-select", *extra])
        assert code == 0
        return json.loads((out / "profile.json").read_text())

    def skew_deg(p: dict) -> np.ndarray:
        m = np.asarray(p["gyroscope"]["matrix"])
        k = (m - m.T) / 2
        return np.degrees([k[2, 1], k[0, 2], k[1, 0]])

    given = run(tmp_path / "given")
    assert not given["reference"]["applied"].get("rotation")
    assert skew_deg(given)[0] == pytest.approx(-0.8, abs=0.1)  # M_g undoes the turn
    assert "partly" not in given["observed"]["gyroscope.matrix"]
    ref = write_reference(tmp_path / "rotated.tum", world_deg=30.0)
    moved = run(tmp_path / "moved", "--groundtruth", str(ref))
    r = moved["reference"]
    est = Rotation.from_matrix(np.asarray(r["rotation_imu_from_reference"]))
    true = Rotation.from_quat(wxyz_to_xyzw(quat_axis_angle(R_TRUE_AXIS, R_TRUE_DEG)))
    assert math.degrees((est * true.inv()).magnitude()) == pytest.approx(0.8, abs=0.1)  # the turn is in the frame
    assert np.all(np.abs(skew_deg(moved)) < 0.1)  # and not in M_g
    assert "misalignment rotation" in moved["observed"]["gyroscope.matrix"]["partly"]
