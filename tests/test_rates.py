"""A model or profile is for the rate and device it was made from: what checkpoints record
(imu_learn.infer.checkpoint: new ones from the training data, old ones from their config), the
5 % rule (imu_learn.infer.rates), and ``imu-learn refine`` refusing a recording of another rate in
one line naming both rates (exit 2; ``--force`` proceeds with a warning) and warning for another
device."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from imu_learn import _imu_core as core
from imu_learn.calib.profile import Profile
from imu_learn.cli import fit as fit_cli
from imu_learn.cli.checkpoint import main as checkpoint_main
from imu_learn.cli.refine import main as refine_main
from imu_learn.data.formats import fetch
from imu_learn.data.types import Segment
from imu_learn.errors import InvalidInputError
from imu_learn.infer import rates
from imu_learn.infer.checkpoint import (
    describe,
    imu_record,
    load_checkpoint,
    save_checkpoint,
    strip_checkpoint,
    training_record,
)
from imu_learn.nn.model import ImuRefiner, ModelConfig

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
MODELS = REPO / "models"
EUROC = REPO / "datasets" / "euroc" / "MH_04_difficult"
TUMVI = REPO / "datasets" / "tum-vi" / "dataset-room2_512_16"
IMU_REL = Path("mav0") / "imu0" / "data.csv"

SHIPPED = {  # checkpoint: (rate from its config, device)
    "euroc_adis16448.pt": (200.0, "euroc"),
    "euroc_adis16448_cov.pt": (200.0, "euroc"),
    "euroc_adis16448_openloop.pt": (200.0, "euroc"),
    "tumvi_bmi160.pt": (200.0, "tum-vi"),
    "blackbird_clover.pt": (100.0, "blackbird"),
    "blackbird_clover_calibrated.pt": (100.0, "blackbird"),
    "fetch_debias.pt": (100.0, "fetch"),
    "broad_handheld.pt": (285.7, "broad"),
}


def fetch_crop(root: Path, every: int = 2, n: int = 1200) -> Path:
    """A 100 Hz recording in the Fetch layout: the EuRoC crop's motion, every other sample."""
    t, g, a = core.read_asl_imu(str(EUROC / IMU_REL))
    t, g, a = t[: n * every : every], g[: n * every : every], a[: n * every : every]
    f = root / IMU_REL
    f.parent.mkdir(parents=True)
    rows = [fetch.format_row(int(float(t[k])), [*g[k], *a[k]]) for k in range(len(t))]
    f.write_text("# timestamp, wx, wy, wz, ax, ay, az\n" + "\n".join(rows) + "\n")
    return root


def refine(args, capsys):
    rc = refine_main([str(x) for x in args])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


# ---- the rule ----------------------------------------------------------------------------------


def test_five_percent_both_ways_and_one_line_naming_both_rates():
    made = [rates.MadeFor("model m.pt", 200.0, "euroc")]
    assert rates.check("rec", 209.9, None, made) == []
    assert rates.check("rec", 190.1, None, made) == []
    for off in (210.1, 189.9, 100.0):
        with pytest.raises(InvalidInputError) as e:
            rates.check("rec", off, None, made)
        msg = str(e.value)
        assert "\n" not in msg and "200 Hz" in msg and rates.hz(off) in msg and "--force" in msg
    (line,) = rates.check("rec", 100.0, None, made, force=True)
    assert "100 Hz" in line and "200 Hz" in line and "--force" in line
    # a profile is checked alike; a rate unknown on either side is not checked (an info line says so)
    prof = rates.MadeFor("profile p.json", 285.7, "broad")
    with pytest.raises(InvalidInputError, match="285.7 Hz"):
        rates.check("rec", 200.0, None, [prof])
    assert rates.check("rec", None, None, made) == rates.check("rec", 100.0, None, [rates.MadeFor("m", None, None)]) == []
    assert len(rates.unchecked(None, [rates.MadeFor("m", None, None)])) == 2


