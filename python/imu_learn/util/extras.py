"""The optional dependencies (pyproject.toml's extras) and the one-line error when one is missing.

A stage checks its extra when it starts (:func:`require_extra`), so a missing package is one line
naming the extra to install (``imu-learn <command>: error: MissingExtraError: ...``), not a
ModuleNotFoundError traceback after minutes of work.
"""
from __future__ import annotations

import importlib
from types import ModuleType
from typing import Dict, Optional, Tuple

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
    except ImportError as e:
        if interrupted(e):  # a Ctrl-C inside a C extension's initialisation (gtsam's) comes as ImportError
            raise KeyboardInterrupt from None
        raise MissingExtraError(f"{needed_for} needs {module.split('.')[0]}, the {extra} extra: "
                                f"pip install 'imu-learn[{extra}]'") from None


def interrupted(e: BaseException) -> bool:
    """Whether a KeyboardInterrupt caused ``e`` (its cause or context, at any depth)."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def optional(module: str) -> Optional[ModuleType]:
    """``module`` imported, or None where it is not installed (a figure left out); a Ctrl-C during its
    import is raised as the KeyboardInterrupt it was, never read as "not installed"."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        if interrupted(e):
            raise KeyboardInterrupt from None
        return None


def require_extra(extra: str, needed_for: str) -> None:
    """Every package of ``extra`` importable, else a :class:`MissingExtraError` naming the first
    one missing and the extra."""
    for module in EXTRAS[extra]:
        require(module, extra, needed_for)
