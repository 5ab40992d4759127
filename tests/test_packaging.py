"""The wheel, as a user gets it: ``maturin build --release``, installed in a fresh virtual environment
(no checkout on its path, the working directory outside the repository).

- with no extra (no torch, no gtsam): ``imu-learn --help`` lists the subcommands, ``import
  imu_learn.fuse`` works, and relative data paths resolve from the data root (``IMU_LEARN_DATA``),
  else the working directory, never from a checkout;
- with the ``train`` extra: ``imu-learn refine`` refines a shipped crop with a shipped model, and
  the refined file is byte for byte what the checkout's own build writes.

Needs ``maturin`` and cargo (the build) and pip's index or cache (the dependencies); skipped when the
dependencies cannot be installed (offline without a cache), never when the package itself is wrong.
Those are the slow tests; the fast ones check that ``pyproject.toml`` declares every third-party
module imported by the package and the tests (core: what the torch-free layers import at module level).
"""
from __future__ import annotations

import ast
import importlib.metadata
import os
import re
import shutil
import subprocess
import sys
import venv
from pathlib import Path
from typing import Dict, Iterator, List, Set

import pytest

from crops import CROP_RUN_TOML

try:
    import tomllib
except ImportError:  # Python < 3.11
    import tomli as tomllib

REPO = Path(__file__).resolve().parent.parent
CROPS = REPO / "datasets" / "euroc"
MODEL = REPO / "models" / "euroc_adis16448.pt"
SUBCOMMANDS = ("labels", "fit", "evaluate", "refine", "export", "fuse")
# pip's messages when an index or a wheel cannot be had (offline, no cache): a skip, not a failure
UNAVAILABLE = ("No matching distribution", "Could not find a version", "Failed to establish a new connection",
               "Temporary failure in name resolution", "Network is unreachable", "ProxyError")