def test_a_profile_with_nothing_that_depends_on_the_rate_applies_at_any_rate():
    """Biases, matrices and noise densities mean the same at any rate: a warning line, not a refusal; a time
    offset a fit observed or a low-pass is named in the refusal."""
    free = rates.MadeFor("profile p.json", 166.6, "my-imu", "")
    (line,) = rates.check("rec", 100.0, None, [free])
    assert "166.6 Hz" in line and "100 Hz" in line and "nothing in it depends on the rate" in line
    bound = rates.MadeFor("profile p.json", 200.0, "euroc", "time offset (0.539 samples)")
    with pytest.raises(InvalidInputError, match=r"its time offset \(0.539 samples\) depend on the rate"):
        rates.check("rec", 100.0, None, [bound])


def test_a_profiles_rate_terms_are_its_observed_time_offset_and_its_low_pass():
    tumvi = Profile.load(MODELS / "profiles" / "tumvi_bmi160" / "profile.json")  # offset held at its prior (0)
    euroc = Profile.load(MODELS / "profiles" / "euroc_adis16448" / "profile.json")
    assert tumvi.rate_terms() == "" and euroc.rate_terms().startswith("time offset (0.5")
    tumvi.floor = tumvi.floor.with_params(time_offset=0.5)  # an offset, but one no fit observed: the prior's half sample
    tumvi.observed["time_offset"] = {"observed": False, "why": "positions only"}
    assert tumvi.rate_terms() == ""
    tumvi.floor = tumvi.floor.with_params(cutoff_acc=20.0)
    assert tumvi.rate_terms() == "low-pass (acc 20 Hz)"
    del tumvi.observed["time_offset"]  # a profile that does not say: taken as observed
    assert tumvi.rate_terms() == "time offset (0.5 samples) and low-pass (acc 20 Hz)"


def test_refine_applies_a_rate_free_profile_to_a_recording_at_another_rate(tmp_path, capsys):
    """TUM-VI's profile (200 Hz; its time offset held at the prior, no low-pass) on a 100 Hz recording:
    refined with one warning line for the rate; EuRoC's (an observed offset) refused naming it."""
    rec = fetch_crop(tmp_path / "fetch_rec")
    rc, _out, err = refine(["--profile", MODELS / "profiles" / "tumvi_bmi160" / "profile.json", "--input", rec,
                            "--out", tmp_path / "o", "--quiet"], capsys)
    assert rc == 0 and (tmp_path / "o" / IMU_REL).is_file(), err
    assert sum("nothing in it depends on the rate" in ln for ln in rate_or_device_lines(err)) == 1, err
    rc, _out, err = refine(["--profile", MODELS / "profiles" / "euroc_adis16448" / "profile.json", "--input", rec,
                            "--out", tmp_path / "o2", "--quiet"], capsys)
    assert rc == 2 and "its time offset" in err and err.count("\n") == 1 and not (tmp_path / "o2").exists(), err


def test_another_device_is_one_warning_line():
    made = [rates.MadeFor("model m.pt", 200.0, "euroc+tum-vi")]
    assert rates.check("rec", 200.0, "tum-vi", made) == rates.check("rec", 200.0, "EuRoC", made) == []
    (line,) = rates.check("rec", 200.0, "fetch", made)
    assert "'fetch'" in line and "'euroc+tum-vi'" in line and "\n" not in line
    assert rates.recording_device("asl") is None  # EuRoC and TUM-VI share ASL: the layout does not tell
    assert rates.recording_device("asl", "tum-vi") == "tum-vi"
    assert rates.recording_device("fetch") == "fetch"
    assert rates.recording_device("csv-columns", "auto", "my-imu") == "my-imu"


