"""One correction plan for refine and navigate (imu_learn.calib.correction): navigate's --checkpoint
gets refine's rate check (refused more than 5 % off, --force a warning line) and the guard; a model
that holds its profile's floor is not given it again; refine and navigate correct the same recording
into the same samples, bit for bit."""
from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest
import torch

from imu_learn import _imu_core as core
from imu_learn.calib import correction
from imu_learn.calib.profile import Profile
from imu_learn.cli import main
from imu_learn.data.formats import fetch
from imu_learn.infer.checkpoint import load_checkpoint, model_from_checkpoint, save_checkpoint
from imu_learn.infer.windowing import apply
from imu_learn.nn.model import ImuRefiner, ModelConfig

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
MODEL = REPO / "models" / "euroc_adis16448.pt"
PROFILE = REPO / "models" / "profiles" / "euroc_adis16448" / "profile.json"
EUROC = REPO / "datasets" / "euroc" / "MH_04_difficult"
IMU_REL = Path("mav0") / "imu0" / "data.csv"
GT_REL = Path("mav0") / "state_groundtruth_estimate0" / "data.csv"
NOISE = "1.7e-4,2e-3,1.9e-5,3e-3"


def fetch_crop(root: Path, n: int = 1200) -> Path:
    """A 100 Hz recording in the Fetch layout: the EuRoC crop's motion, every other sample."""
    t, g, a = core.read_asl_imu(str(EUROC / IMU_REL))
    t, g, a = t[: 2 * n : 2], g[: 2 * n : 2], a[: 2 * n : 2]
    f = root / IMU_REL
    f.parent.mkdir(parents=True)
    f.write_text("# timestamp, wx, wy, wz, ax, ay, az\n"
                 + "\n".join(fetch.format_row(int(float(t[k])), [*g[k], *a[k]]) for k in range(len(t))) + "\n")
    return root


def positions(path: Path) -> Path:
    rows = (EUROC / GT_REL).read_text().splitlines()[1::20]
    path.write_text("\n".join(f"{int(r.split(',')[0]) * 1e-9:.9f} {' '.join(r.split(',')[1:4])}" for r in rows) + "\n")
    return path


GIVEN_NOISE = (1.6968e-4, 2.0e-3, 1.9393e-5, 3.0e-3)  # --imu-noise: no fit from the (absent) aiding


def body_imu(rec: Path, **given):
    from imu_learn.fuse import navigate as nav

    return nav.read_body_imu(nav.Sources(rec, Path("unused.tum"), **given), nav.NavigateOptions(imu_noise=GIVEN_NOISE))


