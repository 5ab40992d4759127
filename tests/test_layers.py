"""The package's parts import one way: each part imports only itself and the parts below it (the
order is docs/README.md's "Code layout"). Every import counts, at module level or inside a function,
relative ones resolved. A function-local import is only for an optional heavy dependency (torch,
gtsam, matplotlib, rosbags; LAZY adds the other extras' packages and scipy/h5py), never to hide an
import against the order; each stage names its missing extra in one line (tests/test_extras.py)."""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Iterator, List, Optional, Set, Tuple

PKG = Path(__file__).resolve().parents[1] / "python" / "imu_learn"
README = Path(__file__).resolve().parents[1] / "docs" / "README.md"

# Lowest first. A part is a subpackage or a top-level module of imu_learn; "api" is imu_learn/__init__.py
# (the public API, which re-exports core and data); "stages" the `python -m imu_learn.<stage>` shims.
ORDER = (
    "errors", "_imu_core", "util", "settings",
    "core", "data", "api", "score", "nn", "infer", "baselines", "calib", "train", "eval",
    "fuse", "cli", "stages",
)
STAGES = ("fit", "refine", "export", "labels", "evaluate")

# Imports against the order that are known and being removed: (file under imu_learn/, imported part).
# Empty: fuse/ no longer reaches the CLI layer (it did for its one-line error wording).
KNOWN_EXCEPTIONS: Set[Tuple[str, str]] = set()


def part_of(module: str) -> str:
    """The part of a dotted imu_learn module name."""
    parts = module.split(".")
    assert parts[0] == "imu_learn", module
    if len(parts) == 1:
        return "api"
    if len(parts) == 2 and parts[1] in STAGES:
        return "stages"
    return parts[1]


def module_of(path: Path) -> Tuple[str, bool]:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    is_pkg = parts[-1] == "__init__"
    if is_pkg:
        parts.pop()
    return ".".join(parts), is_pkg


def is_submodule(dotted: str) -> bool:
    """Whether ``dotted`` names one of the package's modules or subpackages (the Rust extension
    included)."""
    parts = dotted.split(".")
    if parts[0] != "imu_learn" or len(parts) < 2:
        return False
    where = PKG.joinpath(*parts[1:-1])
    return (where / parts[-1]).is_dir() or any(where.glob(f"{parts[-1]}.*"))


def imported(path: Path, source: Optional[str] = None) -> Iterator[Tuple[int, str]]:
    """(line, absolute module name) of every import in ``path`` (or ``source`` as if it were that
    file), function-local included, relative ones resolved."""
    name, is_pkg = module_of(path)
    package = name if is_pkg else name.rsplit(".", 1)[0]
    text = path.read_text() if source is None else source
    for node in ast.walk(ast.parse(text, str(path))):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")
                up = up[: len(up) - (node.level - 1)]
                base = ".".join(up + ([base] if base else []))
            for a in node.names:  # `from imu_learn.x import y`: y may be a module
                target = f"{base}.{a.name}"
                yield node.lineno, target if is_submodule(target) else base


def violations() -> List[str]:
    rank = {p: i for i, p in enumerate(ORDER)}
    out = []
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG).as_posix()
        src = part_of(module_of(path)[0])
        for line, target in imported(path):
            if target != "imu_learn" and not target.startswith("imu_learn."):
                continue
            dst = part_of(target)
            if dst == src or (rel, dst) in KNOWN_EXCEPTIONS:
                continue
            if rank[dst] > rank[src]:
                out.append(f"python/imu_learn/{rel}:{line}: {src} imports {dst} ({target}), which is above it")
    return list(dict.fromkeys(out))


def parts_on_disk() -> List[str]:
    return sorted({part_of(module_of(p)[0]) for p in PKG.rglob("*.py")} | {"_imu_core"})


def test_every_part_has_a_place_in_the_order():
    missing = [p for p in parts_on_disk() if p not in ORDER]
    assert not missing, f"parts with no place in ORDER (tests/test_layers.py, docs/README.md): {missing}"


def test_imports_follow_the_order():
    found = violations()
    assert not found, "imports against the order " + " -> ".join(ORDER) + ":\n" + "\n".join(found)


def test_known_exceptions_are_still_needed():
    """An exception no import needs any more goes from the list."""
    used = set()
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG).as_posix()
        for _, target in imported(path):
            if target.startswith("imu_learn."):
                used.add((rel, part_of(target)))
    stale = sorted(KNOWN_EXCEPTIONS - used)
    assert not stale, f"known exceptions no import needs (remove them): {stale}"


HEAVY = ("torch", "gtsam", "matplotlib", "rosbags")  # optional: each stage names its extra
# modules a command imports where it needs them for their start-up time alone (each with why)
DEFERRED = {"imu_learn.fuse.calibrate_positions": "calibrate's GNSS reference: the navigator and scipy's rotations, "
                                                  "about 1 s of start-up every other reference kind does not need"}


