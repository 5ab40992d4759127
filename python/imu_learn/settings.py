"""Settings files and command-line overrides, for every stage: TOML in, dataclasses out, every key
and value checked against the dataclass's fields and types (a bad one is a one-line
:class:`~imu_learn.errors.ConfigError` naming the key). No torch."""
from __future__ import annotations

import sys
import typing
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any, Dict, List, Sequence, Tuple

from imu_learn.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - only on 3.9/3.10
    try:
        import tomli as tomllib  # type: ignore[no-redef]
    except ImportError:  # pragma: no cover
        tomllib = None  # type: ignore[assignment]


# Environment variable naming the data root (DataConfig.data_root); --data-root DIR (the CLI) beats it.
DATA_ROOT_ENV = "IMU_LEARN_DATA"



def hints_of(cls: type) -> Dict[str, Any]:
    mod = sys.modules[cls.__module__]
    return typing.get_type_hints(cls, vars(mod))


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin in (list, List, tuple, Tuple):
        args = typing.get_args(tp)
        return f"list of {_type_name(args[0])}" if args else "list"
    if is_dataclass(tp):
        return "table"
    return getattr(tp, "__name__", str(tp))


def _convert(key: str, value: Any, tp: Any) -> Any:
    """``value`` (from TOML) checked against ``tp``; returns the value to store."""
    origin = typing.get_origin(tp)
    if is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, dict):
            raise ConfigError(f"{key}: expected a table, got {value!r}")
        return from_dict(tp, value, key)
    if origin in (list, List, tuple, Tuple, Sequence) or tp in (list, tuple):
        args = [a for a in typing.get_args(tp) if a is not Ellipsis]
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}: expected a {_type_name(tp)}, got {value!r}")
        items = [_convert(f"{key}[{i}]", v, args[0]) if args else v for i, v in enumerate(value)]
        return tuple(items) if origin in (tuple, Tuple) else items
    if origin is typing.Union:  # Optional[X]: None (a saved config's null, or the default) or an X
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None and len(args) < len(typing.get_args(tp)):
            return None
        if len(args) == 1:
            return _convert(key, value, args[0])
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        return value
    return value  # pragma: no cover - no other field types in use


def from_dict(cls: type, d: Dict[str, Any], prefix: str = "") -> Any:
    """Build dataclass ``cls`` from a (possibly partial) dict, checking every key and value."""
    hints = hints_of(cls)
    names = {f.name for f in fields(cls) if f.init}
    kwargs = {}
    for k, v in d.items():
        key = f"{prefix}.{k}" if prefix else k
        if k not in names:
            raise ConfigError(f"{key}: unknown key (known: {', '.join(sorted(names))})")
        kwargs[k] = _convert(key, v, hints[k])
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{prefix or cls.__name__}: {e}") from e


def merge(base: Dict[str, Any], over: Dict[str, Any]) -> Dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = merge(out[k], v)
        else:
            out[k] = v
    return out


def parse_value(key: str, text: str, tp: Any) -> Any:
    """A command-line string as a value of type ``tp`` (lists and tables as TOML values)."""
    if tp is str:
        return text
    if tp is bool:
        low = text.strip().lower()
        if low in ("true", "1", "yes", "on"):
            return True
        if low in ("false", "0", "no", "off"):
            return False
        raise ConfigError(f"--{key}: expected true or false, got {text!r}")
    if tp is int:
        try:
            return int(text)
        except ValueError:
            raise ConfigError(f"--{key}: expected an integer, got {text!r}") from None
    if tp is float:
        try:
            return float(text)
        except ValueError:
            raise ConfigError(f"--{key}: expected a number, got {text!r}") from None
    # lists / tables: a TOML value; a bare comma list for lists of strings
    try:
        value = tomllib.loads(f"v = {text}")["v"] if tomllib is not None else None
    except Exception:
        value = None
    if value is None and typing.get_origin(tp) in (list, List) and typing.get_args(tp) == (str,):
        value = [s.strip() for s in text.split(",") if s.strip()]
    if value is None:
        raise ConfigError(f"--{key}: expected a {_type_name(tp)} written as TOML, got {text!r}")
    return _convert(f"--{key}", value, tp)


def split_overrides(args: Sequence[str], usage: str = "--key.sub value") -> List[Tuple[str, str]]:
    """``["--optim.lr", "3e-4", "--model.causal=true"]`` -> ``[("optim.lr", "3e-4"), ...]``: the
    command-line grammar shared by every entry point (values are parsed by the caller)."""
    out: List[Tuple[str, str]] = []
    i = 0
    args = list(args)
    while i < len(args):
        a = args[i]
        if not a.startswith("--") or len(a) <= 2:
            raise ConfigError(f"{a}: expected {usage}")
        if "=" in a:
            key, text = a[2:].split("=", 1)
            i += 1
        else:
            key = a[2:]
            if i + 1 >= len(args):
                raise ConfigError(f"--{key}: missing value")
            text = args[i + 1]
            i += 2
        out.append((key, text))
    return out


def nest(flat: Dict[str, Any]) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for key, v in flat.items():
        parts = key.split(".")
        d = out
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = v
    return out


def toml_of_text(text: str) -> Dict[str, Any]:
    """A TOML text as read by :func:`read_toml` (a config written by this package)."""
    if tomllib is None:  # pragma: no cover
        raise ConfigError("reading TOML needs Python 3.11 or the tomli package")
    return tomllib.loads(text)


def read_toml(path: Path) -> Dict[str, Any]:
    if tomllib is None:  # pragma: no cover
        raise ConfigError(f"{path}: reading TOML needs Python 3.11 or the tomli package")
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML ({e})") from e


