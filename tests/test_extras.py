"""A stage whose optional dependency is missing stops at once with one line naming the extra
(imu_learn.util.extras), not with a ModuleNotFoundError traceback after the work."""
from __future__ import annotations

import subprocess
import sys

import pytest

from imu_learn.errors import MissingExtraError
from imu_learn.util.extras import EXTRAS, require, require_extra


def test_require_names_the_package_and_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # what an absent package looks like to import
    with pytest.raises(MissingExtraError) as e:
        require_extra("eval", "imu-learn evaluate")
    assert str(e.value) == "imu-learn evaluate needs matplotlib, the eval extra: pip install 'imu-learn[eval]'"
    assert require("numpy", "eval", "x").__name__ == "numpy"


def test_every_extra_names_packages_of_pyproject():
    assert set(EXTRAS) <= {"train", "fuse", "eval", "export", "bags"}


@pytest.mark.parametrize("blocked", ["torch", "polars", "matplotlib"])
def test_evaluate_without_its_extra_is_one_line_before_any_work(tmp_path, blocked):
    out = tmp_path / "report"
    code = (f"import sys; sys.modules[{blocked!r}] = None\n"
            "from imu_learn.cli import main\n"
            f"sys.exit(main(['evaluate', '--methods', 'raw', '--out', {str(out)!r}]))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr[-2000:]
    assert r.stderr.splitlines() == [f"imu-learn evaluate: error: MissingExtraError: imu-learn evaluate needs "
                                     f"{blocked}, the eval extra: pip install 'imu-learn[eval]'"]
    assert not out.exists()  # nothing fitted, nothing written


def test_the_library_entry_checks_too(tmp_path, monkeypatch):
    """run_evaluation (what the command calls) checks the eval extra itself, before fitting anything."""
    from imu_learn.eval.run import load_eval_config, run_evaluation

    res = load_eval_config(None, [])
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(MissingExtraError, match=r"evaluate needs matplotlib, the eval extra"):
        run_evaluation(res, ["raw"], tmp_path / "report")
    assert not (tmp_path / "report").exists()


def test_a_ctrl_c_inside_an_extensions_import_is_a_ctrl_c(monkeypatch):
    """A C extension interrupted while it initialises (gtsam under pybind11) raises ImportError
    ("initialization failed") from the KeyboardInterrupt: that is Ctrl-C, not "install the extra"."""
    import importlib

    from imu_learn.util import extras

    def interrupted_import(name, package=None):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:
            raise ImportError("initialization failed") from e

    monkeypatch.setattr(importlib, "import_module", interrupted_import)
    with pytest.raises(KeyboardInterrupt):
        require("gtsam", "fuse", "imu-learn navigate")
    with pytest.raises(KeyboardInterrupt):
        extras.optional("matplotlib")

    def missing(name, package=None):
        raise ModuleNotFoundError(f"No module named {name!r}")

    monkeypatch.setattr(importlib, "import_module", missing)
    assert extras.optional("matplotlib") is None
    with pytest.raises(MissingExtraError):
        require("gtsam", "fuse", "imu-learn navigate")
