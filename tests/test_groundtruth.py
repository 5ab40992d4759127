"""The ground-truth check (imu_learn.eval.groundtruth, ``imu-learn groundtruth``): its fits on
synthetic recordings with a known answer, and the command on the shipped crops.

The IMU is the exact, instantaneous angular rate (point samples at their stamps, plus a bias and a
little noise) of a closed-form wobbling rotation; the ground truth is the same motion seen from a
body frame rotated by R_off and stamped τ late: q_gt(t) = q_imu(t − τ) ⊗ q_off, so ω_imu = R_off ω_gt.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imu_learn.cli.groundtruth import main as groundtruth_main
from imu_learn.data.synthetic import G, axis_angle, qconj, qmul, rotate, stamps
from imu_learn.data.types import GroundTruth, ImuData, Segment
from imu_learn.errors import ImuError, TooShortError
from imu_learn.eval import groundtruth as gr

REPO = Path(__file__).resolve().parent.parent
EUROC = REPO / "datasets" / "euroc"

BIAS = np.array([0.01, -0.02, 0.03])
OFF_AXIS, OFF_ANGLE = np.array([0.3, -1.0, 0.5]), np.radians(3.0)


def motion(t: np.ndarray) -> np.ndarray:
    """Orientation (w,x,y,z) at arbitrary times: yaw ramp plus wobbles about three axes."""
    return qmul(qmul(axis_angle([0.0, 0.0, 1.0], 0.5 * t + 0.4 * np.sin(1.7 * t)),
                     axis_angle([1.0, -1.0, 0.0], 0.3 * np.sin(2.3 * t + 0.4))),
                axis_angle([1.0, 1.0, 0.5], 0.25 * np.sin(3.1 * t + 1.0)))


def position(t: np.ndarray, deriv: int = 0) -> np.ndarray:
    """IMU position (or its derivatives) in the world: a slow Lissajous curve."""
    w = np.array([0.9, 1.3, 1.1])
    amp = np.array([1.0, 0.7, 0.3])
    return amp * w**deriv * np.sin(w * t[:, None] + deriv * np.pi / 2)


def body_rate(t: np.ndarray, eps: float = 1e-5) -> np.ndarray:
    """Instantaneous body angular rate by a central difference of the closed form."""
    d = qmul(qconj(motion(t - eps)), motion(t + eps))
    return 2 * d[:, 1:] * np.sign(d[:, :1]) / (2 * eps)


def recording(tau_s: float, lever=(0.0, 0.0, 0.0), seconds: float = 30.0, seed: int = 0) -> Segment:
    t_ns = stamps(seconds)
    t = (t_ns - t_ns[0]) * 1e-9
    q_off = axis_angle(OFF_AXIS, OFF_ANGLE)
    q_gt = qmul(motion(t - tau_s), np.broadcast_to(q_off, (len(t), 4)))
    rng = np.random.default_rng(seed)
    gyro = body_rate(t) + BIAS + 0.003 * rng.standard_normal((len(t), 3))
    q = motion(t)
    acc = rotate(qconj(q), position(t, 2) + np.array([0.0, 0.0, G]))
    p_gt = position(t - tau_s) - rotate(q_gt, np.broadcast_to(np.asarray(lever, dtype=float), (len(t), 3)))
    return Segment("synthetic", t_ns, gyro, acc, p_gt, np.zeros_like(p_gt), q_gt)


def rotation_matrix(q: np.ndarray) -> np.ndarray:
    return np.stack([rotate(q, e) for e in np.eye(3)], axis=1)


@pytest.mark.parametrize("tau_s", [0.0075, -0.0120, 0.0])
def test_fit_offset_recovers_rotation_time_offset_and_bias(tau_s):
    off = gr.fit_offset([recording(tau_s)])
    truth = rotation_matrix(axis_angle(OFF_AXIS, OFF_ANGLE))
    err_deg, _ = gr.angle_axis(off.r_off.T @ truth)
    assert err_deg < 0.02
    assert gr.angle_axis(off.r_off)[0] == pytest.approx(3.0, abs=0.02)
    assert off.tau_s == pytest.approx(tau_s, abs=3e-4)
    np.testing.assert_allclose(off.gyro_bias, BIAS, atol=5e-4)


def test_fit_offset_sees_no_offset_where_there_is_none():
    seq = recording(0.0)
    seq = Segment(seq.name, seq.t_ns, seq.gyro, seq.acc, seq.p, seq.v, motion((seq.t_ns - seq.t_ns[0]) * 1e-9))
    off = gr.fit_offset([seq])
    assert gr.angle_axis(off.r_off)[0] < 0.02
    assert abs(off.tau_s) < 3e-4


def test_fit_lever_arm_recovers_a_known_lever_arm():
    lever = np.array([0.05, -0.03, 0.02])
    seq = recording(0.0, lever=lever)
    # IMU rotated into the GT body frame, as check does with the fitted R_off
    r = rotation_matrix(axis_angle(OFF_AXIS, OFF_ANGLE))
    seq = Segment(seq.name, seq.t_ns, seq.gyro @ r, seq.acc @ r, seq.p, seq.v, seq.q_wxyz)
    est, se = gr.fit_lever_arm([seq], r.T @ BIAS)
    np.testing.assert_allclose(est, lever, atol=2e-3)
    assert np.all(se < 2e-3)


def test_check_of_a_synthetic_recording_names_its_frame_and_clock():
    seq = recording(0.0075)
    imu = ImuData(seq.t_ns, seq.gyro, seq.acc)
    gt = GroundTruth(seq.t_ns, seq.p, seq.q_wxyz)
    row, off = gr.check(imu, gt, "synthetic", "gt")
    assert row.off_deg == pytest.approx(3.0, abs=0.05)
    assert row.tau_ms == pytest.approx(7.5, abs=0.5)
    assert row.verdict.startswith("rotated 3.0° off the IMU, GT 7 ms late") or row.verdict.startswith("rotated 3.0° off the IMU, GT 8 ms late")
    assert row.after_rot[0] < row.n200[0]  # R_off applied: the rotation agrees better
    # the recommendation quotes (and ranks by) the figures after the rotation and lag, not before: a camera-frame VO
    # read 11.3 deg over 1 s beside "use", 0.22 deg once its 89 deg rotation was applied
    line = gr.summary_line("synthetic", [row], gr.pick_best([row])["synthetic"])
    assert f"rot {row.after_hold[0]:.3f}°" in line and "after its rotation and lag" in line
    assert f"{row.n200[0]:.3f}°" not in line and row.after_hold[0] < 0.5 * row.n200[0]


def test_the_summary_spans_200_imu_samples_not_200_reference_samples():
    """200 samples are the IMU's (the scores' horizons): 1 s at 200 Hz, whatever the reference's rate (a
    50 Hz reference was said to span 4 s)."""
    seq = recording(0.0)
    imu = ImuData(seq.t_ns, seq.gyro, seq.acc)
    rate = 1e9 / float(np.median(np.diff(seq.t_ns)))
    sub = slice(None, None, 4)
    row, _ = gr.check(imu, GroundTruth(seq.t_ns[sub], seq.p[sub], seq.q_wxyz[sub]), "synthetic", "gt")
    assert row.rate_hz == pytest.approx(rate / 4, rel=0.01)
    line = gr.summary_line("synthetic", [row], row)
    assert f"over 200 samples ({200 / rate:.2g} s)" in line, line


def test_a_reference_world_not_along_gravity_is_levelled_before_translation_and_lever_arm():
    # a VO/SLAM world: the same recording with its world turned 100° (gravity no longer along its z)
    lever = np.array([0.05, -0.03, 0.02])
    seq = recording(0.0, lever=lever)
    imu = ImuData(seq.t_ns, seq.gyro, seq.acc)
    level, _ = gr.check(imu, GroundTruth(seq.t_ns, seq.p, seq.q_wxyz), "synthetic", "gt")
    q_w = axis_angle([1.0, 0.4, 0.0], np.radians(100.0))
    turned = GroundTruth(seq.t_ns, rotate(np.broadcast_to(q_w, seq.q_wxyz.shape), seq.p),
                         qmul(np.broadcast_to(q_w, seq.q_wxyz.shape), seq.q_wxyz))
    row, _ = gr.check(imu, turned, "synthetic", "gt")
    assert level.world_tilt_deg < 0.5 and not level.levelled
    assert row.world_tilt_deg == pytest.approx(100.0, abs=0.5) and row.levelled
    assert row.verdict.endswith("its world tilted 100° from gravity")
    for a, b in ((row.n200, level.n200), (row.after_rot, level.after_rot), (row.after_hold, level.after_hold)):
        assert a[0] == pytest.approx(b[0], rel=1e-6)  # rotation: any world
        assert a[1] == pytest.approx(b[1], rel=0.02)  # translation: the levelled world's
    np.testing.assert_allclose(row.lever_cm, 100 * lever, atol=0.3)
    # without the levelling the translation over 1 s is gravity's (metres), as before
    assert gr.bias_removed_score(gr.segments(imu, turned, 0.05), 200)[1] > 10 * level.n200[1]


@pytest.mark.parametrize("gyro, says", [
    (lambda g: np.radians(g), "the reference's rates: deg/s read as rad/s"),  # rad/s data given --gyro-unit deg/s
    (lambda g: g * [1.0, 1.0, -1.0], "a gyro unit, a mirrored or swapped axis"),  # one axis's sign flipped
])
def test_rates_that_match_in_no_frame_are_the_verdict_not_a_frame(gyro, says):
    # calibrate refuses these; the check said "IMU frame" (a unit) or a rotation and a lever arm (a mirror)
    seq = recording(0.0)
    gt = GroundTruth(seq.t_ns, seq.p, seq.q_wxyz)
    good, _ = gr.check(ImuData(seq.t_ns, seq.gyro, seq.acc), gt, "synthetic", "gt")
    assert good.rates_match and not good.verdict.startswith("its rotation rates")
    row, _ = gr.check(ImuData(seq.t_ns, gyro(seq.gyro), seq.acc), gt, "synthetic", "gt")
    assert not row.rates_match
    assert row.verdict.startswith("its rotation rates do not match the IMU's in any frame") and says in row.verdict


def test_a_reference_late_beyond_the_fine_search_is_found_by_the_coarse_lag():
    # a VO 0.2 s late (a clock set by hand): the +-20-sample search read 403 ms and "rates match in no frame"
    seq = recording(0.0)
    imu = ImuData(seq.t_ns, seq.gyro, seq.acc)
    late = GroundTruth(seq.t_ns + 200_000_000, seq.p, seq.q_wxyz)
    row, off = gr.check(imu, late, "synthetic", "gt")
    assert row.rates_match and row.tau_ms == pytest.approx(200.0, abs=1.0) and off.tau_s == pytest.approx(0.2, abs=1e-3)
    assert "GT 200 ms late" in row.verdict
    early, _ = gr.check(imu, GroundTruth(seq.t_ns - 200_000_000, seq.p, seq.q_wxyz), "synthetic", "gt")
    assert "GT 200 ms early" in early.verdict  # not "GT -200 ms late"


def test_positions_in_another_unit_are_the_verdict():
    # positions in mm: the check said "IMU frame" and a lever arm of 127 m; calibrate and navigate refuse them
    seq = recording(0.0)
    imu = ImuData(seq.t_ns, seq.gyro, seq.acc)
    metric, _ = gr.check(imu, GroundTruth(seq.t_ns, seq.p, seq.q_wxyz), "synthetic", "gt")
    assert metric.scale == pytest.approx(1.0, abs=0.03) and not metric.scale_off
    mm, _ = gr.check(imu, GroundTruth(seq.t_ns, 1000.0 * seq.p, seq.q_wxyz), "synthetic", "gt")
    assert mm.scale_off and mm.scale == pytest.approx(1000.0, rel=0.03)
    assert mm.verdict.startswith("its positions are x") and "millimetres" in mm.verdict


def test_check_of_a_recording_shorter_than_one_window_is_a_typed_error():
    seq = recording(0.0, seconds=0.5)  # shorter than alignment's shortest segment
    with pytest.raises(ImuError):
        gr.check(ImuData(seq.t_ns, seq.gyro, seq.acc), GroundTruth(seq.t_ns, seq.p, seq.q_wxyz), "short", "gt")
    seq = recording(0.0, seconds=1.5)
    every2 = slice(None, None, 2)  # 100 Hz: 1.5 s aligns, but holds no window of 200 samples
    imu = ImuData(seq.t_ns[every2], seq.gyro[every2], seq.acc[every2])
    with pytest.raises(TooShortError, match="needs more than 200"):
        gr.check(imu, GroundTruth(seq.t_ns, seq.p, seq.q_wxyz), "short", "gt")


def test_command_on_a_crop_says_its_ground_truth_is_in_the_imu_frame(capsys):
    assert groundtruth_main(["--input", str(EUROC / "MH_04_difficult")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("MH_04_difficult / its own ground truth: reference at 200 Hz, 12001 IMU samples in 1 segment(s)")
    assert out[-2] == "  verdict: IMU frame"
    assert out[-1].startswith("MH_04_difficult: use its own ground truth (IMU frame; over 200 samples (1 s) rot")


def test_command_picks_the_ground_truth_that_agrees_best(capsys):
    rec = EUROC / "V1_01_easy"
    argv = ["--input", str(rec), "--groundtruth", str(rec / "groundtruth_pose.tum"),
            "--groundtruth", str(rec / "groundtruth_state_20hz.csv")]
    assert groundtruth_main(argv) == 0
    out = capsys.readouterr().out.splitlines()
    assert "  verdict: rotated 1.1° off the IMU" in out
    assert out[-1].startswith("V1_01_easy: use groundtruth_state_20hz.csv (IMU frame;")
    assert out[-1].endswith("others groundtruth_pose.tum: 0.310°")  # after its 1.1° rotation (0.486° before)


def test_command_errors_are_one_line(tmp_path, capsys):
    assert groundtruth_main(["--input", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("imu-learn groundtruth: error: FileNotFoundError:")


def test_command_refuses_when_no_ground_truth_matches_the_imu(tmp_path, capsys):
    """Another recording's ground truth on this one's clock: the rates match in no frame; the command said "use"
    it and exited 0. Now exit 2, one line naming the file and the causes; a matching file beside it is the one
    named even where the other scores lower."""
    rec = EUROC / "V1_01_easy"
    own = rec / "groundtruth_pose.tum"
    rows = np.loadtxt(own)
    wrong = np.column_stack([rows[:, 0], rows[::-1, 1:]])  # the motion played backwards on the same stamps
    path = tmp_path / "wrong.tum"
    np.savetxt(path, wrong, fmt="%.9f")
    assert groundtruth_main(["--input", str(rec), "--groundtruth", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("imu-learn groundtruth: error: ConfigError: V1_01_easy: no ground truth "
                                               f"matches its IMU: {path}: its rotation rates do not match"), err
    assert "quaternions in another order" in err[0]
    assert groundtruth_main(["--input", str(rec), "--groundtruth", str(path), "--groundtruth", str(own)]) == 0
    assert capsys.readouterr().out.splitlines()[-1].startswith("V1_01_easy: use groundtruth_pose.tum")


@pytest.mark.parametrize("text", ["1403715274.302143 0.1 0.2 0.3\n1403715274.312143 0.1 0.2 0.4\n",
                                  "t,x,y,z\n1403715274.302143,0.1,0.2,0.3\n"])
def test_a_positions_only_file_is_named_as_such(tmp_path, capsys, text):
    """A 4-column TUM or CSV (t x y z) ended in 'expected 8 columns, found 4' or a header error listing ASL's
    headers; it names what the file is and where positions go."""
    path = tmp_path / "positions.tum"
    path.write_text(text)
    assert groundtruth_main(["--input", str(EUROC / "MH_04_difficult"), "--groundtruth", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "positions only (t x y z)" in err[0] and "--aiding" in err[0], err