def split_imports(path: Path) -> Tuple[List[Tuple[int, str]], List[Tuple[int, str]]]:
    """(module-level, function-local) imports of ``path`` as (line, absolute module name)."""
    local_lines = set()
    for fn in ast.walk(ast.parse(path.read_text())):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            local_lines |= {n.lineno for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))}
    top, local = [], []
    for line, target in imported(path):
        (local if line in local_lines else top).append((line, target))
    return top, local


def heavy_modules() -> Set[str]:
    """The package's modules that import an optional heavy dependency at module level, directly or
    through the package's modules they import at module level."""
    paths = {module_of(p)[0]: p for p in PKG.rglob("*.py")}
    deps = {}
    for name, p in paths.items():
        top, _ = split_imports(p)
        deps[name] = {t for _, t in top}
    heavy = {n for n, ts in deps.items() if any(t.split(".")[0] in HEAVY for t in ts)}
    grew = True
    while grew:
        grew = False
        for n, ts in deps.items():
            if n not in heavy and any(owner(t, paths) in heavy for t in ts):
                heavy.add(n)
                grew = True
    return heavy


def owner(target: str, paths) -> str:
    """The module of an imported name (``imu_learn.a.b.name`` -> ``imu_learn.a.b``)."""
    while target and target not in paths:
        target = target.rsplit(".", 1)[0] if "." in target else ""
    return target


def test_function_local_imports_only_hold_back_optional_dependencies():
    """A function imports one of the package's modules only when that module brings in torch, GTSAM,
    matplotlib or rosbags and the importing module does not have them already, or it is one of
    :data:`DEFERRED` (its start-up time)."""
    paths = {module_of(p)[0]: p for p in PKG.rglob("*.py")}
    heavy = heavy_modules()
    found = []
    for name, path in sorted(paths.items()):
        rel = path.relative_to(PKG).as_posix()
        for line, target in split_imports(path)[1]:
            if target.split(".")[0] != "imu_learn":
                continue
            mod = owner(target, paths) or target
            if mod in DEFERRED:
                continue
            if mod not in heavy or name in heavy:
                found.append(f"python/imu_learn/{rel}:{line}: {target} (import it at module level)")
    assert not found, "function-local imports of the package's own modules:\n" + "\n".join(dict.fromkeys(found))


def readme_order() -> Optional[List[str]]:
    for line in README.read_text().splitlines():
        if line.startswith("Import order"):
            return [p.strip(" `.") for p in line.split(":", 1)[1].split("->")]
    return None


def test_the_order_is_the_documented_one():
    assert readme_order() == list(ORDER), "docs/README.md's 'Import order:' line and ORDER differ"


def test_the_checker_sees_function_local_and_relative_imports():
    src = "from __future__ import annotations\nfrom . import x\ndef f():\n    from ..cli import main\n"
    got = {t: line for line, t in imported(PKG / "core" / "probe.py", src)}
    assert got == {"__future__": 1, "imu_learn.core": 2, "imu_learn.cli": 4}
    assert part_of("imu_learn") == "api" and part_of("imu_learn.fit") == "stages"
    assert part_of("imu_learn.train.trainer") == "train"


def test_stage_modules_only_dispatch_to_the_cli():
    """``python -m imu_learn.<stage>`` is ``imu-learn <stage>``: each top-level stage module is the
    dispatcher into imu_learn.cli and nothing else (the stage's code is in its part, its options in
    imu_learn/cli/<stage>.py), and nothing imports it."""
    top = {p.stem for p in PKG.glob("*.py")} - {"__init__", "errors", "settings"}
    assert top == set(STAGES), f"top-level modules that are not stage dispatchers: {sorted(top - set(STAGES))}"
    for stage in STAGES:
        tree = ast.parse((PKG / f"{stage}.py").read_text())
        body = [n for n in tree.body if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))]
        assert len(body) == 1 and isinstance(body[0], ast.If) and "__main__" in ast.unparse(body[0].test), stage
        assert f'entry(["{stage}", *sys.argv[1:]])' in ast.unparse(body[0]).replace("'", '"'), stage
        assert (PKG / "cli" / f"{stage}.py").exists(), stage


# Packages a function may import: the optional heavy dependencies, the other optional extras'
# packages, and two required but slow ones only their readers need (scipy, h5py: ~0.2-0.4 s each).
LAZY = HEAVY + ("polars", "onnxruntime", "ruamel", "tensorboard", "scipy", "h5py")


def test_function_local_imports_of_other_packages_only_for_lazy_ones():
    found = []
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG).as_posix()
        for line, target in split_imports(path)[1]:
            top = target.split(".")[0]
            if top not in ("imu_learn", "__future__") and top not in LAZY:
                found.append(f"python/imu_learn/{rel}:{line}: {target} (import it at module level)")
    assert not found, "function-local imports of packages that are neither optional nor slow:\n" + "\n".join(found)
