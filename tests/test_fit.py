"""The trainer, python -m imu_learn.fit: run folder, resume, Ctrl-C, corrupt checkpoints, config.

Runs are tiny (1-layer model of width 8, window 50, 4 steps per epoch) so the file stays fast.
"""
import csv
import json
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from imu_learn.cli import fit as fit_cli
from imu_learn.infer.checkpoint import load_checkpoint
from imu_learn.nn.model import ImuRefiner, ModelConfig
from imu_learn.train import trainer
from imu_learn.train.config import ConfigError, RunConfig, build_config, load_config, read_toml

REPO = Path(__file__).resolve().parent.parent
PY = sys.executable

TINY = [
    "--quiet",
    "--data.window", "50", "--data.batch_size", "8", "--data.val_stride", "200", "--data.eval_stride", "50",
    "--model.hidden", "8", "--model.fc", "8", "--model.layers", "1",
    "--optim.steps_per_epoch", "4", "--optim.lr", "1e-3", "--seed", "7", "--threads", "1",
    "--model.start", "raw",  # the mechanics of a run; the default start (calibrate) is tested on its own
]


def tiny(run_dir, epochs, *more):
    return ["--out", str(run_dir), *TINY, "--optim.epochs", str(epochs), *more]


def rows(run_dir):
    with open(Path(run_dir) / "metrics.csv") as f:
        out = list(csv.DictReader(f))
    for r in out:
        r.pop("elapsed_s")
    return out


def weights(path):
    return load_checkpoint(path)["model"]


