"""No machine paths in the repository: no tracked text file, and no config stored inside a shipped
checkpoint (models/*.pt), names an absolute path of the machine it was written on (a home, root,
work or temporary folder). Shipped checkpoints store their data paths relative to a data root, with
no data root of their own; their weights are those of the checkpoints first shipped, byte for byte."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path
from typing import Any, Iterator, List, Tuple

import pytest

REPO = Path(__file__).resolve().parent.parent
# An absolute path into a machine's home, root, work, mount or temporary folder (POSIX or Windows),
# not part of a URL or of a longer relative path. Spelt in pieces so this file does not match itself.
_DIRS = "|".join(["ho" + "me", "ro" + "ot", "wo" + "rk", "Us" + "ers", "mn" + "t", "scr" + "atch", "tm" + "p"])
MACHINE_PATH = re.compile(rf"(?<![\w.~:/-])/(?:{_DIRS})/|\b[A-Za-z]:\\(?:{_DIRS})\\")
# The last commit whose models/*.pt held the training machine's data root; the rewritten files
# must keep its weights bit-identical.
BEFORE_REWRITE = "39716cf"


def _tracked_files() -> List[str]:
    try:
        out = subprocess.run(["git", "ls-files", "-z", "-co", "--exclude-standard"], cwd=REPO,
                             capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [p for p in out.decode().split("\0") if p]


def _text(path: Path) -> str:
    """The file's text, or "" for a binary file (a NUL byte) or one that is gone."""
    try:
        raw = path.read_bytes()
    except (FileNotFoundError, IsADirectoryError):
        return ""
    if b"\0" in raw[:8192]:
        return ""
    return raw.decode("utf-8", errors="replace")


def test_pattern_matches_machine_paths_and_nothing_else():
    hits = ["/" + "home/u/data", "see /" + "root/x", "'/" + "work/shared/data'", "(/" + "tmp/out.json)",
            "C:\\" + "Users\\me\\data"]
    misses = ["https://example.org/" + "home/x", "datasets/euroc/MH_01_easy", "runs/" + "work/a",
              "~/" + "work/x", "$TMPDIR/imu_learn_bench_scale", "../shared/data"]
    assert all(MACHINE_PATH.search(s) for s in hits), [s for s in hits if not MACHINE_PATH.search(s)]
    assert not any(MACHINE_PATH.search(s) for s in misses), [s for s in misses if MACHINE_PATH.search(s)]


def test_no_tracked_text_file_names_a_machine_path():
    bad = []
    for rel in _tracked_files():
        if rel.endswith(".lock"):  # Cargo.lock: registry checksums only
            continue
        for no, line in enumerate(_text(REPO / rel).splitlines(), 1):
            m = MACHINE_PATH.search(line)
            if m:
                bad.append(f"{rel}:{no}: {line.strip()[:120]}")
    assert not bad, "machine paths (use a path relative to the data root / repository, or IMU_LEARN_DATA):\n" + \
        "\n".join(bad)


def _strings(value: Any, where: str) -> Iterator[Tuple[str, str]]:
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _strings(v, f"{where}.{k}")
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            yield from _strings(v, f"{where}[{i}]")
    elif isinstance(value, str):
        yield where, value


SHIPPED = sorted((REPO / "models").glob("*.pt"))


@pytest.mark.parametrize("path", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_checkpoint_stores_no_machine_path(path):
    pytest.importorskip("torch")
    from imu_learn.infer.checkpoint import load_checkpoint

    state = load_checkpoint(path)
    plain = {k: v for k, v in state.items() if k != "model"}  # everything but the weights
    bad = [f"{w} = {s!r}" for w, s in _strings(plain, path.name) if MACHINE_PATH.search(s)]
    assert not bad, f"{path.name}: machine paths in the stored config: {bad}"
    data = state["config"]["data"]
    assert data["data_root"] == "", f"{path.name}: data.data_root is {data['data_root']!r}, not empty"
    for i, root in enumerate(data["roots"]):
        for key in ("path", "groundtruth"):
            assert not Path(root[key]).is_absolute(), \
                f"{path.name}: data.roots[{i}].{key} = {root[key]!r} is not relative to a data root"


def _rewritten() -> List[Path]:
    """The shipped checkpoints that existed at BEFORE_REWRITE (the ones the rewrite touched).
    Checkpoints shipped later never held a machine path, so they have no "before" to compare with;
    test_shipped_checkpoint_stores_no_machine_path covers them. Empty where git or that commit is
    missing (not a checkout, or a shallow one): then the test below is reported as skipped."""
    try:
        out = subprocess.run(["git", "ls-tree", "--name-only", BEFORE_REWRITE, "models/"], cwd=REPO,
                             capture_output=True, check=True, text=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return []
    return [p for p in SHIPPED if p.relative_to(REPO).as_posix() in out.split("\n")]


REWRITTEN = _rewritten()


def test_the_rewritten_checkpoints_are_in_this_checkouts_history():
    """The five checkpoints shipped at BEFORE_REWRITE are found there (so the test below runs on
    each): a checkout whose history lost them would otherwise pass with nothing checked."""
    if not (REPO / ".git").exists():
        pytest.skip("not a git checkout")
    assert sorted(p.name for p in REWRITTEN) == ["blackbird_clover.pt", "broad_handheld.pt", "euroc_adis16448.pt",
                                                  "euroc_adis16448_cov.pt", "tumvi_bmi160.pt"]


@pytest.mark.parametrize("path", REWRITTEN, ids=[p.name for p in REWRITTEN])
def test_rewritten_checkpoint_keeps_its_weights_bit_identical(path, tmp_path):
    """The rewrite changed only the stored config: every tensor equals the one shipped before, byte
    for byte (dtype, shape and data), and every other entry but the config and the new digest."""
    torch = pytest.importorskip("torch")
    from imu_learn.infer.checkpoint import DIGEST_KEY, load_checkpoint

    rel = path.relative_to(REPO).as_posix()
    old_bytes = subprocess.run(["git", "show", f"{BEFORE_REWRITE}:{rel}"], cwd=REPO, capture_output=True,
                               check=True).stdout
    (tmp_path / "old.pt").write_bytes(old_bytes)
    old = torch.load(tmp_path / "old.pt", weights_only=True)
    new = load_checkpoint(path)
    assert sorted(old["model"]) == sorted(new["model"])
    for k, a in old["model"].items():
        b = new["model"][k]
        assert (a.dtype, tuple(a.shape)) == (b.dtype, tuple(b.shape)), k
        assert a.contiguous().view(torch.uint8).numpy().tobytes() == \
            b.contiguous().view(torch.uint8).numpy().tobytes(), f"{path.name}: tensor {k} changed"
    for k in old:
        if k not in ("model", "config", DIGEST_KEY):
            assert new[k] == old[k], f"{path.name}: {k} changed"
    old_cfg, new_cfg = old["config"], new["config"]
    old_cfg["data"]["data_root"] = new_cfg["data"]["data_root"]
    assert new_cfg == old_cfg, f"{path.name}: the config changed beyond data.data_root"
