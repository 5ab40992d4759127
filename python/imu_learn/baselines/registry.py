"""Every method ``imu-learn evaluate`` can fit and score, by name, and how to load one. Methods are
imported only when asked for (most need torch). Beside the registered names, ``profile:PATH`` scores a
device profile's floor as it ships (:mod:`imu_learn.baselines.profile_floor`; nothing fitted)."""
from __future__ import annotations

import importlib
import logging
import re
from pathlib import Path
from typing import Callable, Dict, Optional, Tuple, Union

from imu_learn.baselines.base import Method
from imu_learn.errors import ConfigError

log = logging.getLogger(__name__)

# Method name -> (module, class name or None = the Method subclass defined there whose ``name``
# matches, else its only one), or a factory callable (tests register their own).
MethodEntry = Union[Tuple[str, Optional[str]], Callable[[], Method]]

REGISTRY: Dict[str, MethodEntry] = {
    "raw": ("imu_learn.baselines.base", "Raw"),
    "timing": ("imu_learn.baselines.timing", "Timing"),
    "traditional": ("imu_learn.baselines.traditional", None),
    "traditional+timing": ("imu_learn.baselines.traditional", "TraditionalTiming"),
    "gyro-denoise": ("imu_learn.baselines.gyro_denoise", None),
    "end-to-end": ("imu_learn.baselines.end_to_end", None),
    "airimu-style": ("imu_learn.baselines.airimu_style", None),
    "proposed": ("imu_learn.baselines.proposed", None),
}
DEFAULT_METHODS = list(REGISTRY)
# Registered after the defaults, so only runs that name it fit it (--methods tlio-style): TLIO-style
# displacement regression, evaluated with ground-truth orientation inside each window (its docstring).
REGISTRY["tlio-style"] = ("imu_learn.baselines.tlio", None)
# ... and its simple floor, the same factors predicting zero displacement (the device stays put).
REGISTRY["zero-displacement"] = ("imu_learn.baselines.zero_displacement", None)


PREFIX = "profile:"  # profile:PATH, a device profile's floor (imu_learn.baselines.profile_floor)


def is_method(name: str) -> bool:
    """A name evaluate knows: a registered one, or ``profile:PATH``."""
    return name in REGISTRY or (name.startswith(PREFIX) and len(name) > len(PREFIX))


def safe_name(name: str) -> str:
    """``name`` as a file name: letters, digits and ``_.+-`` kept (``traditional+timing``), runs of
    anything else one ``-``."""
    return re.sub(r"[^A-Za-z0-9_.+\-]+", "-", name).strip("-") or "method"


def method_file(folder: Path, name: str, method: Optional[Method] = None) -> Path:
    """Where ``imu-learn evaluate`` saves method ``name``'s fit in ``folder`` (``<safe name><its
    save_suffix>``; ``method``: an instance when the caller has one, else the registry's class)."""
    if method is None:
        factory = load_method_class(name)
        method = factory if isinstance(factory, type) or factory is None else factory()
    return Path(folder) / f"{safe_name(name)}{getattr(method, 'save_suffix', None) or '.pt'}"


def load_method_class(name: str) -> Optional[Callable[[], Method]]:
    """A factory for method ``name``, or None (after a one-line warning) when its module is absent."""
    if is_method(name) and name not in REGISTRY:  # profile:PATH
        floor = importlib.import_module("imu_learn.baselines.profile_floor").ProfileFloor
        return lambda: floor(Path(name[len(PREFIX):]))
    if name not in REGISTRY:
        raise ConfigError(f"methods: unknown method {name!r} (known: {known()})")
    entry = REGISTRY[name]
    if callable(entry):
        return entry
    module, cls_name = entry
    try:
        mod = importlib.import_module(module)
    except ImportError as e:
        missing = getattr(e, "name", None) or str(e)
        why = "" if missing == module else f" (it needs {missing})"
        log.warning("skipping %s: module %s not available%s", name, module, why)
        return None
    if cls_name is not None:
        return getattr(mod, cls_name)
    cands = [c for c in vars(mod).values()
             if isinstance(c, type) and issubclass(c, Method) and c.__module__ == mod.__name__]
    named = [c for c in cands if getattr(c, "name", None) == name]
    pick = named or cands
    if len(pick) != 1:
        raise ConfigError(f"methods: {module} defines {len(pick)} Method classes named {name!r}; cannot pick one")
    return pick[0]


def known() -> str:
    """The method names an unknown one is told of: the registered ones and ``profile:PATH``."""
    return ", ".join([*REGISTRY, f"{PREFIX}PATH (a profile.json)"])
