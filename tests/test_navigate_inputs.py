"""``imu-learn navigate`` checks its side files before fusing: a positions-only ``--groundtruth`` is
refused first (exit 2, one line), with no track written (imu_learn.fuse.navigate.check_inputs)."""
from __future__ import annotations

import logging
import shutil
from pathlib import Path

import pytest

from crops import CROP, SHIPPED
from imu_learn.cli import main
from imu_learn.errors import ConfigError
from imu_learn.fuse import navigate as nav

GT_REL = Path("mav0") / "state_groundtruth_estimate0" / "data.csv"


def test_positions_only_groundtruth_is_refused_before_fusion(tmp_path, capsys, monkeypatch):
    rec = tmp_path / "MH_04_difficult"
    shutil.copytree(SHIPPED / CROP / "mav0" / "imu0", rec / "mav0" / "imu0")
    rows = (SHIPPED / CROP / GT_REL).read_text().splitlines()[1::20]
    aiding = tmp_path / "fixes.tum"
    gt = tmp_path / "positions.tum"
    lines = [f"{int(r.split(',')[0]) * 1e-9:.9f} {' '.join(r.split(',')[1:4])}" for r in rows]
    aiding.write_text("\n".join(lines) + "\n")
    gt.write_text("\n".join(lines) + "\n")  # 4 columns: positions only

    from imu_learn.fuse import navigate as nav

    def no_fusion(*a, **k):
        raise AssertionError("fusion ran before the ground truth was checked")

    monkeypatch.setattr(nav, "fuse_run", no_fusion)
    out = tmp_path / "out"
    rc = main(["navigate", "--input", str(rec), "--aiding", str(aiding), "--aiding-kind", "position",
               "--groundtruth", str(gt), "--out", str(out), "--quiet", "--imu-noise", "1.7e-4,2e-3,1.9e-5,3e-3"])
    err = capsys.readouterr().err
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "--groundtruth" in lines[0] and "positions-only" in lines[0], err
    assert not out.exists() or not any(out.iterdir())


def test_a_positions_profile_gives_its_mounting_delay_and_lever_arm_unless_the_options_do(tmp_path, caplog):
    """A profile that calibrate fitted against positions carries the mounting, delay and lever arm it used
    or estimated (reference.navigator); navigate takes them where the options are absent (one line says so)
    and the options win where given. Without them a car's profile ran unmounted: gap ends up to 131 m."""
    import logging

    import numpy as np

    from imu_learn.calib.profile import Profile
    from imu_learn.cli.navigate import options, parser

    prof = Profile.load(SHIPPED.parent / "models" / "profiles" / "euroc_adis16448" / "profile.json")
    prof.reference = {"kind": "positions", "navigator": {"imu_rotation_rpy_deg": [1.0, -6.8, -174.3],
                                                          "imu_delay_s": -0.179, "lever_arm_m": [0.1, 0.0, 0.9]}}
    path = tmp_path / "profile.json"
    prof.save(path)
    base = ["--input", "imu.csv", "--aiding", "fix.pos", "--profile", str(path)]
    with caplog.at_level(logging.INFO):
        o = options(parser().parse_args(base))
    assert np.allclose(o.imu_rotation_rpy_deg, (1.0, -6.8, -174.3)) and o.imu_delay_s == -0.179 and o.imu_delay_from == "profile"
    assert np.allclose(o.lever_arm, (0.1, 0.0, 0.9))
    assert "taken from" in caplog.text and "--imu-rotation-rpy-deg 1,-6.8,-174.3" in caplog.text
    given = options(parser().parse_args(base + ["--imu-rotation-rpy-deg", "180,0,0", "--imu-delay-s", "0",
                                                "--lever-arm", "0,0,0"]))
    assert given.imu_rotation_rpy_deg == (180.0, 0.0, 0.0) and given.imu_delay_s == 0.0 and given.lever_arm == (0, 0, 0)
    poses = options(parser().parse_args(base + ["--aiding-kind", "relative-pose"]))
    assert poses.lever_arm is None and poses.imu_delay_s == -0.179  # a lever arm is the antenna's