def refined(args, out: Path, capsys):
    rc = main(["refine", *map(str, args), "--out", str(out), "--device", "cpu", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 0, err
    _t, g, a = core.read_asl_imu(str(out / IMU_REL))
    return np.asarray(g), np.asarray(a), json.loads((out / "summary.json").read_text())


def test_navigate_with_a_model_for_another_rate_is_refused_and_forced_like_refine(tmp_path, capsys, caplog,
                                                                                   monkeypatch):
    pytest.importorskip("gtsam")
    from imu_learn.fuse import navigate as nav

    rec = fetch_crop(tmp_path / "fetch_rec")
    assert main(["refine", "--checkpoint", str(MODEL), "--input", str(rec), "--out", str(tmp_path / "r")]) == 2
    refused = capsys.readouterr().err.strip()
    monkeypatch.setattr(nav, "fuse_run", lambda *a, **k: pytest.fail("fused a recording the model is not for"))
    rc = main(["navigate", "--input", str(rec), "--aiding", str(positions(tmp_path / "fixes.tum")), "--aiding-kind",
               "position", "--imu-noise", NOISE, "--checkpoint", str(MODEL), "--out", str(tmp_path / "n"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.count("\n") == 0 and "100 Hz" in err and "200 Hz" in err, err
    assert err.split(": error: ", 1)[1] == refused.split(": error: ", 1)[1]
    # --force: the same warning lines (rate, then device), and the guard has its say too
    main(["refine", "--checkpoint", str(MODEL), "--input", str(rec), "--out", str(tmp_path / "r"), "--force", "--quiet"])
    warned = [ln.split(": warning: ", 1)[1] for ln in capsys.readouterr().err.splitlines() if ": warning: " in ln]
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="imu_learn"):
        imu = body_imu(rec, checkpoint=MODEL, force=True)
    plan_lines = [r for r in caplog.records if r.name == correction.__name__]
    # rate, device, and the guard (the shipped model carries its training statistics: Fetch's gyro is not EuRoC's)
    assert [r.getMessage() for r in plan_lines if r.levelno == logging.WARNING] == warned and len(warned) == 3
    assert "looks unlike model" in warned[2]
    assert imu.correction["guard"]["verdict"] == "unlike the training data"
    assert imu.correction["recording"]["device"] == "fetch"


def holding_checkpoints(tmp_path: Path):
    """Two checkpoints of one small model carrying the EuRoC profile: one whose model holds its floor
    (model.start = profile), one trained after it (start = raw)."""
    torch.manual_seed(0)
    model = ImuRefiner(ModelConfig(hidden=8, fc=8, layers=1, start="profile"))
    record = {"sample_rate_hz": 200.0, "device": "euroc", "profile": Profile.load(PROFILE).to_dict()}
    held, after = tmp_path / "held.pt", tmp_path / "after.pt"
    save_checkpoint(held, model, {"test": True}, 1, 1, None, record=record)
    model.cfg.start = "raw"
    save_checkpoint(after, model, {"test": True}, 1, 1, None, record=record)
    return model_from_checkpoint(load_checkpoint(held)), held, after


def test_a_model_holding_its_profile_is_not_given_the_floor_again(tmp_path, capsys):
    model, held, after = holding_checkpoints(tmp_path)
    t, g, a = (np.asarray(x) for x in core.read_asl_imu(str(EUROC / IMU_REL)))
    floor_g, floor_a = Profile.load(PROFILE).apply(t, g, a)
    once = apply(model, floor_g, floor_a)[:2]
    none = apply(model, g, a)[:2]
    assert np.abs(once[0] - none[0]).max() > 1e-4  # the floor makes a difference the test can see
    rec = correction.Recording(str(EUROC), t, g, a, "asl")
    for ck, expected, how in ((held, none, "in-model"), (after, once, "applied")):
        plan = correction.build(correction.Request(checkpoint=ck))
        fixed = correction.correct(plan, rec)
        np.testing.assert_array_equal(fixed.gyro, expected[0])
        np.testing.assert_array_equal(fixed.acc, expected[1])
        assert fixed.summary["model_profile"] == how
        # navigate, with the same profile given for its noise: the floor still once
        imu = body_imu(EUROC, checkpoint=ck, profile=PROFILE)
        np.testing.assert_array_equal(imu.gyro, expected[0])
        np.testing.assert_array_equal(imu.acc, expected[1])
        g_r, a_r, summary = refined(["--checkpoint", ck, "--input", EUROC], tmp_path / f"refined_{how}", capsys)
        np.testing.assert_array_equal(g_r, expected[0])
        assert ("held by the model" in " ".join(summary["applied"])) == (how == "in-model")


@pytest.mark.parametrize("given", ["profile", "checkpoint"])
def test_refine_and_navigate_correct_a_recording_into_the_same_samples(given, tmp_path, capsys):
    path = PROFILE if given == "profile" else MODEL
    g_r, a_r, summary = refined([f"--{given}", path, "--input", EUROC], tmp_path / "refined", capsys)
    imu = body_imu(EUROC, **{given: path})
    assert g_r.tobytes() == imu.gyro.tobytes() and a_r.tobytes() == imu.acc.tobytes()
    _t, g, _a = core.read_asl_imu(str(EUROC / IMU_REL))
    assert np.abs(g_r - np.asarray(g)).max() > 1e-5  # something was applied
    assert imu.correction["applied"] == summary["applied"] and imu.correction["guard"]["verdict"] == summary["guard"]["verdict"]


def test_navigate_applies_the_model_in_the_imus_own_frame_then_the_mounting(tmp_path):
    """With --imu-rotation-rpy-deg the model sees the IMU as it was trained on it (its own axes); the
    samples and a covariance head's variances are then turned into the body frame."""
    from imu_learn.data.formats.gnss_imu import mounting_rotation
    from imu_learn.fuse import navigate as nav

    cov = REPO / "models" / "euroc_adis16448_cov.pt"
    plain = body_imu(EUROC, checkpoint=cov)
    opts = nav.NavigateOptions(imu_rotation_rpy_deg=(-90.0, 0.0, 0.0), imu_noise=GIVEN_NOISE)  # y up: an axis permutation with a flip
    turned = nav.read_body_imu(nav.Sources(EUROC, Path("unused.tum"), checkpoint=cov), opts)
    M = mounting_rotation((-90.0, 0.0, 0.0))
    np.testing.assert_array_equal(turned.gyro, np.ascontiguousarray(plain.gyro @ M.T))
    np.testing.assert_array_equal(turned.acc, np.ascontiguousarray(plain.acc @ M.T))
    order = np.abs(np.round(M)).argmax(1)  # body axis i is IMU axis order[i]
    np.testing.assert_allclose(turned.var, np.hstack([plain.var[:, order], plain.var[:, 3 + order]]), rtol=1e-12)
    assert plain.var is not None and not np.allclose(plain.var[:, order], plain.var[:, :3])
