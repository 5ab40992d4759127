"""checkpoint strip, export and evaluate replace only their own earlier outputs: a file of the user's
where they would write is refused before any work (one line, exit 2, the file and the fix), and left
as it was (imu_learn.util.outputs)."""
import json
from pathlib import Path

import pytest
import torch

from imu_learn.cli import evaluate as ev_cli
from imu_learn.cli.checkpoint import main as checkpoint_main
from imu_learn.cli.export import main as export_main
from imu_learn.errors import InvalidInputError
from imu_learn.eval import report
from imu_learn.infer.checkpoint import load_checkpoint, save_checkpoint
from imu_learn.nn.model import ImuRefiner, ModelConfig
from imu_learn.util.outputs import check_replaceable

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
MODELS = REPO / "models"
SMALL = MODELS / "fetch_debias.pt"  # stripped_from "ALL/best.pt"
COV = MODELS / "euroc_adis16448_cov.pt"  # stripped_from "euroc_cov_head_s0/best.pt"
CSV = REPO / "datasets" / "euroc" / "V1_01_easy" / "mav0" / "imu0" / "data.csv"
EVAL_DEFAULT = REPO / "configs" / "eval_default.toml"
EVAL_ARGS = ["--config", str(EVAL_DEFAULT), "--methods", "raw", "--quiet", "--eval.stride", "50"]


def one_error_line(capsys, command):
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    errors = [ln for ln in lines if ln.startswith(f"imu-learn {command}: error:")]
    assert len(errors) == 1 and lines[-1] == errors[0], err
    return errors[0]


# ---------------------------------------------------------------------------------------------
# the shared rule


def test_check_replaceable_names_the_file_the_reason_and_the_fix(tmp_path):
    mine = tmp_path / "mine.txt"
    mine.write_text("x")
    check_replaceable([tmp_path / "absent"], lambda p: "never asked", "cmd")  # nothing there: nothing refused
    check_replaceable([mine], lambda p: None, "cmd")  # an earlier output of cmd
    with pytest.raises(InvalidInputError) as e:
        check_replaceable([mine], lambda p: "no marker", "cmd")
    assert str(e.value) == (f"{mine} exists and is not an earlier cmd output (no marker): cmd replaces only its "
                            "own outputs; remove it or give OUT a new name")
    (tmp_path / "dir").mkdir()
    with pytest.raises(InvalidInputError, match="a folder"):
        check_replaceable([tmp_path / "dir"], lambda p: None, "cmd")


# ---------------------------------------------------------------------------------------------
# checkpoint strip


def test_strip_refuses_a_users_file_and_leaves_it_as_it_was(tmp_path, capsys):
    victim = tmp_path / "victim.csv"
    victim.write_bytes(CSV.read_bytes())
    assert checkpoint_main(["strip", str(SMALL), str(victim)]) == 2
    line = one_error_line(capsys, "checkpoint")
    assert "InvalidInputError" in line and str(victim) in line and line.endswith("remove it or give DST a new name")
    assert victim.read_bytes() == CSV.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["victim.csv"]  # no temporary file left


def test_strip_refuses_a_checkpoint_it_did_not_write(tmp_path, capsys):
    """A run's checkpoint (no extra.stripped_from: e.g. another run's best.pt) is not strip's to replace."""
    run_ckpt = tmp_path / "best.pt"
    save_checkpoint(run_ckpt, ImuRefiner(ModelConfig(hidden=8, layers=1, fc=8)), {}, epoch=0, step=0,
                    best_metric=None)
    before = run_ckpt.read_bytes()
    assert checkpoint_main(["strip", str(SMALL), str(run_ckpt)]) == 2
    line = one_error_line(capsys, "checkpoint")
    assert str(run_ckpt) in line and "stripped_from" in line
    assert run_ckpt.read_bytes() == before


def test_strip_replaces_its_own_output_and_keeps_the_original_provenance(tmp_path, capsys):
    dst = tmp_path / "x.pt"
    assert checkpoint_main(["strip", str(COV), str(dst)]) == 0
    assert load_checkpoint(dst)["extra"]["stripped_from"] == "euroc_cov_head_s0/best.pt"  # re-stripped: kept
    assert checkpoint_main(["strip", str(SMALL), str(dst)]) == 0  # an earlier strip output: replaced
    assert load_checkpoint(dst)["extra"]["stripped_from"] == "ALL/best.pt"
    again = tmp_path / "again.pt"
    assert checkpoint_main(["strip", str(dst), str(again)]) == 0
    assert load_checkpoint(again)["extra"]["stripped_from"] == "ALL/best.pt"  # not "<tmp>/x.pt"


# ---------------------------------------------------------------------------------------------
# export


def export(out):
    return export_main(["--checkpoint", str(SMALL), "--out", str(out), "--window", "20"])


def test_export_refuses_a_users_model_json_and_replaces_its_own(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    mine = out / "model.json"
    mine.write_text('{"my": "own model card"}\n')
    assert export(out) == 2
    line = one_error_line(capsys, "export")
    assert "InvalidInputError" in line and str(mine) in line and line.endswith("remove it or give --out a new folder")
    assert mine.read_text() == '{"my": "own model card"}\n' and [p.name for p in out.iterdir()] == ["model.json"]
    assert not [p for p in tmp_path.iterdir() if p.name != "out"]  # no staging folder left

    mine.unlink()
    assert export(out) == 0
    card = json.loads(mine.read_text())
    assert export(out) == 0  # an earlier export: replaced
    assert json.loads(mine.read_text())["format"] == card["format"]

    onnx = out / "model.onnx"
    onnx.write_bytes(onnx.read_bytes() + b"changed by the user")  # no longer the file the card records
    changed = onnx.read_bytes()
    assert export(out) == 2
    line = one_error_line(capsys, "export")
    assert str(onnx) in line and "sha256" in line and onnx.read_bytes() == changed


# ---------------------------------------------------------------------------------------------
# evaluate


def test_evaluate_refuses_a_users_report_before_fitting_and_replaces_its_own(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("IMU_LEARN_DATA", raising=False)
    out = tmp_path / "report"
    out.mkdir()
    notes = out / "report.md"
    notes.write_text("# my notes\n")
    rc = ev_cli.main([*EVAL_ARGS, "--out", str(out)])
    torch.set_num_threads(1)
    assert rc == 2
    line = one_error_line(capsys, "evaluate")
    assert "InvalidInputError" in line and str(notes) in line and line.endswith("remove it or give --out a new folder")
    assert notes.read_text() == "# my notes\n" and [p.name for p in out.iterdir()] == ["report.md"]  # nothing fitted

    notes.unlink()
    assert ev_cli.main([*EVAL_ARGS, "--out", str(out)]) == 0
    torch.set_num_threads(1)
    report.check_out(out)  # an earlier report: evaluate's to replace
    (out / "report.md").write_text("stale\n")
    assert ev_cli.main([*EVAL_ARGS, "--out", str(out), "--reuse"]) == 0
    torch.set_num_threads(1)
    assert (out / "report.md").read_text() != "stale\n"


def test_evaluate_guard_needs_evaluations_own_result_json(tmp_path):
    """A result.json of another tool does not make the folder's CSVs evaluate's."""
    (tmp_path / "result.json").write_text('{"accuracy": 0.9}')
    (tmp_path / "peers.csv").write_text("a,b\n")
    with pytest.raises(InvalidInputError, match="result.json"):
        report.check_out(tmp_path)
    (tmp_path / "result.json").write_text(json.dumps({"config_name": "x", "methods": ["raw"], "eval": {}}))
    report.check_out(tmp_path)