def _clean_env(**extra: str) -> Dict[str, str]:
    """The environment without anything that would put the checkout or the dev venv on the path."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "IMU_LEARN_DATA",
                                                              "PYTHONHOME")}
    env.update(extra)
    return env


def _run(cmd: List[str], cwd: Path, timeout: float = 600, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], cwd=cwd, env=_clean_env(**env), capture_output=True, text=True,
                          timeout=timeout)


def _ok(r: subprocess.CompletedProcess) -> str:
    assert r.returncode == 0, f"{r.args} exited {r.returncode}\nstdout:\n{r.stdout[-3000:]}\nstderr:\n{r.stderr[-3000:]}"
    return r.stdout


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    maturin = shutil.which("maturin") or str(Path(sys.executable).parent / "maturin")
    if not Path(maturin).exists() or shutil.which("cargo") is None:
        pytest.skip("maturin or cargo not installed")
    out = tmp_path_factory.mktemp("dist")
    # Same target folder and profile as `maturin develop --release`: only what changed is rebuilt.
    # `maturin build` writes only the wheel (never python/imu_learn/_imu_core*.so of the checkout).
    _ok(_run([maturin, "build", "--release", "--quiet", "--out", out], cwd=REPO))
    (whl,) = out.glob("imu_learn-*.whl")
    return whl


def _venv(where: Path, requirement: str) -> Path:
    """A fresh venv at ``where`` with ``requirement`` pip-installed; its python."""
    venv.EnvBuilder(with_pip=True, clear=True).create(where)
    py = where / "bin" / "python"
    # --no-cache-dir is not used: pip's cache is what makes the 3 GB torch download a one-time cost
    r = _run([py, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", requirement], cwd=where)
    if r.returncode != 0:
        # a half-installed venv (torch's is ~5 GB) is removed at once: pytest keeps its last three
        # temporary folders, and a failed install left behind would fill the disk for the next run
        shutil.rmtree(where, ignore_errors=True)
        if any(s in r.stdout + r.stderr for s in UNAVAILABLE):
            pytest.skip(f"dependencies of {requirement} unavailable: {(r.stdout + r.stderr).strip()[-400:]}")
    _ok(r)
    return py


@pytest.fixture(scope="module")
def bare(wheel, tmp_path_factory) -> Iterator[Path]:
    """A venv with the wheel and its core dependencies only (removed afterwards)."""
    where = tmp_path_factory.mktemp("venv_bare")
    try:
        yield _venv(where, str(wheel))
    finally:
        shutil.rmtree(where, ignore_errors=True)


@pytest.fixture(scope="module")
def data_root(tmp_path_factory) -> Path:
    """A data root outside the repository holding the shipped EuRoC crops (copied)."""
    root = tmp_path_factory.mktemp("data")
    for seq in ("MH_01_easy", "V1_01_easy"):
        shutil.copytree(CROPS / seq, root / "euroc" / seq)
    return root


@pytest.mark.slow
def test_bare_wheel_has_no_torch_and_runs_the_cli(bare, tmp_path):
    bindir = bare.parent
    out = _ok(_run([bindir / "imu-learn", "--help"], cwd=tmp_path))
    assert all(f"\n  {c} " in out for c in SUBCOMMANDS), out
    probe = ("import sys, imu_learn, imu_learn.fuse, imu_learn.data.splits as s; "
             "assert 'torch' not in sys.modules, 'torch imported'; "
             "print(imu_learn.__file__); print(s.checkout_root())")
    lines = _ok(_run([bare, "-c", probe], cwd=tmp_path)).split()
    assert Path(lines[0]).is_relative_to(bare.parent.parent), f"imu_learn imported from {lines[0]}, not the venv"
    assert lines[1] == "None", "an installed wheel must not fall back to a checkout"
    r = _run([bare, "-c", "import torch"], cwd=tmp_path)
    assert r.returncode != 0, "torch is installed without the train extra"


SPLIT_PROBE = """
import json, sys
from imu_learn.train.config import load_config
from imu_learn.data.splits import make_split
s = make_split(load_config(sys.argv[1]).data)
print(json.dumps([s.record["data_root"], s.record["test"][0]["path"]]))
"""


@pytest.mark.slow
def test_bare_wheel_resolves_relative_data_paths_without_a_checkout(bare, data_root, tmp_path):
    import json

    cfg = tmp_path / "wheel.toml"
    cfg.write_text(CROP_RUN_TOML.format(data_root=""))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    # from the data root (IMU_LEARN_DATA), the working directory elsewhere
    got = json.loads(_ok(_run([bare, "-c", SPLIT_PROBE, cfg], cwd=elsewhere, IMU_LEARN_DATA=str(data_root))))
    assert got == [str(data_root.resolve()), str(data_root.resolve() / "euroc" / "V1_01_easy")]
    # no data root: from the working directory
    got = json.loads(_ok(_run([bare, "-c", SPLIT_PROBE, cfg], cwd=data_root)))
    assert got[0] is None and got[1] == "euroc/V1_01_easy"
    # neither: a one-line DataPathError naming what was tried, nothing from a checkout
    r = _run([bare, "-c", SPLIT_PROBE, cfg], cwd=elsewhere)
    assert r.returncode != 0 and "DataPathError" in r.stderr, r.stderr
    assert str(REPO) not in r.stderr, f"the checkout was tried:\n{r.stderr[-1500:]}"


@pytest.fixture(scope="module")
def trained(wheel, tmp_path_factory) -> Iterator[Path]:
    """A venv with the wheel and its train extra (torch, ~5 GB installed with the CUDA build: removed
    afterwards; pip's cache, where it keeps downloads, serves torch after the first time)."""
    where = tmp_path_factory.mktemp("venv_train")
    try:
        yield _venv(where, f"{wheel}[train]")
    finally:
        shutil.rmtree(where, ignore_errors=True)


@pytest.mark.slow
def test_wheel_refines_a_shipped_crop_with_a_shipped_model(trained, data_root, tmp_path):
    env = {"OMP_NUM_THREADS": "1", "CUDA_VISIBLE_DEVICES": ""}
    # relative --input from the working directory (the data root), as a user outside a checkout
    r = _ok(_run([trained.parent / "imu-learn", "refine", "--checkpoint", MODEL, "--input", "euroc/MH_01_easy",
                  "--out", tmp_path / "wheel", "--device", "cpu", "--quiet"], cwd=data_root, **env))
    assert "written to" in r, r
    # the checkout's own build (the interpreter running these tests) writes the same bytes
    _ok(_run([sys.executable, "-m", "imu_learn.refine", "--checkpoint", MODEL, "--input",
              data_root / "euroc" / "MH_01_easy", "--out", tmp_path / "checkout", "--device", "cpu", "--quiet"],
             cwd=REPO, **env))
    # summary.json names the paths each was given: the refined files must agree byte for byte
    wheel_files = sorted(p.relative_to(tmp_path / "wheel") for p in (tmp_path / "wheel").rglob("*")
                         if p.is_file() and p.name != "summary.json")
    assert wheel_files, "refine wrote nothing"
    for rel in wheel_files:
        assert (tmp_path / "wheel" / rel).read_bytes() == (tmp_path / "checkout" / rel).read_bytes(), \
            f"{rel}: the wheel's refine differs from the checkout's"


# --- dependencies declared once: pyproject.toml covers every import ------------------------------

PROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
# Layers that must import with the core dependencies alone (no extra): what they import at module level.
CORE_LAYERS = ("data", "core", "util", "cli", "fuse", "settings.py", "errors.py", "__init__.py")


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _names(reqs: List[str]) -> Set[str]:
    return {_norm(re.match(r"\s*([A-Za-z0-9_.-]+)", r)[1]) for r in reqs}


def _expand(extra: str) -> List[str]:
    """The requirements of ``imu-learn[extra]``: core + the extra's, following ``imu-learn[...]``."""
    own, reqs, todo, seen = _norm(PROJECT["name"]), list(PROJECT["dependencies"]), [extra], set()
    while todo:
        e = todo.pop()
        if e in seen:
            continue
        seen.add(e)
        for r in PROJECT["optional-dependencies"][e]:
            m = re.match(r"\s*([A-Za-z0-9_.-]+)\s*\[([^\]]*)\]", r)
            if m and _norm(m[1]) == own:
                todo += [x.strip() for x in m[2].split(",")]
            else:
                reqs.append(r)
    return reqs


def _imports(files: List[Path], module_level_only: bool = False) -> Dict[str, str]:
    """Top-level module name -> one ``file:line`` importing it (absolute imports)."""
    out: Dict[str, str] = {}
    for f in files:
        tree = ast.parse(f.read_text(), str(f))
        nodes = tree.body if module_level_only else ast.walk(tree)
        for n in nodes:
            if isinstance(n, ast.Import):
                mods = [a.name for a in n.names]
            elif isinstance(n, ast.ImportFrom) and n.level == 0 and n.module:
                mods = [n.module]
            else:
                continue
            for m in mods:
                out.setdefault(m.split(".")[0], f"{f.relative_to(REPO)}:{n.lineno}")
    return out


def _third_party(mods: Dict[str, str]) -> Dict[str, str]:
    local = {p.stem for d in ("tests", "bench") for p in (REPO / d).glob("*.py")}
    return {m: at for m, at in mods.items()
            if m not in sys.stdlib_module_names and m not in local and m != "imu_learn"}


def _declared(module: str, reqs: List[str]) -> bool:
    dists = importlib.metadata.packages_distributions().get(module, []) + [module]
    return bool(_names(reqs) & {_norm(d) for d in dists})


@pytest.mark.parametrize("extra", sorted(PROJECT["optional-dependencies"]))
def test_every_extra_expands(extra):
    assert _expand(extra), extra


def test_every_import_of_the_package_and_tests_is_declared():
    files = sorted((REPO / "python" / "imu_learn").rglob("*.py")) + sorted((REPO / "tests").glob("*.py"))
    missing = {m: at for m, at in _third_party(_imports(files)).items() if not _declared(m, _expand("all"))}
    assert not missing, f"imported but not in pyproject.toml's dependencies or extras: {missing}"


def test_torch_free_layers_need_only_the_core_dependencies():
    pkg = REPO / "python" / "imu_learn"
    files = [f for layer in CORE_LAYERS for f in ([pkg / layer] if layer.endswith(".py")
                                                   else sorted((pkg / layer).rglob("*.py")))]
    core = list(PROJECT["dependencies"])
    missing = {m: at for m, at in _third_party(_imports(files, module_level_only=True)).items()
               if not _declared(m, core)}
    assert not missing, f"imported at module level by a torch-free layer but not a core dependency: {missing}"


def test_tests_extra_covers_what_the_tests_import():
    files = sorted((REPO / "tests").glob("*.py"))
    missing = {m: at for m, at in _third_party(_imports(files)).items() if not _declared(m, _expand("test"))}
    assert not missing, f"the tests import what the test extra does not install: {missing}"
