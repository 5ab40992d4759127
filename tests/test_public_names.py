"""The package's public names: what ``__getattr__`` loads on first use (``_EXPORTS``), what ``__all__``
lists and what type checkers see (the ``if TYPE_CHECKING:`` imports) are the same names, each from the
same module; ``import imu_learn`` alone loads neither numpy nor torch."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import imu_learn

INIT = Path(imu_learn.__file__)


def _type_checking_imports() -> dict:
    tree = ast.parse(INIT.read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If) and getattr(n.test, "id", "") == "TYPE_CHECKING")
    return {a.name: node.module for node in block.body if isinstance(node, ast.ImportFrom) for a in node.names}


def test_the_type_checkers_names_are_the_lazy_ones_from_the_same_modules():
    assert _type_checking_imports() == imu_learn._EXPORTS
    assert set(imu_learn.__all__) == set(imu_learn._EXPORTS)


def test_every_public_name_loads_and_import_alone_loads_nothing_heavy():
    for name in imu_learn.__all__:
        assert getattr(imu_learn, name) is not None, name
    code = "import sys, imu_learn; print(sorted(m for m in ('numpy', 'torch') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out
