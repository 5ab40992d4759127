"""bench/ holds benchmarks only, experiments/ the scripts behind the docs' tables, and neither is
imported by the tests nor imports them (what both share lives in the package). Checked on the
source (ast), function-local imports and sys.path edits included."""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Iterator, List, Set, Tuple

REPO = Path(__file__).resolve().parent.parent
TESTS, BENCH, EXPERIMENTS = REPO / "tests", REPO / "bench", REPO / "experiments"


def scripts(folder: Path) -> List[Path]:
    return sorted(folder.glob("*.py"))


def stems(folder: Path) -> Set[str]:
    return {p.stem for p in scripts(folder)}


def imports(path: Path) -> Iterator[Tuple[str, int]]:
    """(top-level module, line) of every absolute import in the file, at any depth."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name.split(".")[0], node.lineno
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module.split(".")[0], node.lineno


def path_edits(path: Path) -> Iterator[Tuple[Set[str], int]]:
    """(string constants in the call, line) of every ``sys.path.<method>(...)`` call."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and isinstance(node.func.value, ast.Attribute) and node.func.value.attr == "path"
                and isinstance(node.func.value.value, ast.Name) and node.func.value.value.id == "sys"):
            consts = {c.value for c in ast.walk(node) if isinstance(c, ast.Constant) and isinstance(c.value, str)}
            yield consts, node.lineno


def offences(files: List[Path], modules: Set[str], folders: Set[str]) -> List[str]:
    bad = []
    for f in files:
        rel = f.relative_to(REPO)
        bad += [f"{rel}:{line} imports {m}" for m, line in imports(f) if m in modules]
        bad += [f"{rel}:{line} puts {sorted(c & folders)} on sys.path" for c, line in path_edits(f) if c & folders]
    return bad


def test_the_tests_import_nothing_from_bench_or_experiments():
    own = stems(TESTS)
    modules = (stems(BENCH) | stems(EXPERIMENTS) | {"bench", "experiments"}) - own
    bad = offences(scripts(TESTS), modules, {"bench", "experiments"})
    assert not bad, bad


def test_bench_and_experiments_import_nothing_from_the_tests():
    modules = stems(TESTS) | {"tests"}
    bad = offences(scripts(BENCH) + scripts(EXPERIMENTS), modules, {"tests"})
    assert not bad, bad


def test_bench_holds_benchmarks_only():
    others = [p.name for p in scripts(BENCH) if not p.stem.startswith("bench_")]
    assert not others, f"bench/ is for benchmarks (bench_*.py); move these to experiments/ or the package: {others}"


def test_every_experiment_says_what_it_writes_and_is_listed():
    readme = (EXPERIMENTS / "README.md").read_text()
    for p in scripts(EXPERIMENTS):
        doc = ast.get_docstring(ast.parse(p.read_text())) or ""
        assert f"python experiments/{p.name}" in doc, f"{p.name}: its docstring gives no command"
        assert "Writes:" in doc and "Data:" in doc, f"{p.name}: its docstring says not which table it writes or its data"
        assert f"`{p.name}`" in readme, f"{p.name} is not listed in experiments/README.md"