@pytest.mark.parametrize("profile", sorted((MODELS / "profiles").glob("*/profile.json")))
def test_a_shipped_profile_is_for_its_datasets_recordings_and_not_the_others(profile):
    """A profile named DATASET_SENSOR is for that dataset's recordings: no warning there (the shipped Fetch
    profile on a Fetch recording warned before), one line on every other dataset's."""
    device = json.loads(profile.read_text())["device"]
    made = [rates.MadeFor(f"profile {profile.parent.name}", None, device)]
    own = [d for d in rates.DEVICE_FORMATS if device.startswith(d.replace("-", ""))]
    assert len(own) == 1, (device, own)
    assert rates.check("rec", None, own[0], made) == []
    for other in set(rates.DEVICE_FORMATS) - set(own):
        assert len(rates.check("rec", None, other, made)) == 1, other


# ---- what checkpoints record ---------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_models_get_their_rate_from_their_config(name):
    rec = imu_record(load_checkpoint(MODELS / name))
    assert (rec["sample_rate_hz"], rec["device"], rec["source"]) == (*SHIPPED[name], "config")


def test_a_new_checkpoint_records_rate_and_device_and_strip_keeps_them(tmp_path):
    t = 1_000_000_000 + np.arange(500, dtype=np.int64) * 5_000_000  # 200 Hz
    t[100:] += 1  # one odd period does not move the median
    z = np.zeros((500, 3))
    seg = Segment("s", t, z, z, z, z, np.tile([1.0, 0, 0, 0], (500, 1)))
    cfg = {"data": {"roots": [{"path": "mine/run1", "format": "asl"}], "window": 50}}
    record = training_record([seg], cfg)
    assert record == {"sample_rate_hz": pytest.approx(200.0), "device": "mine", "profile": None}
    cfg_named = {"data": {**cfg["data"], "device": "my-imu"}}
    assert training_record([seg], cfg_named)["device"] == "my-imu"
    ck = tmp_path / "ck.pt"
    save_checkpoint(ck, ImuRefiner(ModelConfig(hidden=8, fc=8, layers=1)), cfg, 1, 1, None, record=record)
    state = load_checkpoint(ck)
    assert imu_record(state)["source"] == "recorded" and state["device"] == "mine"
    assert "profile" not in state  # only what is known is stored
    small = strip_checkpoint(ck, tmp_path / "small.pt")
    assert imu_record(small) == imu_record(state)
    assert describe(load_checkpoint(tmp_path / "small.pt"))["imu"] == {
        "sample_rate_hz": pytest.approx(200.0), "device": "mine", "source": "recorded"}


def test_fit_records_the_training_rate_and_dataset(tmp_path, capsys):
    run = tmp_path / "run"
    assert fit_cli.main([
        "--out", str(run), "--quiet", "--data.window", "50", "--data.batch_size", "4", "--data.val_stride", "400",
        "--data.eval_stride", "400", "--model.hidden", "8", "--model.fc", "8", "--model.layers", "1",
        "--optim.steps_per_epoch", "1", "--optim.epochs", "1", "--seed", "1", "--threads", "1",
    ]) == 0
    state = load_checkpoint(run / "last.pt")
    assert state["sample_rate_hz"] == pytest.approx(200.0, rel=1e-3) and state["device"] == "euroc"
    capsys.readouterr()
    assert checkpoint_main(["info", str(run / "last.pt")]) == 0
    assert '"source": "recorded"' in capsys.readouterr().out


def test_evaluates_learned_method_records_its_training_rate(crop_split, tmp_path):
    from imu_learn.baselines.base import FitSettings
    from imu_learn.baselines.proposed import Proposed, ProposedConfig

    m = Proposed(ProposedConfig(model=ModelConfig(hidden=8, layers=1, fc=8), evals=1))
    m.fit([crop_split[0]], [crop_split[1]], FitSettings(window=50, batch_size=4, steps=2, seed=0))
    m.save(tmp_path / "p.pt")
    rec = imu_record(load_checkpoint(tmp_path / "p.pt"))
    assert rec["source"] == "recorded" and rec["sample_rate_hz"] == pytest.approx(200.0, rel=1e-3)


# ---- imu-learn refine ------------------------------------------------------------------------------


