"""The one command line: ``imu-learn <command>``. Every subcommand reports a known error as exactly one
line ``imu-learn <cmd>: error: <Class>: <message>`` on stderr with exit status 2 (a missing input
file, a bad config key or option value, a malformed input file), Ctrl-C exits 130, any other
exception is a traceback, ``--traceback`` re-raises, ``--quiet`` silences progress and info.
Nothing here trains: every case fails before training starts."""
from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import pytest

from imu_learn.cli import COMMANDS, main

REPO = Path(__file__).resolve().parents[1]
CROP = REPO / "datasets" / "euroc" / "MH_01_easy"
MODEL = REPO / "models" / "euroc_adis16448.pt"
IMU_CSV = Path("mav0") / "imu0" / "data.csv"
ENV = dict(os.environ, OMP_NUM_THREADS="1", RAYON_NUM_THREADS="1")


def run(argv, capsys):
    """(exit status, stdout, stderr) of ``imu-learn ARGV`` run in this process."""
    rc = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def assert_error(argv, capsys, expected):
    rc, _out, err = run(argv, capsys)
    assert (rc, err) == (2, expected + "\n")


@pytest.fixture(scope="module")
def bad_crop(tmp_path_factory):
    """A copy of the MH_01_easy crop whose IMU CSV has a non-numeric field (line 4, column 3)."""
    root = tmp_path_factory.mktemp("bad") / "euroc"
    shutil.copytree(CROP, root / "MH_01_easy")
    csv = root / "MH_01_easy" / IMU_CSV
    lines = csv.read_text().split("\n")
    cells = lines[3].split(",")
    cells[2] = "abc"
    lines[3] = ",".join(cells)
    csv.write_text("\n".join(lines))
    return root


def not_numeric(crop_root: Path) -> str:
    return (f'NotNumericError: {crop_root / "MH_01_easy" / IMU_CSV}:4:3: field "w_RS_S_y [rad s^-1]" = "abc" '
            f"is not a number")


def missing(path: Path) -> str:
    return f"FileNotFoundError: {path}: No such file or directory"


def fit_config(tmp_path: Path, crop_root: Path) -> Path:
    cfg = tmp_path / "fit.toml"
    cfg.write_text(f"""
[data.split]
train = ["MH_01_easy[0:0.6]"]
val = ["MH_01_easy[0.6:0.8]"]
test = ["MH_01_easy[0.8:1]"]
[[data.roots]]
path = "{crop_root / 'MH_01_easy'}"
format = "euroc"
""")
    return cfg


def known(cls) -> str:
    return ", ".join(sorted(f.name for f in fields(cls)))


# ---- the command and its subcommands --------------------------------------------------------

def test_help_lists_every_subcommand():
    r = subprocess.run([sys.executable, "-m", "imu_learn.cli", "--help"], capture_output=True, text=True, env=ENV,
                       timeout=120)
    assert r.returncode == 0 and r.stderr == ""
    listed = [line.split()[0] for line in r.stdout.split("commands:\n")[1].split("\n\n")[0].splitlines()]
    assert listed == ["labels", "fit", "evaluate", "refine", "export", "fuse", "navigate", "groundtruth", "calibrate", "checkpoint"] == list(COMMANDS)


