"""The data root: relative data.roots paths are taken from it; --data.data_root beats the
environment variable IMU_LEARN_DATA, which beats the config file's value; a missing recording is a
one-line error that says how to set it."""
import json
from pathlib import Path

import pytest

from crops import CROP_RUN_TOML
from imu_learn.cli import fit as fit_cli
from imu_learn.data.splits import DataPathError, make_split
from imu_learn.eval import run as ev
from imu_learn.train.config import ConfigError, load_config

REPO = Path(__file__).resolve().parent.parent
CROPS = REPO / "datasets" / "euroc"
ENV = "IMU_LEARN_DATA"

# The shipped crops, addressed relative to a data root (a folder that holds euroc/<SEQ>).


def _root(base: Path) -> Path:
    """A data root at ``base`` holding the shipped crops (symlinked)."""
    (base / "euroc").mkdir(parents=True)
    for seq in ("MH_01_easy", "V1_01_easy"):
        (base / "euroc" / seq).symlink_to(CROPS / seq, target_is_directory=True)
    return base


@pytest.fixture
def roots(tmp_path, monkeypatch):
    """(good data root, a data root without the recordings, a config file without data_root);
    the working directory is elsewhere, so nothing resolves from it or by accident."""
    monkeypatch.delenv(ENV, raising=False)
    good = _root(tmp_path / "data")
    empty = tmp_path / "empty"
    empty.mkdir()
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    cfg = tmp_path / "dr.toml"
    cfg.write_text(CROP_RUN_TOML.format(data_root=""))
    return good, empty, cfg


def test_env_var_sets_the_data_root(roots, monkeypatch):
    good, _, cfg = roots
    with pytest.raises(DataPathError):  # without a data root the relative paths are found nowhere
        make_split(load_config(cfg).data)
    monkeypatch.setenv(ENV, str(good))
    c = load_config(cfg)
    assert c.data.data_root == str(good)
    split = make_split(c.data)
    assert [s.name.split("[")[0] for s in split.train] == ["MH_01_easy"] and split.test
    assert split.record["data_root"] == str(good.resolve())
    test_row = split.record["test"][0]
    assert test_row["path"] == str(good.resolve() / "euroc" / "V1_01_easy")
    assert test_row["groundtruth_path"] == str(good.resolve() / "euroc" / "V1_01_easy" / "groundtruth_state_20hz.csv")


def test_cli_beats_env(roots, monkeypatch):
    good, empty, cfg = roots
    monkeypatch.setenv(ENV, str(empty))
    with pytest.raises(DataPathError, match=str(empty)):
        make_split(load_config(cfg).data)
    c = load_config(cfg, ["--data.data_root", str(good)])
    assert c.data.data_root == str(good)
    assert make_split(c.data).record["data_root"] == str(good.resolve())
    # the same in imu_learn.eval.run (its [data] goes to the same DataConfig)
    ecfg = cfg.parent / "eval_dr.toml"
    ecfg.write_text(f'base = "{cfg.name}"\nmethods = ["raw"]\n')
    assert ev.load_eval_config(ecfg).run.data.data_root == str(empty)
    assert ev.load_eval_config(ecfg, ["--data.data_root", str(good)]).run.data.data_root == str(good)


def test_config_value_and_env_over_it(roots, monkeypatch):
    good, empty, cfg = roots
    cfg.write_text(CROP_RUN_TOML.format(data_root=f'data_root = "{good}"'))
    c = load_config(cfg)
    assert c.data.data_root == str(good)
    assert make_split(c.data).record["data_root"] == str(good.resolve())
    monkeypatch.setenv(ENV, str(empty))
    assert load_config(cfg).data.data_root == str(empty)  # the environment beats the file
    monkeypatch.setenv(ENV, "")  # empty: unset
    assert load_config(cfg).data.data_root == str(good)


def test_relative_data_root_from_the_working_directory(roots, monkeypatch):
    good, _, cfg = roots
    monkeypatch.chdir(good.parent)
    c = load_config(cfg, ["--data.data_root", good.name])
    assert make_split(c.data).record["data_root"] == str(good.resolve())