def test_euroc_model_on_a_100_hz_fetch_crop_stops_in_one_line(tmp_path, capsys):
    rec = fetch_crop(tmp_path / "fetch_rec")
    out = tmp_path / "out"
    rc, stdout, err = refine(["--checkpoint", MODELS / "euroc_adis16448.pt", "--input", rec, "--out", out], capsys)
    assert rc == 2 and stdout == "" and err.count("\n") == 1, err
    assert err.startswith("imu-learn refine: error: ") and "200 Hz" in err and "100 Hz" in err
    assert not out.exists()
    # --force: refined, with one warning line for the rate, one for the device, one from the guard (the
    # model's training statistics: Fetch's gyro is not EuRoC's)
    rc, stdout, err = refine(["--checkpoint", MODELS / "euroc_adis16448.pt", "--input", rec, "--out", out,
                              "--force", "--quiet"], capsys)
    assert rc == 0 and (out / IMU_REL).is_file()
    warnings = [ln for ln in err.splitlines() if ln.startswith("imu-learn refine: warning: ")]
    assert len(warnings) == 3 and "100 Hz" in warnings[0] and "'fetch'" in warnings[1], err
    assert "looks unlike model" in warnings[2], err
    assert "100 Hz" in stdout and "200 Hz" in stdout  # the summary line names the model's and the recording's rates


def rate_or_device_lines(err: str) -> list:
    """The rate and device check's warning lines (the guard's, on the data, aside)."""
    return [ln for ln in err.splitlines() if ln.startswith("imu-learn refine: warning: ") and "looks unlike" not in ln]


def test_a_model_of_the_recordings_rate_and_device_runs_without_a_word_from_the_rate_check(tmp_path, capsys):
    """The crop is EuRoC's motion in Fetch's layout at Fetch's rate: the rate and device checks pass
    silently; the guard, reading the data, names it unlike the Fetch model's training data (its mounting)."""
    rec = fetch_crop(tmp_path / "fetch_rec")
    rc, stdout, err = refine(["--checkpoint", MODELS / "fetch_debias.pt", "--input", rec, "--out", tmp_path / "o",
                              "--quiet"], capsys)
    assert rc == 0 and rate_or_device_lines(err) == [] and "fetch at 100 Hz" in stdout, err
    assert err.count("\n") == 1 and "looks unlike model" in err and "acc_median" in err, err


def test_same_rate_another_device_warns_once(tmp_path, capsys):
    """TUM-VI's model on an EuRoC folder: an ASL folder does not say which device wrote it, so the device
    check says nothing without --format or --imu-name; the guard, on the data, warns every time."""
    args = ["--checkpoint", MODELS / "tumvi_bmi160.pt", "--input", EUROC, "--out", tmp_path / "o", "--quiet"]
    rc, _out, err = refine(args, capsys)
    assert rc == 0 and rate_or_device_lines(err) == [] and "looks unlike model" in err, err
    rc, _out, err = refine([*args[:-2], tmp_path / "o2", "--format", "euroc", "--quiet"], capsys)
    lines = rate_or_device_lines(err)
    assert rc == 0 and len(lines) == 1 and "'euroc'" in lines[0] and "'tum-vi'" in lines[0], err
    rc, _out, err = refine([*args[:-2], tmp_path / "o3", "--imu-name", "tum-vi", "--quiet"], capsys)
    assert rc == 0 and rate_or_device_lines(err) == []


def test_a_checkpoint_without_a_rate_is_applied_with_an_info_line(tmp_path, capsys):
    ck = tmp_path / "ck.pt"
    save_checkpoint(ck, ImuRefiner(ModelConfig(hidden=8, fc=8, layers=1)), {"test": True}, 1, 1, None)
    rc, _out, err = refine(["--checkpoint", ck, "--input", TUMVI, "--out", tmp_path / "o"], capsys)
    assert rc == 0 and "records no sample rate" in err and "warning" not in err, err