@pytest.mark.parametrize("name", list(COMMANDS))
def test_every_subcommand_has_help_with_the_common_flags(name, capsys):
    with pytest.raises(SystemExit) as e:
        main([name, "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith(f"usage: imu-learn {name} ")
    for flag in ("--quiet", "--traceback"):
        assert flag in text
    if name in ("fit", "evaluate", "fuse", "labels"):
        assert "--data-root DIR" in text
    for old in ("--run-dir", "--output", "--root ", "--no-progress", "--data.data_root"):
        assert old not in text


def test_unknown_subcommand(capsys):
    rc, out, err = run(["nope"], capsys)
    assert rc == 2 and err.startswith("imu-learn: error: unknown command 'nope'\n")


def test_pyproject_declares_the_console_script():
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert project["scripts"] == {"imu-learn": "imu_learn.cli:entry"}


def test_a_ctrl_c_once_the_command_finished_does_not_fail_the_run():
    """A Ctrl-C after a command finished (its outputs complete and said so) made the exit 130 without a word; the
    console entry ignores it while the process exits (here sent by the process to itself as it exits)."""
    code = ("import atexit, os, signal, sys; sys.argv = ['imu-learn', '--help']; "
            "atexit.register(lambda: os.kill(os.getpid(), signal.SIGINT)); "
            "from imu_learn.cli import entry; entry()")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == "", (done.returncode, done.stderr)
    assert done.stdout.startswith("usage: imu-learn <command>")


@pytest.mark.parametrize("stage", ["fit", "refine", "evaluate", "labels", "export"])
def test_python_dash_m_stage_is_the_same_command(stage):
    r = subprocess.run([sys.executable, "-m", f"imu_learn.{stage}", "--help"], capture_output=True, text=True,
                       env=ENV, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith(f"usage: imu-learn {stage} "), r.stderr


# ---- (a) a missing input file ----------------------------------------------------------------

def test_missing_input_file(tmp_path, capsys):
    gone = tmp_path / "missing"
    assert_error(["labels", "euroc", "--dataset-dir", gone, "--out", tmp_path / "c"], capsys, f"imu-learn labels: error: {missing(gone)}")
    assert_error(["labels", "euroc", "--data-root", tmp_path, "--out", tmp_path / "c"], capsys,
                 f"imu-learn labels: error: {missing(tmp_path / 'euroc')}")
    toml = tmp_path / "missing.toml"
    assert_error(["fit", "--config", toml], capsys, f"imu-learn fit: error: {missing(toml)}")
    assert_error(["evaluate", "--config", toml], capsys, f"imu-learn evaluate: error: {missing(toml)}")
    assert_error(["fuse", "--config", toml], capsys, f"imu-learn fuse: error: {missing(toml)}")
    pt = tmp_path / "missing.pt"
    assert_error(["refine", "--checkpoint", pt, "--input", CROP, "--out", tmp_path / "o"], capsys,
                 f"imu-learn refine: error: {missing(pt)}")
    assert_error(["export", "--checkpoint", pt, "--out", tmp_path / "e"], capsys, f"imu-learn export: error: {missing(pt)}")
    assert_error(["checkpoint", "info", pt], capsys, f"imu-learn checkpoint: error: {missing(pt)}")
    assert not (tmp_path / "o").exists() and not (tmp_path / "e").exists()


# ---- (b) a bad config key, or a bad option value where the command has no config -------------

def test_bad_config_key_or_option_value(tmp_path, capsys):
    from imu_learn.eval.run import EvalSettings
    from imu_learn.fuse.experiments.config import FuseConfig
    from imu_learn.train.config import OptimConfig

    assert_error(["labels", "euroc", "--dataset-dir", CROP.parent, "--out", tmp_path / "c", "--window", "0", "-q"], capsys,
                 "imu-learn labels: error: InvalidInputError: window must be at least 1 sample")
    assert_error(["fit", "--out", tmp_path / "run", "--optim.nope", "1"], capsys,
                 f"imu-learn fit: error: ConfigError: --optim.nope: unknown key (known here: {known(OptimConfig)})")
    assert_error(["fit", "--out", tmp_path / "run", "--data.data_root", tmp_path], capsys,
                 "imu-learn fit: error: ConfigError: --data.data_root: set the data root with --data-root DIR "
                 "(or IMU_LEARN_DATA)")
    assert not (tmp_path / "run").exists()
    assert_error(["evaluate", "--out", tmp_path / "r", "--eval.nope", "1"], capsys,
                 f"imu-learn evaluate: error: ConfigError: --eval.nope: unknown key (known in eval: {known(EvalSettings)})")
    cfg = tmp_path / "fuse.toml"
    cfg.write_text('name = "t"\nnope = 1\n')
    assert_error(["fuse", "--config", cfg], capsys,
                 f"imu-learn fuse: error: ConfigError: nope: unknown key (known: {known(FuseConfig)})")
    assert_error(["fuse", "--config", cfg, "--checkpoint", MODEL], capsys,
                 "imu-learn fuse: error: ConfigError: --checkpoint: only with --online")
    assert_error(["refine", "--checkpoint", MODEL, "--input", CROP, "--out", tmp_path / "o", "--fill-covariance"], capsys,
                 f"imu-learn refine: error: InvalidInputError: {MODEL}: no covariance head (trained with "
                 f"model.covariance = false); --fill-covariance needs one, e.g. models/euroc_adis16448_cov.pt")
    assert_error(["export", "--checkpoint", MODEL, "--out", tmp_path / "e", "--window", "1"], capsys,
                 "imu-learn export: error: InvalidInputError: --window must be >= 2, got 1")
    assert_error(["checkpoint", "strip", MODEL, MODEL], capsys,
                 f"imu-learn checkpoint: error: CheckpointError: {MODEL}: is the source checkpoint; write the "
                 f"stripped copy elsewhere")
    assert not (tmp_path / "o").exists() and not (tmp_path / "e").exists()


def test_argparse_errors_exit_2_with_the_command_name(capsys):
    with pytest.raises(SystemExit) as e:
        main(["export", "--checkpoint", str(MODEL)])
    assert e.value.code == 2
    err = capsys.readouterr().err.splitlines()
    assert err == ["imu-learn export: error: the following arguments are required: --out (imu-learn export --help lists "
                   "the options)"], err  # one line, not the usage block


# ---- (c) a malformed input file --------------------------------------------------------------

def test_malformed_input_file(tmp_path, bad_crop, capsys):
    line = not_numeric(bad_crop)
    assert_error(["labels", "euroc", "--dataset-dir", bad_crop, "--out", tmp_path / "c", "--quiet"], capsys,
                 f"imu-learn labels: error: {line}")
    assert_error(["labels", "euroc", "--data-root", bad_crop.parent, "--out", tmp_path / "c", "--quiet"], capsys,
                 f"imu-learn labels: error: {line}")
    fit_cfg = fit_config(tmp_path, bad_crop)
    assert_error(["fit", "--config", fit_cfg, "--out", tmp_path / "run", "--quiet"], capsys, f"imu-learn fit: error: {line}")
    ev = tmp_path / "eval.toml"
    ev.write_text(f'name = "t"\nbase = "{fit_cfg}"\nmethods = ["raw"]\n')
    assert_error(["evaluate", "--config", ev, "--out", tmp_path / "report", "--quiet"], capsys,
                 f"imu-learn evaluate: error: {line}")
    assert_error(["refine", "--checkpoint", MODEL, "--input", bad_crop / "MH_01_easy", "--out", tmp_path / "o",
                  "--quiet"], capsys, f"imu-learn refine: error: {line}")
    assert not (tmp_path / "o").exists()
    bad_pt = tmp_path / "bad.pt"
    bad_pt.write_bytes(b"PK\x03\x04 not a zip")
    rc, _out, err = run(["export", "--checkpoint", bad_pt, "--out", tmp_path / "e"], capsys)
    assert rc == 2 and err.count("\n") == 1
    assert err.startswith(f"imu-learn export: error: CheckpointError: {bad_pt}: not a readable checkpoint (")
    rc, _out, err2 = run(["checkpoint", "info", bad_pt], capsys)
    assert rc == 2 and err2 == err.replace("imu-learn export:", "imu-learn checkpoint:")


def test_malformed_input_file_fuse(tmp_path, bad_crop, capsys):
    pytest.importorskip("gtsam")
    cfg = tmp_path / "fuse.toml"
    cfg.write_text(f'name = "t"\ninputs = ["raw"]\nseeds = [0]\n[[recordings]]\npath = "{bad_crop / "MH_01_easy"}"\n'
                   'format = "euroc"\n[[scenarios]]\nname = "gnss"\nkind = "position"\n')
    assert_error(["fuse", "--config", cfg, "--out", tmp_path / "fused"], capsys,
                 f"imu-learn fuse: error: {not_numeric(bad_crop)}")
    # fuse's data root: relative recording paths resolve under --data-root
    cfg.write_text('name = "t"\ninputs = ["raw"]\nseeds = [0]\n[[recordings]]\npath = "euroc/MH_01_easy"\n'
                   'format = "euroc"\n[[scenarios]]\nname = "gnss"\nkind = "position"\n')
    assert_error(["fuse", "--config", cfg, "--data-root", bad_crop.parent, "--out", tmp_path / "fused"], capsys,
                 f"imu-learn fuse: error: {not_numeric(bad_crop)}")


# ---- one rule for everything else ------------------------------------------------------------

def test_an_unknown_exception_is_a_traceback_not_a_line(tmp_path, monkeypatch):
    import imu_learn.infer.exporters as export

    def boom(*a, **k):
        raise RuntimeError("a bug")

    monkeypatch.setattr(export, "export", boom)
    with pytest.raises(RuntimeError, match="a bug"):
        main(["export", "--checkpoint", str(MODEL), "--out", str(tmp_path / "e")])


def test_an_unknown_exception_prints_the_traceback_through_python_dash_m(tmp_path):
    # a directory where a checkpoint file is expected: whatever torch raises, it is either a known
    # error (one line) or a traceback, never a swallowed bug; refine no longer catches Exception
    code = ("import sys, imu_learn.infer.exporters as e\n"
            "def boom(*a, **k): raise RuntimeError('a bug')\n"
            "e.export = boom\n"
            "from imu_learn.cli import main\n"
            f"sys.exit(main(['export', '--checkpoint', {str(MODEL)!r}, '--out', {str(tmp_path / 'e')!r}]))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=120)
    assert r.returncode == 1 and "Traceback (most recent call last)" in r.stderr
    assert r.stderr.strip().splitlines()[-1] == "RuntimeError: a bug"


def test_ctrl_c_exits_130_and_says_what_was_kept(tmp_path, monkeypatch, capsys):
    import imu_learn.data.label_builder as labels

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(labels, "build_cache", interrupted)
    out = tmp_path / "c"
    rc, stdout, err = run(["labels", "euroc", "--out", out], capsys)
    assert (rc, stdout, err) == (130, "", f"imu-learn labels: interrupted; finished recordings are kept in {out}; "
                                          f"run again to resume\n")
    import imu_learn.infer.exporters as export

    monkeypatch.setattr(export, "export", interrupted)
    rc, stdout, err = run(["export", "--checkpoint", MODEL, "--out", tmp_path / "e"], capsys)
    assert (rc, err) == (130, "imu-learn export: interrupted\n")


def test_traceback_flag_reraises_a_known_error(tmp_path, capsys):
    from imu_learn.errors import ConfigError, InvalidInputError

    for argv, cls in [
        (["checkpoint", "info", str(tmp_path / "missing.pt")], FileNotFoundError),
        (["export", "--checkpoint", str(MODEL), "--out", str(tmp_path / "e"), "--window", "1"], InvalidInputError),
        (["fit", "--optim.nope", "1"], ConfigError),
        (["evaluate", "--eval.nope", "1"], ConfigError),
        (["labels", "euroc", "--dataset-dir", str(tmp_path / "missing")], FileNotFoundError),
        (["refine", "--checkpoint", str(tmp_path / "x.pt"), "--input", str(CROP), "--out", str(tmp_path / "o")],
         FileNotFoundError),
        (["fuse", "--config", str(tmp_path / "missing.toml")], FileNotFoundError),
    ]:
        with pytest.raises(cls):
            main([*argv, "--traceback"])
    assert capsys.readouterr().err == ""


def test_quiet_turns_progress_and_info_off(tmp_path, monkeypatch, capsys):
    """The wiring, with a stand-in build_cache that logs at info and warning and draws a bar."""
    import imu_learn.data.label_builder as labels

    def fake(dataset, root, out, *a, progress=True, **k):
        from tqdm import tqdm

        log = logging.getLogger("imu_learn.data.label_builder")
        log.info("reading %s", root)
        for _ in tqdm(range(3), desc="fake bar", disable=not progress, file=sys.stderr):
            pass
        log.warning("something odd")
        return {"recordings": []}

    monkeypatch.setattr(labels, "build_cache", fake)
    out = tmp_path / "c"
    rc, stdout, err = run(["labels", "euroc", "--dataset-dir", CROP.parent, "--out", out], capsys)
    assert rc == 0 and stdout == f"cache: {out} (format v{labels.CACHE_VERSION})\n"
    lines = err.splitlines()
    assert lines[0] == f"imu-learn labels: reading {CROP.parent}" and "fake bar" in err
    assert lines[-1] == "imu-learn labels: warning: something odd"
    rc, stdout2, err = run(["labels", "euroc", "--dataset-dir", CROP.parent, "--out", out, "--quiet"], capsys)
    assert rc == 0 and stdout2 == stdout  # results still on stdout
    assert err == "imu-learn labels: warning: something odd\n"
    # the logger is left as it was: a library call after the command prints nothing of its own
    assert not [h for h in logging.getLogger("imu_learn").handlers if type(h).__name__ == "_StderrHandler"]


def test_quiet_on_a_real_run(tmp_path, capsys):
    out = tmp_path / "c"
    rc, stdout, err = run(["labels", "euroc", "--dataset-dir", CROP.parent, "--out", out, "--window", "100",
                           "--stride", "100"], capsys)
    assert rc == 0 and "labels euroc" in err  # the progress bar, on stderr
    assert stdout.splitlines()[-1] == f"cache: {out} (format v{__import__('imu_learn.data.cache').data.cache.CACHE_VERSION})"
    rc, stdout2, err = run(["labels", "euroc", "--dataset-dir", CROP.parent, "--out", tmp_path / "c2", "--window",
                            "100", "--stride", "100", "--quiet"], capsys)
    assert rc == 0 and err == "" and stdout2.replace(str(tmp_path / "c2"), str(out)) == stdout
