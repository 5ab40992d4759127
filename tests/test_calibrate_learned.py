"""A refiner trained on top of a device profile: ``imu-learn fit --model.start PATH/profile.json`` and
``imu-learn calibrate --learned``.

- Untrained, the model is the profile's floor: its fixed calibration and FIR shift are the
  profile's, the learned part is zero. On the MH_04 crop with uniform stamps it equals
  :meth:`Profile.apply` to float32 precision (the model runs in float32: 5e-7 rad/s, 5e-6 m/s^2 for
  accelerations up to 14 m/s^2); with the crop's own stamps (periods of 4999936 and 5000192 ns) to
  2e-5 rad/s and 5e-4 m/s^2, since the model shifts by samples and the profile by time.
- Only the network's residual on top of the floor is regularised (the start's regulariser is 0).
- The floor is applied once: the checkpoint carries the profile, and ``refine --checkpoint`` gives
  the model's own output on the raw input (not the model after the profile's floor).
- ``calibrate --learned`` end to end on the MH_01 crop (slow: the floor's fit dominates).
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from floors import set_floor
from imu_learn import _imu_core as core
from imu_learn.calib.profile import Affine, Profile
from imu_learn.cli import fit as fit_cli
from imu_learn.cli import main
from imu_learn.cli.refine import main as refine_main
from imu_learn.data.types import Segment
from imu_learn.infer.checkpoint import imu_record, load_checkpoint, load_model
from imu_learn.infer.refiner import refine_arrays
from imu_learn.infer.windowing import Windowing, attach
from imu_learn.train import trainer
from imu_learn.train.config import build_config

REPO = Path(__file__).resolve().parent.parent
MH01 = REPO / "datasets" / "euroc" / "MH_01_easy"
MH04 = REPO / "datasets" / "euroc" / "MH_04_difficult"
IMU_REL = Path("mav0") / "imu0" / "data.csv"
TINY = ["--quiet", "--data.window", "50", "--data.batch_size", "8", "--data.val_stride", "200",
        "--data.eval_stride", "50", "--model.hidden", "8", "--model.fc", "8", "--model.layers", "1",
        "--optim.steps_per_epoch", "4", "--seed", "7", "--threads", "1"]


def profile_file(tmp_path: Path, time_offset: float = 0.54, cutoffs=(None, None)) -> Path:
    """A profile with set floor parameters (a rotation-sized misalignment, biases, g-sensitivity)."""
    m = set_floor(cutoffs, time_offset)
    p = m.params
    fl = m.to_dict()
    prof = Profile(device="my-imu", sample_rate_hz=200.0, time_offset_s=time_offset / 200.0, time_offset_s_std=math.nan,
                   gyro=Affine(p.M_g, p.b_g, "rad/s"), acc=Affine(p.M_a, p.b_a, "m/s^2"), g_sensitivity=p.G,
                   gravity_mps2=9.81, gravity_mps2_std=math.nan, floor=fl)
    path = tmp_path / "profile.json"
    prof.save(path)
    return path


def crop_imu():
    return core.read_asl_imu(str(MH04 / IMU_REL))


def untrained(path: Path, window: int = 200, refine: str = "imu"):
    cfg = build_config({}, {"model.start": str(path), "model.hidden": 8, "model.fc": 8, "model.layers": 1,
                            "data.window": window, "model.refine": refine})
    cfg, start = trainer.profile_start(cfg)
    t, g, a = crop_imu()
    seg = Segment("x", t, g, a, np.zeros_like(g), np.zeros_like(g), np.tile([1.0, 0, 0, 0], (len(t), 1)))
    model = trainer.new_state(cfg, [seg], torch.device("cpu"), start).model.eval()
    attach(model, Windowing.for_training_window(window))
    return cfg, model, start.profile


@pytest.mark.parametrize("refine", ["imu", "gyro"])
def test_the_untrained_model_on_a_profile_is_its_floor(tmp_path, refine):
    """A model refining the gyro alone (TUM-VI's config) holds the whole floor too: it passed the raw
    accelerometer through, dropping the profile's (epoch 0 1.078x the floor in translation)."""
    path = profile_file(tmp_path)
    cfg, model, prof = untrained(path, refine=refine)
    assert (cfg.model.start, cfg.model.fir_taps, cfg.model.fir_init_tau, cfg.model.calib) == ("profile", 3, 0.54, True)
    assert prof == Profile.load(path).to_dict()
    t, g, a = crop_imu()
    mg, ma = refine_arrays(model, g, a)
    uniform = t[0] + np.arange(len(t), dtype=np.int64) * 5_000_000
    fg, fa = Profile.load(path).apply(uniform, g, a)
    np.testing.assert_allclose(mg, fg, rtol=0, atol=5e-7)  # float32
    np.testing.assert_allclose(ma, fa, rtol=0, atol=5e-6)
    fg, fa = Profile.load(path).apply(t, g, a)  # the crop's own stamps: the profile shifts by time
    np.testing.assert_allclose(mg, fg, rtol=0, atol=2e-5)
    np.testing.assert_allclose(ma, fa, rtol=0, atol=5e-4)
    assert np.abs(mg - g).max() > 1e-3  # the floor did something


def test_the_untrained_model_holds_the_profiles_low_pass_too(tmp_path):
    """A profile with calibrate's usual acc low-pass (20 Hz at 200 Hz): the FIR holds the shift and the
    filter (53 taps: below 1e-5 of its response left out); equal to Profile.apply away from the recording's
    ends (the zero-phase filter pads them otherwise)."""
    path = profile_file(tmp_path, cutoffs=(None, 20.0))
    cfg, model, _ = untrained(path)
    assert cfg.model.fir_taps == 53
    t, g, a = crop_imu()
    mg, ma = refine_arrays(model, g, a)
    fg, fa = Profile.load(path).apply(t[0] + np.arange(len(t), dtype=np.int64) * 5_000_000, g, a)
    inner = slice(40, -40)
    np.testing.assert_allclose(mg[inner], fg[inner], rtol=0, atol=5e-7)
    np.testing.assert_allclose(ma[inner], fa[inner], rtol=0, atol=1e-4)  # the left-out tail: 1e-5 of 14 m/s^2
    (tmp_path / "nf").mkdir()
    _, no_filter = Profile.load(profile_file(tmp_path / "nf")).apply(t, g, a)
    assert np.abs(ma - no_filter)[inner].max() > 1e-2  # the filter is there


@pytest.mark.parametrize("more,expected", [
    (["--model.fir_taps", "3"], "needs model.fir_taps >= 7"),
    (["--model.start", "profile"], "name the device profile's file"),
    (["--model.start", "traditional"], "model.start: must be one of calibrate, raw, timing, traditional+timing or a device"),
])
def test_a_start_that_cannot_hold_the_floor_is_one_line(tmp_path, capsys, more, expected):
    path = profile_file(tmp_path, time_offset=2.4)
    argv = ["--out", str(tmp_path / "run"), *TINY, "--optim.epochs", "1", "--model.start", str(path), *more]
    assert fit_cli.main(argv) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1


def test_refine_applies_a_profile_started_model_once(tmp_path, capsys):
    """fit --model.start PATH: the checkpoint carries the profile and says the model holds it;
    refine --checkpoint gives the model's own output on the raw input, bit for bit in the ASL file."""
    path = profile_file(tmp_path)
    run = tmp_path / "run"
    assert fit_cli.main(["--out", str(run), *TINY, "--optim.epochs", "1", "--optim.lr", "1e-2",
                         "--model.start", str(path), "--optim.validate_start", "true"]) == 0
    with open(run / "metrics.csv") as f:
        epoch0 = next(csv.DictReader(f))
    assert float(epoch0["val_reg"]) == 0.0  # the regulariser sees the network's residual, not the floor's correction
    state = load_checkpoint(run / "best.pt")
    rec = imu_record(state)
    assert rec["profile_in_model"] and rec["device"] == "my-imu"
    assert Profile.from_dict(rec["profile"]).to_dict() == Profile.load(path).to_dict()
    assert state["model_args"]["start"] == "profile" and state["config"]["model"]["start"] == "profile"
    _, model0, _ = untrained(path, window=50)
    assert torch.equal(state["model"]["fir.weight"], model0.fir.weight.detach())  # the floor's FIR stays fixed
    capsys.readouterr()
    out = tmp_path / "refined"
    assert refine_main(["--checkpoint", str(run / "best.pt"), "--input", str(MH04), "--out", str(out),
                        "--format", "euroc", "--force", "--quiet"]) == 0
    assert "held by the model" in capsys.readouterr().out
    t, g, a = crop_imu()
    t2, g2, a2 = core.read_asl_imu(str(out / IMU_REL))
    model = load_model(run / "best.pt")
    want_g, want_a = refine_arrays(model, g, a)
    assert np.array_equal(t2, t) and np.array_equal(g2, want_g) and np.array_equal(a2, want_a)
    twice_g, _ = refine_arrays(model, *Profile.load(path).apply(t, g, a))
    assert np.abs(twice_g - want_g).max() > 1e-3  # what applying the floor twice would have given


def test_learned_options_are_refused_before_any_work(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for argv, expected in ((["--input", MH01, "--learned-epochs", "2"], "add --learned"),
                           (["--input", MH01, "--imu-only", "--learned"], "--learned needs a reference trajectory")):
        assert main(["calibrate", *map(str, argv), "--out", "x", "--quiet"]) == 2
        err = capsys.readouterr().err
        assert expected in err and err.count("\n") == 1
        assert not (tmp_path / "x").exists()


@pytest.mark.slow  # the floor's fit, five times (a minute or more on a loaded machine)
def test_calibrate_learned_end_to_end(tmp_path, capsys):
    """calibrate --learned on the MH_01 crop, 1 epoch of a tiny refiner: the profile, the run folder,
    the model file named by the verdict (carrying the profile), learned.json and the one line."""
    out = tmp_path / "cal"
    rc = main(["calibrate", "--input", str(MH01), "--out", str(out), "--no-plot", "--quiet", "--learned",
               "--learned-epochs", "1", "--seed", "3"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    line = [x for x in cap.out.splitlines() if x.startswith("learned refiner:")]
    assert len(line) == 1
    verdict = json.loads((out / "learned.json").read_text())
    name = "model.pt" if verdict["beats_floor"] else "model.not_shipped.pt"
    assert (out / name).is_file() and not (out / ({"model.pt", "model.not_shipped.pt"} - {name}).pop()).exists()
    assert ("does NOT beat" in line[0]) != verdict["beats_floor"]
    for f in ("config.toml", "split.json", "metrics.csv", "best.pt", "last.pt"):
        assert (out / "fit" / f).is_file(), f
    state = load_checkpoint(out / name)
    assert imu_record(state)["profile_in_model"]
    assert Profile.from_dict(state["profile"]).to_dict() == Profile.load(out / "profile.json").to_dict()
    assert {c["protocol"] for c in verdict["cells"]} == {"open loop", "start-up bias removed"}
    assert state["config"]["optim"]["epochs"] == 1 and state["config"]["seed"] == 3


def test_the_run_config_of_input_recordings_is_one_fit_can_read_back():
    """calibrate --learned's run config names each --input's format as fit reads it: an ASL folder was
    written as format "asl", which `imu-learn fit --resume OUT/fit` refused ("format 'asl' unknown")."""
    import argparse
    from types import SimpleNamespace

    from imu_learn.cli.calibrate import learned_base
    from imu_learn.data.splits import find_all

    args = argparse.Namespace(data_root=None, config=None, groundtruth=None, input=[MH01], val_fraction=0.15,
                              format="auto")
    cfg = learned_base(args, SimpleNamespace(sources=[{"max_gap_s": 0.05}]))
    assert [r.format for r in cfg.data.roots] == ["euroc"]
    assert list(find_all(cfg.data.roots)) == ["MH_01_easy"]


def test_a_model_calibrate_did_not_ship_is_named_when_applied(tmp_path, capsys, caplog):
    """calibrate --learned keeps a model that lost to its profile as model.not_shipped.pt; refine (and
    navigate, evaluate: one correction plan) applied it without a word."""
    import shutil

    ckpt = tmp_path / "model.not_shipped.pt"
    shutil.copy(REPO / "models" / "euroc_adis16448.pt", ckpt)
    assert refine_main(["--checkpoint", str(ckpt), "--input", str(MH04), "--out", str(tmp_path / "out"),
                        "--format", "euroc"]) == 0
    err = capsys.readouterr().err
    assert "did not beat its profile on validation" in err and "--profile profile.json" in err
    import logging

    from imu_learn.eval.run import CheckpointRefiner

    with caplog.at_level(logging.WARNING, logger="imu_learn.eval.run"):
        CheckpointRefiner(ckpt)  # evaluate's --checkpoint says it too
    assert "did not beat its profile on validation" in caplog.text
    shutil.copy(ckpt, tmp_path / "model.pt")
    assert refine_main(["--checkpoint", str(tmp_path / "model.pt"), "--input", str(MH04), "--out",
                        str(tmp_path / "out2"), "--format", "euroc"]) == 0
    assert "did not beat" not in capsys.readouterr().err
