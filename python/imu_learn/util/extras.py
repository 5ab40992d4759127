"""The optional dependencies (pyproject.toml's extras) and the one-line error when one is missing.

A stage checks its extra when it starts (:func:`require_extra`), so a missing package is one line
naming the extra to install (``imu-learn <command>: error: MissingExtraError: ...``), not a
ModuleNotFoundError traceback after minutes of work.
"""
from __future__ import annotations

import importlib
from types import ModuleType
from typing import Dict, Tuple

from imu_learn.errors import MissingExtraError

# extra -> the packages of it a stage imports (pyproject.toml [project.optional-dependencies])
EXTRAS: Dict[str, Tuple[str, ...]] = {
    "train": ("torch",),
    "eval": ("torch", "polars", "matplotlib"),
    "export": ("torch",),  # onnxruntime only checks the export (a note when absent)
    "fuse": ("gtsam",),
    "bags": ("rosbags",),
}


def require(module: str, extra: str, needed_for: str) -> ModuleType:
    """``module`` imported, or a :class:`MissingExtraError` saying that ``needed_for`` needs it and
    which extra installs it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(f"{needed_for} needs {module.split('.')[0]}, the {extra} extra: "
                                f"pip install 'imu-learn[{extra}]'") from None


def require_extra(extra: str, needed_for: str) -> None:
    """Every package of ``extra`` importable, else a :class:`MissingExtraError` naming the first
    one missing and the extra."""
    for module in EXTRAS[extra]:
        require(module, extra, needed_for)