def test_missing_recording_is_a_one_line_error(roots, monkeypatch, capsys):
    good, empty, cfg = roots
    monkeypatch.setenv(ENV, str(empty))
    with pytest.raises(DataPathError) as ei:
        make_split(load_config(cfg).data)
    msg = str(ei.value)
    assert isinstance(ei.value, ConfigError) and isinstance(ei.value, FileNotFoundError)
    assert "\n" not in msg
    assert msg.startswith("data.roots[0].path: 'euroc/MH_01_easy' not found")
    assert str(empty.resolve() / "euroc" / "MH_01_easy") in msg  # the path tried under the data root
    assert "IMU_LEARN_DATA" in msg and "--data-root" in msg
    # no data root at all: the message says so
    monkeypatch.delenv(ENV)
    with pytest.raises(DataPathError, match=r"no data root set.*IMU_LEARN_DATA=DIR or --data-root DIR"):
        make_split(load_config(cfg).data)
    # a missing ground-truth file names its own key
    monkeypatch.setenv(ENV, str(good))
    c = load_config(cfg, ["--data.roots", '[{path = "euroc/MH_01_easy"}, '
                          '{path = "euroc/V1_01_easy", groundtruth = "euroc/V1_01_easy/nope.csv"}]'])
    with pytest.raises(DataPathError, match=r"^data\.roots\[1\]\.groundtruth: 'euroc/V1_01_easy/nope\.csv' not found"):
        make_split(c.data)
    # the command: exit status 2 and the one line
    monkeypatch.setenv(ENV, str(empty))
    capsys.readouterr()
    assert fit_cli.main(["--config", str(cfg), "--out", str(good.parent / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "data.roots[0].path" in err[0] and "IMU_LEARN_DATA" in err[0], err


def test_split_json_records_the_data_root(roots, monkeypatch):
    from imu_learn.data.splits import write_split

    good, _, cfg = roots
    monkeypatch.setenv(ENV, str(good))
    out = good.parent / "split.json"
    write_split(make_split(load_config(cfg).data), out)
    assert json.loads(out.read_text())["data_root"] == str(good.resolve())


def test_default_config_keeps_working_with_a_data_root_set(roots, monkeypatch):
    """The default run's crops (datasets/..., from the repository) still resolve when a data root
    is set that does not hold them; with none set they resolve as before."""
    good, _, _ = roots
    monkeypatch.setenv(ENV, str(good))
    c = load_config()
    assert c.data.data_root == str(good)
    split = make_split(c.data)
    assert split.record["test"][0]["path"] == str(REPO / "datasets" / "euroc" / "V1_01_easy")
    monkeypatch.delenv(ENV)
    assert make_split(load_config().data).record["data_root"] is None


@pytest.mark.parametrize("cli, env, config, expected", [
    ("/cli", "/env", "/cfg", "/cli"),
    (None, "/env", "/cfg", "/env"),
    (None, "", "/cfg", "/cfg"),  # an empty variable is no value
    (None, None, "/cfg", "/cfg"),
    (None, None, None, ""),
    ("/cli", None, None, "/cli"),
])
def test_one_data_root_rule(monkeypatch, cli, env, config, expected):
    """resolve_data_root: the command line, then IMU_LEARN_DATA, then the config (every config calls it)."""
    from imu_learn.data.config import resolve_data_root

    if env is None:
        monkeypatch.delenv(ENV, raising=False)
    else:
        monkeypatch.setenv(ENV, env)
    assert resolve_data_root(cli, config) == expected


def test_training_and_evaluate_configs_follow_the_rule(roots, monkeypatch):
    """The fit config and the evaluate config (which embeds one) resolve the data root alike."""
    good, empty, _ = roots
    monkeypatch.setenv(ENV, str(empty))
    base = {"data": {"data_root": str(good)}}
    from imu_learn.train.config import build_config

    assert build_config(base, {}).data.data_root == str(empty)  # the variable beats the config
    assert build_config(base, {"data.data_root": "/cli"}).data.data_root == "/cli"  # the command line beats both
    monkeypatch.delenv(ENV)
    assert build_config(base, {}).data.data_root == str(good)
    res = ev.load_eval_config(None, ["--data.data_root", "/cli"])
    assert res.run.data.data_root == "/cli"


@pytest.mark.parametrize("name", ["fuse_euroc.toml", "fuse_gnss_drive.toml"])
def test_fusion_configs_follow_the_rule(tmp_path, monkeypatch, name):
    """Both kinds of fusion config resolve the data root as the training configs do."""
    from imu_learn.fuse.experiments import config as fuse_config
    from imu_learn.fuse.experiments import gnss

    load = gnss.load_config if "gnss" in name else fuse_config.load
    text = (REPO / "configs" / name).read_text()
    cfg_file = tmp_path / name
    cfg_file.write_text('data_root = "/cfg"\n' + "\n".join(
        line for line in text.splitlines() if not line.startswith("data_root")))
    monkeypatch.setenv(ENV, "/env")
    assert load(cfg_file, None).data_root == "/env"  # the variable beats the config
    assert load(cfg_file, "/cli").data_root == "/cli"  # the command line beats both
    monkeypatch.delenv(ENV)
    assert load(cfg_file, None).data_root == "/cfg"
    assert str(load(cfg_file, None).root()) == "/cfg"