def snapshot(d):
    return {p.name: p.read_bytes() for p in sorted(Path(d).iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    """An uninterrupted 3-epoch run, the reference for the resume tests."""
    d = tmp_path_factory.mktemp("fit") / "full"
    assert fit_cli.main(tiny(d, 3)) == 0
    return d


def test_run_writes_run_folder(full_run):
    for name in ("split.json", "metrics.csv", "best.pt", "last.pt", "results.json", "config.toml"):
        assert (full_run / name).is_file(), name
    r = rows(full_run)
    assert [int(x["epoch"]) for x in r] == [1, 2, 3]
    assert [int(x["step"]) for x in r] == [4, 8, 12]
    assert {"train_total", "val_total", "val_q", "val_v", "val_p", "best_epoch"} <= set(r[0])

    split = json.loads((full_run / "split.json").read_text())
    assert [e["entry"] for e in split["train"]] == ["MH_01_easy[0:0.8]"]
    assert [e["entry"] for e in split["val"]] == ["MH_01_easy[0.8:1]"]
    assert [e["entry"] for e in split["test"]] == ["V1_01_easy"]
    tr, va = split["train"][0]["segments"][0], split["val"][0]["segments"][0]
    assert tr["t1_ns"] < va["t0_ns"]  # disjoint time blocks

    last = load_checkpoint(full_run / "last.pt")
    assert last["epoch"] == 3 and last["step"] == 12
    assert last["config"]["optim"]["lr"] == 1e-3 and last["model_args"]["hidden"] == 8
    assert last["optimizer"] is not None and last["code_version"]
    assert torch.count_nonzero(last["model"]["std"] != 1.0) == 6  # training-set normalisation
    best = load_checkpoint(full_run / "best.pt")
    vals = [float(x["val_total"]) for x in r]
    assert best["best_metric"] == pytest.approx(min(vals))
    assert best["epoch"] == 1 + vals.index(min(vals))

    res = json.loads((full_run / "results.json").read_text())
    assert res["test_sequences"] == ["V1_01_easy"]
    for row in ("raw", "model"):
        for col in ("open_loop", "bias_removed"):
            for n in ("10", "200"):
                cell = res["table"][row][col][n]
                assert cell["windows"] > 0 and cell["rot_deg"] > 0 and cell["trans_m"] > 0
    # removing the start-up bias helps the raw EuRoC IMU a lot over 200 samples
    assert res["table"]["raw"]["bias_removed"]["200"]["rot_deg"] < 0.5 * res["table"]["raw"]["open_loop"]["200"]["rot_deg"]


def test_default_run_trains_on_top_of_its_training_splits_profile(tmp_path):
    """The default start (model.start = calibrate): calibrate's profile of the training split alone
    (RUN/profile/), the untrained model is that floor (epoch 0, scored on validation and kept unless an
    epoch beats it), and the final table puts raw, the profile and the model side by side and says which
    ships."""
    d = tmp_path / "on_profile"
    no_start = TINY[:TINY.index("--model.start")]
    assert fit_cli.main(["--out", str(d), *no_start, "--optim.epochs", "2"]) == 0
    prof = json.loads((d / "profile" / "profile.json").read_text())
    assert (d / "profile" / "imu.yaml").is_file()
    fitted_on = prof["sources"][0]
    assert fitted_on["train"] == ["MH_01_easy[0:0.8]"] and fitted_on["val"] == ["MH_01_easy[0.8:1]"]
    assert any(abs(b) > 1e-4 for b in prof["gyroscope"]["bias"])  # EuRoC's gyro bias, fitted
    assert {prof["selection"]["gyro"], prof["selection"]["acc"]} <= set(prof["selection"]["levels"]["gyro"])
    assert [int(x["epoch"]) for x in rows(d)] == [0, 1, 2]
    assert load_checkpoint(d / "best.pt")["model_args"]["start"] == "profile"
    res = json.loads((d / "results.json").read_text())
    assert set(res["table"]) == {"raw", "timing", "profile", "model"}
    # the open-loop AOE is a cell of the table and of the selection (the floor's AOE is far below raw's)
    aoe = res["open_loop_aoe_deg"]
    assert set(aoe) == {"raw", "timing", "profile", "model"} and aoe["profile"] < 0.5 * aoe["raw"]
    assert "open-loop AOE [deg]: raw IMU" in res["text"]
    assert all(float(x["val_pose_aoe_deg"]) > 0 for x in rows(d))
    best_epoch = load_checkpoint(d / "best.pt")["epoch"]
    assert res["ships"] == ("model" if best_epoch else "profile")
    assert f"ships: the {'trained model' if best_epoch else 'device profile'}" in res["text"]
    if not best_epoch:  # best.pt is the floor: the profile's own figures (its low-pass as a truncated FIR)
        for col in ("open_loop", "bias_removed"):
            for n in ("10", "200"):
                m, p = res["table"]["model"][col][n], res["table"]["profile"][col][n]
                assert m["rot_deg"] == pytest.approx(p["rot_deg"], rel=0.03)
                assert m["trans_m"] == pytest.approx(p["trans_m"], rel=0.03)
        assert aoe["model"] == pytest.approx(aoe["profile"], rel=0.03)


def test_select_on_validation_pose(tmp_path, full_run, capsys):
    """optim.select = "val_pose": best.pt is the epoch with the lowest bias-removed pose score on
    the validation block, which can differ from the loss pick; the score is a ratio to raw IMU."""
    d = tmp_path / "pose"
    assert fit_cli.main(tiny(d, 3, "--optim.select", "val_pose")) == 0
    r = rows(d)
    scores = [float(x["val_pose_score"]) for x in r]
    assert all(0.0 < x < 10.0 for x in scores)
    assert all(float(x["val_pose_rot_deg"]) > 0 and float(x["val_pose_trans_m"]) > 0 for x in r)
    # same batches and weights as the loss-selected run: only the choice of best.pt differs
    assert [x["val_total"] for x in r] == [x["val_total"] for x in rows(full_run)]
    best = load_checkpoint(d / "best.pt")
    assert best["best_metric"] == pytest.approx(min(scores))
    assert best["epoch"] == 1 + scores.index(min(scores))
    res = json.loads((d / "results.json").read_text())
    assert res["selected_on"] == "val_pose" and res["best_metric"] == pytest.approx(min(scores))
    note = "no epoch beat raw IMU on the validation sequences" in capsys.readouterr().out
    assert note == (min(scores) >= 1.0)


def test_bias_removed_pose_of_raw_matches_the_final_table_protocol():
    """trainer.bias_removed_pose is the final table's second protocol: a constant bias added to a
    sequence changes its open-loop error but (almost) not the bias-removed one."""
    import numpy as np

    from imu_learn.score.metrics import relative_pose_rmse_many, simulate_sequence, with_imu

    cfg = build_config({}, {"data.startup_bias_s": 5.0, "data.val_stride": 20})
    rng = np.random.default_rng(3)
    n = 6001  # 30 s at 200 Hz
    t_ns = np.arange(n, dtype=np.int64) * 5_000_000
    k = np.arange(n)[:, None] / 200.0
    gyro = 0.5 * np.sin(k * rng.uniform(0.5, 2.0, 3) + rng.uniform(0, 6, 3))
    acc = np.array([0.0, 0.0, 9.81]) + np.sin(k * rng.uniform(0.5, 2.0, 3))
    s = simulate_sequence(t_ns, gyro, acc)  # ground truth whose exact IMU signal is gyro/acc
    b = with_imu(s, s.gyro + np.array([0.01, -0.02, 0.03]), s.acc + np.array([0.1, 0.0, -0.1]))
    biased = trainer.bias_removed_pose([b], 200, cfg)
    open_loop = relative_pose_rmse_many([b], 200, 20, first_s=5.0)
    assert open_loop["rot_deg"] > 1.0 and open_loop["trans_m"] > 0.01
    assert biased["rot_deg"] < 1e-6 and biased["trans_m"] < 1e-7
    assert biased["windows"] == open_loop["windows"]


def test_select_combine_mean_is_the_geometric_mean_of_the_ratios(tmp_path):
    """optim.select_combine: "max" is the worst model/raw ratio over horizons and terms, "mean"
    their geometric mean; same batches and weights, so per epoch mean <= max, and the two agree
    only when every ratio is the same."""
    more = ["--optim.select", "val_pose", "--optim.select_horizons", "[10, 50]"]
    assert fit_cli.main(tiny(tmp_path / "max", 2, *more)) == 0
    assert fit_cli.main(tiny(tmp_path / "mean", 2, *more, "--optim.select_combine", "mean")) == 0
    a, b = rows(tmp_path / "max"), rows(tmp_path / "mean")
    assert [x["val_total"] for x in a] == [x["val_total"] for x in b]
    for x, y in zip(a, b):
        assert float(y["val_pose_score"]) < float(x["val_pose_score"])
    with pytest.raises(ConfigError, match="optim.select_combine"):
        build_config({}, {"optim.select_combine": "median"})


def test_train_bias_remove_takes_a_constant_bias_out_of_train_and_val_only():
    """data.train_bias = "remove": a constant bias added to exact IMU is fitted against ground truth
    over the whole segment and subtracted from the train and val segments; test is untouched."""
    import numpy as np

    from imu_learn.data.splits import Split
    from imu_learn.score.metrics import simulate_sequence, with_imu

    rng = np.random.default_rng(5)
    n = 4001  # 20 s at 200 Hz
    t_ns = np.arange(n, dtype=np.int64) * 5_000_000
    k = np.arange(n)[:, None] / 200.0
    s = simulate_sequence(t_ns, 0.5 * np.sin(k * rng.uniform(0.5, 2.0, 3)),
                          np.array([0.0, 0.0, 9.81]) + np.sin(k * rng.uniform(0.5, 2.0, 3)))
    bg, ba = np.array([0.01, -0.02, 0.08]), np.array([0.1, 0.0, -0.1])
    b = with_imu(s, s.gyro + bg, s.acc + ba)
    cfg = build_config({}, {"data.train_bias": "remove"})
    out = trainer.without_device_bias(Split([b], [b], [b], {}), cfg)
    for seq in (out.train[0], out.val[0]):
        assert np.abs(seq.gyro - s.gyro).max() < 1e-6 and np.abs(seq.acc - s.acc).max() < 1e-5
    assert out.test[0] is b
    with pytest.raises(ConfigError, match="data.train_bias"):
        build_config({}, {"data.train_bias": "drop"})


def test_resume_in_new_process_matches_uninterrupted(tmp_path, full_run):
    d = tmp_path / "resumed"
    assert fit_cli.main(tiny(d, 1)) == 0
    assert len(rows(d)) == 1
    p = subprocess.run([PY, "-m", "imu_learn.fit", "--resume", str(d), "--optim.epochs", "3", "--quiet"],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert rows(d) == rows(full_run)
    for name in ("last.pt", "best.pt"):
        a, b = weights(d / name), weights(full_run / name)
        for k in a:
            torch.testing.assert_close(a[k], b[k], rtol=1e-6, atol=1e-7)
    assert load_checkpoint(d / "last.pt")["step"] == 12


def test_ctrl_c_saves_last_and_exits_130(tmp_path, full_run, capsys):
    d = tmp_path / "interrupted"

    def hook(step, loss):
        if step == 6:  # in the middle of epoch 2
            raise KeyboardInterrupt

    assert fit_cli.main(tiny(d, 3), on_step=hook) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert "interrupted" in err[-1] and "--resume" in err[-1]
    state = load_checkpoint(d / "last.pt")
    assert state["step"] == 6 and state["epoch"] == 1
    assert len(rows(d)) == 1
    assert not (d / "results.json").exists()
    # continuing mid-epoch reproduces the uninterrupted run
    assert fit_cli.main(["--resume", str(d), "--quiet"]) == 0
    assert rows(d) == rows(full_run)
    a, b = weights(d / "last.pt"), weights(full_run / "last.pt")
    for k in a:
        torch.testing.assert_close(a[k], b[k], rtol=1e-6, atol=1e-7)


def test_sigint_to_a_real_process(tmp_path):
    d = tmp_path / "sigint"
    proc = subprocess.Popen([PY, "-m", "imu_learn.fit", *tiny(d, 1000)], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 60
        while not (d / "metrics.csv").exists() and time.time() < deadline and proc.poll() is None:
            time.sleep(0.1)
        assert proc.poll() is None, proc.communicate()[1]
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1].startswith("imu-learn fit: interrupted; saved ")
    assert load_checkpoint(d / "last.pt")["step"] >= 4


@pytest.mark.parametrize("damage", ["truncated", "garbage", "pickle_27", "empty"])
def test_corrupt_checkpoint_is_one_line_exit_2_and_nothing_changes(tmp_path, full_run, damage):
    d = tmp_path / "corrupt"
    shutil.copytree(full_run, d)
    data = (d / "last.pt").read_bytes()
    garbage = np.random.default_rng(7).bytes(4096)
    # bytes that read as pickle protocol 27: torch warns before it raises
    bad = {"truncated": data[: len(data) // 2], "garbage": garbage, "pickle_27": b"\x80\x1b" + garbage,
           "empty": b""}[damage]
    (d / "last.pt").write_bytes(bad)
    before = snapshot(d)
    p = subprocess.run([PY, "-m", "imu_learn.fit", "--resume", str(d), "--optim.epochs", "5"],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    assert lines[0].startswith("imu-learn fit: error: CheckpointError:") and "last.pt" in lines[0]
    assert snapshot(d) == before


def test_resume_without_checkpoint(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert fit_cli.main(["--resume", str(tmp_path / "empty")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "last.pt" in err[0]
    assert list((tmp_path / "empty").iterdir()) == []


@pytest.mark.parametrize(
    "args, key",
    [
        (["--optim.lr", "abc"], "optim.lr"),
        (["--optim.lrr", "1e-3"], "optim.lrr"),
        (["--data.window", "2.5"], "data.window"),
        (["--model.causal", "maybe"], "model.causal"),
        (["--data.augment.gyro_bias_max", "x"], "data.augment.gyro_bias_max"),
        (["--optim.epochs"], "optim.epochs"),
        (["--data.split.train", "[1, 2]"], "data.split.train"),
        (["--optim.epochs", "0"], "optim.epochs"),
        (["--optim.select", "test_loss"], "optim.select"),
    ],
)
def test_override_errors_name_the_key(tmp_path, capsys, args, key):
    assert fit_cli.main(["--out", str(tmp_path / "x"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0] and err[0].startswith("imu-learn fit: error:")
    assert not (tmp_path / "x").exists()


def test_resume_refuses_changing_the_model(tmp_path, full_run, capsys):
    d = tmp_path / "r"
    shutil.copytree(full_run, d)
    before = snapshot(d)
    assert fit_cli.main(["--resume", str(d), "--model.hidden", "16"]) == 2
    assert "model.hidden" in capsys.readouterr().err
    assert snapshot(d) == before


def test_resume_refuses_an_edited_config_toml(tmp_path, full_run, capsys):
    """The run's config.toml edited by hand (its model smaller): the resume would train the checkpoint's
    config and leave the file lying; refused in one line naming the key, nothing written."""
    d = tmp_path / "r"
    shutil.copytree(full_run, d)
    text = (d / "config.toml").read_text()
    assert "hidden = 8\n" in text
    (d / "config.toml").write_text(text.replace("hidden = 8\n", "hidden = 4\n"))
    before = snapshot(d)
    assert fit_cli.main(["--resume", str(d), "--optim.epochs", "4"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "model.hidden" in err[0] and "config.toml" in err[0], err
    assert snapshot(d) == before


def test_a_newer_versions_root_keys_are_no_edit_but_a_roots_path_is(tmp_path, full_run):
    """A run's config.toml written before data.roots' entries gained keys (a user CSV's columns and units) was
    refused as edited after an update (the roots compared as one list); entry by entry, key by key, only keys
    both hold count, and a root's changed path still does."""
    from imu_learn.train.trainer import config_edits, resolve_config

    cfg, _ = resolve_config(None, full_run, {})
    text = (full_run / "config.toml").read_text()
    older = "".join(ln for ln in text.splitlines(keepends=True)
                    if ln.split("=")[0].strip() not in ("columns", "time_unit", "gyro_unit", "acc_unit"))
    assert older != text
    (tmp_path / "config.toml").write_text(older)
    assert config_edits(tmp_path / "config.toml", cfg) == []
    moved = re.sub(r'(?m)^path = "(.*)"$', r'path = "\1_moved"', older, count=1)  # the first root's path
    (tmp_path / "config.toml").write_text(moved)
    assert config_edits(tmp_path / "config.toml", cfg) == ["data.roots.0.path"]


def test_resume_refuses_another_out(tmp_path, full_run, capsys):
    """--out with --resume was ignored without a word (the run trained on in its own folder)."""
    assert fit_cli.main(["--resume", str(full_run), "--out", str(tmp_path / "other")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a resumed run continues in its own folder" in err[0], err
    assert not (tmp_path / "other").exists()


def test_a_run_stopped_before_its_first_save_starts_again_on_resume(tmp_path, full_run, capsys):
    """Ctrl-C while the run's profile was fitted leaves config.toml and split.json, no last.pt: --resume
    starts the run again from its config (it was a FileNotFoundError)."""
    d = tmp_path / "early"
    d.mkdir()
    for name in ("config.toml", "split.json"):
        shutil.copy(full_run / name, d / name)
    text = (d / "config.toml").read_text().replace("epochs = 3", "epochs = 1")
    (d / "config.toml").write_text(text)
    assert fit_cli.main(["--resume", str(d), "--quiet"]) == 0, capsys.readouterr().err
    assert (d / "last.pt").is_file() and [int(x["epoch"]) for x in rows(d)] == [1]


def test_existing_run_is_not_overwritten(full_run, capsys):
    before = snapshot(full_run)
    assert fit_cli.main(tiny(full_run, 3)) == 2
    assert "--resume" in capsys.readouterr().err
    assert snapshot(full_run) == before


def test_bad_split_name(tmp_path, capsys):
    assert fit_cli.main(["--out", str(tmp_path / "x"), "--data.split.test", "NoSuchSeq"]) == 2
    err = capsys.readouterr().err
    assert "data.split.test" in err and "NoSuchSeq" in err


def test_overlapping_blocks_rejected(tmp_path, capsys):
    assert fit_cli.main(["--out", str(tmp_path / "x"), "--data.split.val", "MH_01_easy[0.7:1]"]) == 2
    assert "overlaps" in capsys.readouterr().err


def test_config_files(monkeypatch):
    monkeypatch.delenv("IMU_LEARN_DATA", raising=False)
    # no-args = configs/default.toml = the dataclass defaults
    assert build_config(read_toml(REPO / "configs" / "default.toml"), {}) == RunConfig()
    for name in ("euroc", "blackbird", "broad", "euroc_paper", "tumvi"):
        cfg = load_config(REPO / "configs" / f"{name}.toml")
        assert cfg.data.split.train and cfg.data.split.val and cfg.data.split.test
        # real data: paths relative to the data root (IMU_LEARN_DATA / --data.data_root), none set here
        assert cfg.data.data_root == ""
        for r in cfg.data.roots:
            for p in (r.path, r.groundtruth):
                assert not Path(p).is_absolute() and not p.startswith(".."), (name, p)
    cfg = load_config(REPO / "configs" / "default.toml", ["--optim.lr", "3e-4", "--data.split.test", "A,B"])
    assert cfg.optim.lr == 3e-4 and cfg.data.split.test == ["A", "B"]


def test_root_max_gap_lets_sparse_ground_truth_through():
    """The default run scores V1_01 against the shipped 20 Hz ASL state: with the root's
    max_gap_s = 0.06 it is one segment over the whole crop; with the 50 ms default every 50 ms
    step between states is a gap and no segment is long enough."""
    from imu_learn.data.splits import make_split
    from imu_learn.errors import AlignmentError

    d = RunConfig().data
    assert d.roots[1].groundtruth.endswith("groundtruth_state_20hz.csv") and d.roots[1].max_gap_s == 0.06
    split = make_split(d)
    (v1,) = split.test
    assert v1.name.startswith("V1_01_easy") and len(v1) > 11_500
    assert split.record["test"][0]["groundtruth"] == d.roots[1].groundtruth
    d.roots[1].max_gap_s = 0.05
    with pytest.raises(AlignmentError, match="gap"):
        make_split(d)
    with pytest.raises(ConfigError, match=r"data.roots\[1\].max_gap_s"):
        build_config({}, {"data.roots": [{"path": "a"}, {"path": "b", "max_gap_s": 0.0}]})


@pytest.mark.parametrize("name", ["euroc", "blackbird", "broad", "euroc_paper", "tumvi"])
def test_shipped_configs_split_real_data(shared, name, monkeypatch):
    from imu_learn.data.splits import make_split

    monkeypatch.chdir(REPO)
    monkeypatch.setenv("IMU_LEARN_DATA", str(shared))
    cfg = load_config(REPO / "configs" / f"{name}.toml")
    assert Path(cfg.data.data_root) == shared
    split = make_split(cfg.data)
    assert Path(split.record["data_root"]).resolve() == shared.resolve()  # a symlinked data root is recorded resolved
    names = {k: {s.name for s in split[k]} for k in ("train", "val", "test")}
    assert split.train and split.val and split.test
    assert not (names["train"] & names["test"]) and not (names["val"] & names["test"])


def test_covariance_head_alone_on_a_frozen_refiner(tmp_path, full_run):
    """optim.trainable = covariance: the refiner's weights stay those of optim.init bit for bit,
    the covariance head learns (its weights move), and the NLL is logged."""
    d = tmp_path / "cov"
    assert fit_cli.main(tiny(d, 2, "--model.covariance", "true", "--optim.init", str(full_run / "best.pt"),
                         "--optim.trainable", "covariance", "--loss.w_nll", "1.0")) == 0
    before, after = weights(full_run / "best.pt"), weights(d / "last.pt")
    assert all(torch.equal(before[k], after[k]) for k in before)
    assert any(k.startswith("cov_head.") for k in after)
    fresh = ImuRefiner(ModelConfig(hidden=8, fc=8, layers=1, covariance=True)).state_dict()
    assert any(not torch.equal(fresh[k], after[k]) for k in after if k.startswith("cov_head."))
    assert "val_nll" in rows(d)[0]


@pytest.mark.parametrize("args,key", [
    (["--optim.trainable", "covariance"], "optim.trainable"),
    (["--loss.w_nll", "1.0"], "loss.w_nll"),
])
def test_covariance_settings_that_cannot_work_are_refused(tmp_path, capsys, args, key):
    assert fit_cli.main(tiny(tmp_path / "x", 1, *args)) == 2
    assert key in capsys.readouterr().err


def test_init_from_a_checkpoint_of_another_shape_is_refused(tmp_path, full_run, capsys):
    assert fit_cli.main(tiny(tmp_path / "x", 1, "--model.hidden", "16", "--optim.init", str(full_run / "best.pt"))) == 2
    assert "model.hidden" in capsys.readouterr().err


def test_fir_init_timing_and_validate_start(tmp_path):
    """model.start = timing: fit stores the train split's fitted offset in the checkpoint's model
    config and the untrained model is scored as epoch 0 (optim.validate_start), which best.pt can be."""
    from imu_learn.baselines.timing import Timing  # noqa: F401  (the floor the FIR starts as)

    d = tmp_path / "fir"
    assert fit_cli.main(tiny(d, 2, "--model.fir_taps", "5", "--model.start", "timing",
                             "--optim.validate_start", "true", "--optim.lr", "1e-1")) == 0
    r = rows(d)
    assert [row["epoch"] for row in r] == ["0", "1", "2"]
    assert r[0]["train_total"] == "" and r[0]["val_total"] != ""
    ck = load_checkpoint(d / "best.pt")
    tau = ck["config"]["model"]["fir_init_tau"]
    assert tau != 0.0 and abs(tau) <= 2.0
    best = min(r, key=lambda row: float(row["val_total"]))
    assert int(ck["epoch"]) == int(best["epoch"])


def test_select_reference_start_scores_against_the_untrained_floor(tmp_path):
    """optim.select_reference = start: epoch 0 (the floor model.start names) scores exactly 1, later
    epochs their ratios over it; the reference survives a resume; it needs validate_start."""
    d = tmp_path / "ref"
    args = ["--model.fir_taps", "3", "--model.start", "timing", "--optim.validate_start", "true",
            "--optim.select", "val_pose", "--optim.select_reference", "start"]
    assert fit_cli.main(tiny(d, 1, *args)) == 0
    r = rows(d)
    assert float(r[0]["val_pose_score"]) == pytest.approx(1.0, abs=1e-12)
    ref = load_checkpoint(d / "last.pt")["extra"]["select_reference"]
    assert ref and all(x > 0 for x in ref)
    assert fit_cli.main(["--resume", str(d), "--quiet", "--optim.epochs", "2"]) == 0
    assert load_checkpoint(d / "last.pt")["extra"]["select_reference"] == ref
    assert len(rows(d)) == 3
    assert fit_cli.main(tiny(tmp_path / "bad", 1, "--optim.select", "val_pose", "--optim.select_reference", "start")) == 2


def test_init_from_a_checkpoint_older_than_a_model_arg(tmp_path, full_run):
    """optim.init from a checkpoint written before model.start / fir_init_tau / calib existed: the missing
    args are their defaults, so the init is accepted (the shipped models are such checkpoints)."""
    from imu_learn.infer.checkpoint import write_checkpoint

    state = load_checkpoint(full_run / "best.pt")
    for k in ("start", "fir_init_tau", "calib"):
        state["model_args"].pop(k)
    old = tmp_path / "old.pt"
    write_checkpoint(old, state)
    assert fit_cli.main(tiny(tmp_path / "cov", 1, "--model.covariance", "true", "--optim.init", str(old),
                             "--optim.trainable", "covariance", "--loss.w_nll", "1.0")) == 0


def test_another_devices_profile_as_the_start_is_named_and_the_ships_line_points_at_a_file(tmp_path, caplog):
    """model.start = TUM-VI's shipped profile on EuRoC's crops: one warning before training (its IMU is unlike
    the training segments: another mounting), and the profile the final line ships is written in the run."""
    import logging

    d = tmp_path / "wrongprof"
    args = [a for a in tiny(d, 1) if a not in ("raw",)]
    args[args.index("--model.start") + 1:args.index("--model.start") + 1] = [
        str(REPO / "models/profiles/tumvi_bmi160/profile.json")]
    with caplog.at_level(logging.WARNING):
        assert fit_cli.main(args) == 0
    assert "another device or mounting" in caplog.text and "tumvi_bmi160" in caplog.text
    res = json.loads((d / "results.json").read_text())
    assert res["ships"] in ("profile", "model") and (d / "profile" / "profile.json").is_file()