def test_implausible_fused_biases_are_named():
    """The smoother's last biases beyond a MEMS IMU's (calibrate's limits): one warning naming the usual
    causes, in the summary too; within them nothing."""
    from imu_learn.fuse.navigate import final_bias_check

    assert final_bias_check([0.001, -0.02, 0.08, 0.1, -0.2, 0.15]) == {
        "plausible": True, "limits": {"gyro_rad_s": 0.1, "acc_mps2": 1.0}}
    bad = final_bias_check([0.0, 0.0, 0.0, -0.33, 3.39, -0.7])
    assert not bad["plausible"] and "acc bias +3.39 m/s^2 on y" in bad["why"] and "--lever-arm" in bad["why"]


def test_gaps_outside_the_recording_are_refused():
    """A --gaps window wholly outside the recording would drop nothing: refused in one line; one that
    overlaps it is kept."""
    import pytest

    from imu_learn.errors import ConfigError
    from imu_learn.fuse.navigate import OutageWindow, check_gaps

    check_gaps((OutageWindow(120.0, 30.0), OutageWindow(-5.0, 10.0)), 134.0)
    for bad in (OutageWindow(500.0, 10.0), OutageWindow(-5.0, 3.0)):
        with pytest.raises(ConfigError, match="lies outside the recording"):
            check_gaps((bad,), 134.0)


def test_a_lever_arm_of_metres_is_named_before_the_fusion(tmp_path, capsys, monkeypatch):
    """--lever-arm 0,-5,0 (cm typed as m): one warning before the first sample is fused."""
    rec = tmp_path / "MH_04_difficult"
    shutil.copytree(SHIPPED / CROP / "mav0" / "imu0", rec / "mav0" / "imu0")
    rows = (SHIPPED / CROP / GT_REL).read_text().splitlines()[1::20]
    aiding = tmp_path / "fixes.tum"
    aiding.write_text("\n".join(f"{int(r.split(',')[0]) * 1e-9:.9f} {' '.join(r.split(',')[1:4])}" for r in rows) + "\n")
    from imu_learn.fuse import navigate as nav

    class Fused(Exception):
        pass

    def stop(*a, **k):
        raise Fused

    monkeypatch.setattr(nav, "fuse_run", stop)
    args = ["navigate", "--input", str(rec), "--aiding", str(aiding), "--aiding-kind", "position", "--out",
            str(tmp_path / "out"), "--imu-noise", "1.7e-4,2e-3,1.9e-5,3e-3"]
    for lever, warned in (("0,-5,0", True), ("0,-0.05,0", False)):
        try:
            main(args + ["--lever-arm", lever])
        except Fused:
            pass
        err = capsys.readouterr().err
        assert ("lever arm is 5 m long" in err) == warned, err


def test_gaps_and_keyframe_rates_a_user_can_get_wrong(caplog):
    """A negative --gaps start was accepted (the first seconds dropped without a word); overlapping windows
    and one running past the end pass with a warning."""
    with pytest.raises(ConfigError, match="START must be at least 0"):
        nav.parse_gaps("-5:10")
    with pytest.raises(ConfigError, match="DURATION above 0"):
        nav.parse_gaps("5:0")
    with caplog.at_level(logging.WARNING):
        assert nav.parse_gaps("30:10,35:10") == ((30.0, 10.0), (35.0, 10.0))
        nav.check_gaps(((95.0, 20.0),), 101.6)
    text = caplog.text
    assert "overlap" in text and "runs past the recording's end" in text


def test_an_aiding_file_too_short_to_start_from_is_named(tmp_path, capsys):
    """Four camera poses (0.15 s) inside the IMU's span failed at the start ('gravity from aiding: the aiding
    spans 0.10 s'), after warnings and without the file's name."""
    rec = SHIPPED / CROP
    t0 = int((rec / "mav0" / "imu0" / "data.csv").read_text().splitlines()[1].split(",")[0])
    short = tmp_path / "short.tum"
    short.write_text("".join(f"{(t0 + 5_000_000_000 + k * 50_000_000) * 1e-9:.6f} 0 0 0 0 0 0 1\n" for k in range(4)))
    rc = main(["navigate", "--input", str(rec), "--aiding", str(short), "--aiding-kind", "pose", "--quiet",
               "--out", str(tmp_path / "out")])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == 2 and len(err) == 1, err
    assert f"--aiding {short}: 4 row(s) over 0.15 s inside the IMU's span" in err[0]
