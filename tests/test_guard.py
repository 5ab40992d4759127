"""refine's guard (imu_learn.infer.guard): without ground truth, a recording is compared with the
statistics of a model's training data and with what the model adds to it; a recording unlike them
is one warning line, a checkpoint without them one info line, and summary.json holds the figures.

tests/data/euroc_adis16448_inputs.json is what models/euroc_adis16448.pt would record: the
statistics of EuRoC's five training flights (whole flights, ../shared/data/euroc) and the shipped
model's residual on them (:func:`imu_learn.infer.checkpoint.with_training_inputs`)."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from imu_learn import _imu_core as core
from imu_learn.data import synthetic
from imu_learn.data.types import Segment
from imu_learn.infer import guard

torch = pytest.importorskip("torch")

from imu_learn.cli.refine import main  # noqa: E402
from imu_learn.infer.checkpoint import (  # noqa: E402
    describe,
    load_checkpoint,
    save_checkpoint,
    strip_checkpoint,
    training_record,
    write_checkpoint,
)
from imu_learn.nn.model import ImuRefiner, ModelConfig  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
MODEL = REPO / "models" / "euroc_adis16448.pt"
CROPS = REPO / "datasets" / "euroc"
INPUTS = Path(__file__).resolve().parent / "data" / "euroc_adis16448_inputs.json"
IMU_REL = Path("mav0") / "imu0" / "data.csv"


@pytest.fixture(scope="module")
def model_with_inputs(tmp_path_factory) -> Path:
    """The shipped EuRoC model carrying its training statistics."""
    path = tmp_path_factory.mktemp("ck") / "euroc_with_inputs.pt"
    write_checkpoint(path, {**load_checkpoint(MODEL), "inputs": json.loads(INPUTS.read_text())})
    return path


def refine(ck: Path, src: Path, out: Path, capsys, *extra: str):
    rc = main(["--checkpoint", str(ck), "--input", str(src), "--out", str(out), "--device", "cpu", *extra])
    cap = capsys.readouterr()
    lines = [x for x in cap.err.replace("\r", "\n").splitlines() if x.startswith("imu-learn refine")]  # no bars
    return rc, lines, json.loads((out / "summary.json").read_text())


def test_a_recording_compared_with_itself_passes_and_an_offset_does_not():
    t, g, a = core.read_asl_imu(str(CROPS / "MH_01_easy" / IMU_REL))
    training = guard.training_inputs([("mh01", t, g, a)])
    assert guard.compare(training, guard.input_stats(t, g, a)) == []
    outside = guard.compare(training, guard.input_stats(t, g + [0.0, 0.0, 0.2], a))
    assert outside[0]["statistic"] == "gyro_median[z]" and outside[0]["training"][0] == pytest.approx(np.median(g[:, 2]))
    scaled = {d["statistic"] for d in guard.compare(training, guard.input_stats(t, g, a * 1.1))}
    assert "acc_norm_median" in scaled
    calmer = guard.compare(training, guard.input_stats(t, g * 0.5, a))  # gentler motion is inside what was seen
    assert not [d for d in calmer if "p01" in d["statistic"] or "p99" in d["statistic"] or "std" in d["statistic"]]


def test_a_profile_is_checked_for_its_device_not_for_how_hard_the_recording_moves(tmp_path):
    """A profile's guard reads the locations alone: twice the motion (every tail and spread beyond the
    training's) passes for a profile and warns for a model; another mounting (the accelerometer's axes
    swapped) warns for both, naming it. End to end: calibrate writes the statistics, refine checks them."""
    t, g, a = core.read_asl_imu(str(CROPS / "MH_01_easy" / IMU_REL))
    training = guard.training_inputs([("mh01", t, g, a)])
    harder = guard.input_stats(t, 2.0 * (g - np.median(g, 0)) + np.median(g, 0), a)
    assert guard.compare(training, harder) and not guard.compare(training, harder, device_only=True)
    mounted = guard.input_stats(t, g, a[:, [2, 1, 0]])
    entry, warning, _ = guard.verdict(training, mounted, "profile P", device_only=True)
    assert entry["verdict"] == "unlike the training data" and "another device or mounting" in warning
    from imu_learn.cli.calibrate import main as calibrate

    assert calibrate(["--input", str(CROPS / "MH_01_easy"), "--out", str(tmp_path / "cal"), "--no-plot"]) == 0
    prof = json.loads((tmp_path / "cal" / "profile.json").read_text())
    assert [r["name"] for r in prof["inputs"]["recordings"]] and prof["inputs"]["recordings"][0]["samples"] > 1000


def test_a_model_adding_far_more_than_on_its_training_data_warns():
    t, g, a = core.read_asl_imu(str(CROPS / "MH_01_easy" / IMU_REL))
    training = {**guard.training_inputs([("mh01", t, g, a)]),
                "residual_rms": [{"name": "mh01", "gyro": [0.01] * 3, "acc": [0.1] * 3}]}
    stats = guard.input_stats(t, g, a)
    ok = {"gyro": [0.02] * 3, "acc": [0.3] * 3}  # within 3 x the training's
    assert guard.verdict(training, stats, "model m", ok)[1] is None
    entry, warning, _ = guard.verdict(training, stats, "model m", {"gyro": [0.01, 0.05, 0.01], "acc": [0.1] * 3})
    assert entry["outside"][0]["statistic"] == "model_residual_rms_gyro[y]" and "model_residual_rms_gyro[y]" in warning


def test_a_checkpoint_without_statistics_cannot_be_checked(tmp_path, capsys):
    old = tmp_path / "written_before.pt"  # a checkpoint of before the trainer recorded them
    write_checkpoint(old, {k: v for k, v in load_checkpoint(MODEL).items() if k != "inputs"})
    rc, err, summary = refine(old, CROPS / "MH_04_difficult", tmp_path / "o", capsys)
    assert rc == 0 and summary["guard"]["verdict"] == "unchecked"
    assert len(err) == 1 and "records no statistics of its training data" in err[0]
    assert summary["checkpoint"] == str(old) and summary["recording"]["sample_rate_hz"] == pytest.approx(200.0, rel=1e-3)


def test_the_shipped_euroc_model_carries_its_statistics_and_passes_on_a_crop(tmp_path, capsys):
    assert load_checkpoint(MODEL).get("inputs", {}).get("recordings")
    rc, err, summary = refine(MODEL, CROPS / "MH_04_difficult", tmp_path / "o", capsys)
    assert rc == 0 and summary["guard"]["verdict"] == "like the training data" and not err


@pytest.mark.parametrize("crop", ["MH_04_difficult", "V1_01_easy"])
def test_the_euroc_model_on_euroc_crops_passes(model_with_inputs, tmp_path, capsys, crop):
    rc, err, summary = refine(model_with_inputs, CROPS / crop, tmp_path / "o", capsys)
    g = summary["guard"]
    assert rc == 0 and err == [] and g["verdict"] == "like the training data" and g["outside"] == []
    assert len(g["residual_rms"]["gyro"]) == 3 and len(g["training_recordings"]) == 5


@pytest.mark.parametrize("change", ["gyro bias", "acc scale"])
def test_a_crop_with_a_large_bias_or_scale_warns(model_with_inputs, tmp_path, capsys, change):
    src = tmp_path / "in"
    shutil.copytree(CROPS / "MH_04_difficult", src)
    t, g, a = core.read_asl_imu(str(src / IMU_REL))
    g, a = (g + [0.1, 0.0, 0.0], a) if change == "gyro bias" else (g, a * 1.1)
    header = (src / IMU_REL).read_text().splitlines()[0]
    core.write_asl_imu(str(src / IMU_REL), t, g, a, header)
    rc, err, summary = refine(model_with_inputs, src, tmp_path / "o", capsys)
    assert rc == 0 and len(err) == 1 and "looks unlike model" in err[0]
    worst = summary["guard"]["outside"][0]["statistic"]
    assert worst == ("gyro_median[x]" if change == "gyro bias" else "acc_norm_median"), summary["guard"]["outside"]


def test_a_fetch_like_recording_warns_past_the_rate_check(model_with_inputs, tmp_path, capsys):
    src = synthetic.write_fetch_recording(tmp_path, seconds=20.0)
    out = tmp_path / "o"
    rc, err, summary = refine(model_with_inputs, src, out, capsys, "--force")
    assert rc == 0 and "applied anyway (--force)" in err[0] and "looks unlike model" in err[-1]
    assert summary["guard"]["verdict"] == "unlike the training data"


def test_the_summary_of_a_file_output_lies_beside_it(tmp_path, capsys):
    out = tmp_path / "refined.csv"
    assert main(["--checkpoint", str(MODEL), "--input", str(CROPS / "MH_04_difficult" / IMU_REL), "--out", str(out),
                 "--quiet", "--device", "cpu"]) == 0
    assert json.loads((tmp_path / "refined.csv.summary.json").read_text())["output"] == str(out)


def test_a_new_checkpoint_records_its_training_statistics_and_residual(tmp_path):
    t = synthetic.stamps(3.0)
    rng = np.random.default_rng(0)
    g, a = rng.normal(0, 0.1, (len(t), 3)), rng.normal([0, 0, 9.81], 0.1, (len(t), 3))
    seg = Segment("s", t, g, a, np.zeros((len(t), 3)), np.zeros((len(t), 3)), np.tile([1.0, 0, 0, 0], (len(t), 1)))
    cfg = {"data": {"roots": [{"path": "mine/run1", "format": "asl"}], "window": 50}}
    record = training_record([seg], cfg, inputs=True)
    model = ImuRefiner(ModelConfig(hidden=8, fc=8, layers=1))
    model.train()
    save_checkpoint(tmp_path / "ck.pt", model, cfg, 1, 1, None, record=record)
    assert model.training  # measuring the residual leaves the model's mode as it was
    state = load_checkpoint(tmp_path / "ck.pt")
    inputs = state["inputs"]
    assert inputs["recordings"][0]["name"] == "s" and inputs["recordings"][0]["rate_hz"] == pytest.approx(200.0)
    assert len(inputs["residual_rms"]) == 1 and len(inputs["residual_rms"][0]["gyro"]) == 3
    assert "_training_imu" not in state
    small = strip_checkpoint(tmp_path / "ck.pt", tmp_path / "small.pt")
    assert small["inputs"] == inputs and describe(small)["training_statistics"] == ["s"]
