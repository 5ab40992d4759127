"""Run configuration for ``python -m imu_learn.fit``: nested dataclasses, a TOML file, CLI overrides.

A run is described by :class:`RunConfig`::

    seed, device, threads, runs_dir, name            top level
    [data]   data_root, window, batch_size, fractions, gravity, val_stride, eval_stride, startup_bias_s
    [[data.roots]]  path, format, groundtruth         where recordings are (any format load_sequence reads)
    [data.split]    train, val, test                  sequence names per split (see imu_learn.splits)
    [data.augment]  the fields of imu_learn.AugmentConfig
    [model]  the fields of imu_learn.model.ModelConfig
    [loss]   the fields of imu_learn.losses.LossConfig
    [optim]  lr, epochs, steps_per_epoch, grad_clip

Defaults are the default run (the shipped 60 s EuRoC crops; ``configs/default.toml`` writes them
out). A TOML file may give any subset; ``--key.sub value`` overrides a single field, e.g.
``--optim.lr 3e-4 --data.split.test '["V1_01_easy"]' --model.causal true``. Every key is checked
against the dataclass fields and every value against the field's type; a bad one raises
:class:`ConfigError` with a one-line message naming the key.
"""
from __future__ import annotations

import os
import sys
import typing
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any, Dict, List, Sequence, Tuple

from imu_learn.batches import AugmentConfig, BatchConfig
from imu_learn.errors import ImuError
from imu_learn.integration import PAPER_FRACTIONS
from imu_learn.losses import LossConfig
from imu_learn.model import REFINE_CHANNELS, ModelConfig

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - only on 3.9/3.10
    try:
        import tomli as tomllib  # type: ignore[no-redef]
    except ImportError:  # pragma: no cover
        tomllib = None  # type: ignore[assignment]


class ConfigError(ImuError, ValueError):
    """A configuration file or override names an unknown key or gives a value of the wrong type."""


# Environment variable naming the data root (DataConfig.data_root); --data.data_root beats it.
DATA_ROOT_ENV = "IMU_LEARN_DATA"


@dataclass
class RootConfig:
    """Where recordings are. ``path`` is a dataset folder (every recording under it is found, as
    ``just labels`` finds them) or one recording (an ASL folder, a Blackbird folder, a ``.mat``).
    ``format``: euroc, tum-vi, blackbird, broad, kaist or rosbag (``imu_topic`` / ``groundtruth_topic``). ``groundtruth``: a separate TUM/ASL file,
    only for a ``path`` that is a single recording. Relative paths are taken from
    ``data.data_root`` when one is set, else from the working directory, else from the repository
    root."""

    path: str = ""
    format: str = "euroc"
    groundtruth: str = ""
    # Ground-truth stamps further apart than this split a recording (AlignOptions.max_gap_s);
    # raise it for sparse ground truth, e.g. 0.06 for EuRoC's 20 Hz ASL state files.
    max_gap_s: float = 0.05
    # Added to the ground truth's stamps (AlignOptions.gt_time_offset_s) where its clock is measured
    # to be off the IMU's (bench/groundtruth_report.py: a ground truth late by tau gets -tau).
    gt_time_offset_s: float = 0.0
    # format = "rosbag": the IMU and ground-truth topics (empty: each bag's only one).
    imu_topic: str = ""
    groundtruth_topic: str = ""


@dataclass
class SplitConfig:
    """Sequence names per split. A name may carry a time block ``NAME[a:b]`` with fractions
    0 <= a < b <= 1 of the recording's duration; blocks of one recording in different splits must
    not overlap (checked). A name without a block is the whole recording."""

    train: List[str] = field(default_factory=lambda: ["MH_01_easy[0:0.8]"])
    val: List[str] = field(default_factory=lambda: ["MH_01_easy[0.8:1]"])
    test: List[str] = field(default_factory=lambda: ["V1_01_easy"])


def _default_roots() -> List[RootConfig]:
    # V1_01 against the ASL full state (EuRoC's ground truth, IMU frame, 20 Hz): its
    # groundtruth_pose.tum is ~5.5 deg off the IMU frame (README, "EuRoC ground truth").
    v1 = "datasets/euroc/V1_01_easy"
    return [RootConfig("datasets/euroc/MH_01_easy", "euroc"),
            RootConfig(v1, "euroc", f"{v1}/groundtruth_state_20hz.csv", max_gap_s=0.06)]


def _default_augment() -> AugmentConfig:
    # EuRoC's ADIS16448 datasheet-level noise (sensor.yaml) and biases a few times the device's.
    return AugmentConfig(
        gyro_noise_density=1.7e-4,
        acc_noise_density=2.0e-3,
        gyro_bias_max=0.02,
        acc_bias_max=0.2,
        gyro_bias_walk=1.9e-5,
        acc_bias_walk=3.0e-3,
    )


@dataclass
class DataConfig:
    # Folder that relative data.roots[i].path / .groundtruth are taken from (see
    # splits.resolve_data_path). Set by, highest first: --data.data_root DIR, the environment
    # variable IMU_LEARN_DATA (read by build_config), this value in the config file. Empty: paths
    # are taken from the working directory, else the repository root (the shipped crops).
    data_root: str = ""
    roots: List[RootConfig] = field(default_factory=_default_roots)
    split: SplitConfig = field(default_factory=SplitConfig)
    window: int = 200  # IMU samples per training window (1 s at 200 Hz)
    batch_size: int = 32  # paper: 32
    fractions: List[float] = field(default_factory=lambda: list(PAPER_FRACTIONS))  # paper: 20..100 %
    gravity: float = 9.81
    val_stride: int = 20  # start step of the fixed validation windows [samples]
    eval_stride: int = 10  # start step of the relative-pose-error windows on the test split
    startup_bias_s: float = 10.0  # seconds fitted by fit_startup_bias for the final table
    # Horizons [IMU samples] of the final held-out table (the paper's Table II uses 10). TUM-VI adds
    # 5 s and 20 s (1000, 4000 at 200 Hz): over short horizons its mocap orientation noise dominates.
    eval_horizons: List[int] = field(default_factory=lambda: [10, 200])
    augment: AugmentConfig = field(default_factory=_default_augment)
    # The device's own constant bias in the training and validation recordings: "keep" (the paper:
    # the labels then ask the model to remove it, so it learns the bias of the training flights) or
    # "remove" (one constant gyro and accelerometer bias per segment, fitted against its ground
    # truth over the whole segment, is subtracted before training: the model learns what is left,
    # and a bias at run time is the estimator's job, as the paper's footnote asks). Test sequences
    # are never changed.
    train_bias: str = "keep"

    def batch_config(self) -> BatchConfig:
        return BatchConfig(self.window, self.batch_size, tuple(self.fractions), self.gravity, self.augment)


SELECT_METRICS = ("val_loss", "val_pose")
SELECT_TERMS = ("rot+trans", "rot")


@dataclass
class OptimConfig:
    lr: float = 1e-4  # paper: Adam, 1e-4
    epochs: int = 24  # paper: 700 on a GPU; sized so the default run fits 10 min on 2 CPU cores
    steps_per_epoch: int = 100
    grad_clip: float = 0.0  # max gradient norm; 0 = off
    # What picks best.pt: "val_loss" (the training loss on fixed validation windows) or "val_pose"
    # (relative pose RMSE over data.window samples on the validation sequences, each input's
    # start-up bias removed as in the final table, the worse of rotation and translation as a ratio
    # to raw IMU; see fit.ValidationPose).
    select: str = "val_loss"
    # val_pose only: the horizons [IMU samples] scored on validation (empty: data.window) and the
    # terms: "rot+trans" (the worst ratio over rotation and translation) or "rot" (rotation only,
    # e.g. a gyro-only model). The score is the worst model/raw ratio over horizons and terms.
    select_horizons: List[int] = field(default_factory=list)
    select_terms: str = "rot+trans"
    # How the validation recordings are combined per horizon and term: "pooled" (one RMSE over every
    # window of every validation sequence) or "recordings" (the geometric mean over recordings of
    # each one's model/raw ratio: every recording counts alike, as the paper's "Average" row).
    select_average: str = "pooled"
    # How the model/raw ratios over horizons and terms become one score: "max" (the worst ratio:
    # below 1 only when every one beats raw) or "mean" (their geometric mean: a large gain on one
    # term, e.g. rotation over 10 samples, counts even while another sits at raw's level).
    select_combine: str = "max"
    # Start from a trained checkpoint's weights (its model args must match model.*, except the
    # covariance head, which a refiner without one gets freshly initialised); "" = from scratch.
    init: str = ""
    # What the optimiser moves: "all", or "covariance" (the covariance head alone on the frozen
    # refiner of optim.init: the refined samples stay bit-identical, only the variances learn).
    trainable: str = "all"


@dataclass
class RunConfig:
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    seed: int = 0
    device: str = "auto"  # auto (CUDA when present), cpu, cuda, cuda:N
    threads: int = 1  # torch CPU threads (1 is fastest for this model on a small shared CPU)
    runs_dir: str = "runs"
    name: str = ""  # run folder name; default a timestamp

    def to_dict(self) -> Dict[str, Any]:
        return asdict(self)


# ---------------------------------------------------------------------------------------------
# dict <-> dataclass with type checking

def _hints(cls: type) -> Dict[str, Any]:
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
    hints = _hints(cls)
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


def _merge(base: Dict[str, Any], over: Dict[str, Any]) -> Dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


def _field_type(path: List[str]) -> Any:
    """The declared type of a dotted key, or ConfigError naming it."""
    cls: Any = RunConfig
    for i, part in enumerate(path):
        key = ".".join(path[: i + 1])
        if not is_dataclass(cls):
            raise ConfigError(f"--{key}: {'.'.join(path[:i])} is not a table")
        hints = _hints(cls)
        if part not in hints or part not in {f.name for f in fields(cls)}:
            known = ", ".join(sorted(f.name for f in fields(cls)))
            raise ConfigError(f"--{key}: unknown key (known here: {known})")
        cls = hints[part]
    return cls


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


def parse_overrides(args: Sequence[str]) -> Dict[str, Any]:
    """``["--optim.lr", "3e-4", "--model.causal=true"]`` -> ``{"optim.lr": 3e-4, ...}``, type-checked."""
    return {key: parse_value(key, text, _field_type(key.split("."))) for key, text in split_overrides(args)}


def _nest(flat: Dict[str, Any]) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for key, v in flat.items():
        parts = key.split(".")
        d = out
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = v
    return out


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


def build_config(base: Dict[str, Any], overrides: Dict[str, Any]) -> RunConfig:
    """Defaults, then ``base`` (a TOML dict or a saved config), then dotted overrides.

    ``data.data_root``: an explicit ``data.data_root`` override wins, else the environment variable
    ``IMU_LEARN_DATA`` (when set and not empty), else ``base``'s value."""
    env_root = os.environ.get(DATA_ROOT_ENV, "")
    if env_root and "data.data_root" not in overrides:
        overrides = {**overrides, "data.data_root": env_root}
    merged = _merge(asdict(RunConfig()), base)
    merged = _merge(merged, _nest(overrides))
    cfg = from_dict(RunConfig, merged)
    validate(cfg)
    return cfg


def load_config(path: Any = None, overrides: Sequence[str] = ()) -> RunConfig:
    """Defaults, then the TOML file ``path`` (if any), then ``--key.sub value`` overrides."""
    base = read_toml(Path(path)) if path else {}
    return build_config(base, parse_overrides(overrides))


def validate(cfg: RunConfig) -> None:
    """Value checks beyond types (one-line ConfigError naming the key)."""
    d, o = cfg.data, cfg.optim

    def need(ok: bool, key: str, what: str) -> None:
        if not ok:
            raise ConfigError(f"{key}: {what}")

    need(d.window >= 2, "data.window", f"must be at least 2, got {d.window}")
    need(d.batch_size >= 1, "data.batch_size", f"must be at least 1, got {d.batch_size}")
    need(len(d.fractions) > 0 and all(0 < f <= 1 for f in d.fractions), "data.fractions", "must be in (0, 1]")
    need(d.val_stride >= 1, "data.val_stride", "must be at least 1")
    need(d.eval_stride >= 1, "data.eval_stride", "must be at least 1")
    need(d.startup_bias_s > 0, "data.startup_bias_s", "must be positive")
    need(len(d.roots) > 0, "data.roots", "give at least one root")
    for i, r in enumerate(d.roots):
        need(bool(r.path), f"data.roots[{i}].path", "is empty")
        need(r.max_gap_s > 0, f"data.roots[{i}].max_gap_s", f"must be positive, got {r.max_gap_s}")
    need(len(d.split.train) > 0, "data.split.train", "give at least one sequence")
    need(len(d.split.val) > 0, "data.split.val", "give at least one sequence")
    need(o.lr > 0, "optim.lr", f"must be positive, got {o.lr}")
    need(o.epochs >= 1, "optim.epochs", f"must be at least 1, got {o.epochs}")
    need(o.steps_per_epoch >= 1, "optim.steps_per_epoch", f"must be at least 1, got {o.steps_per_epoch}")
    need(o.grad_clip >= 0, "optim.grad_clip", "must be >= 0")
    need(all(n >= 1 for n in d.eval_horizons) and len(d.eval_horizons) > 0, "data.eval_horizons",
         "give at least one horizon, each >= 1 sample")
    need(all(n >= 1 for n in o.select_horizons), "optim.select_horizons", "each horizon must be >= 1 sample")
    need(o.select_terms in SELECT_TERMS, "optim.select_terms",
         f"must be one of {', '.join(SELECT_TERMS)}, got {o.select_terms!r}")
    need(o.select_average in ("pooled", "recordings"), "optim.select_average",
         f"must be pooled or recordings, got {o.select_average!r}")
    need(cfg.data.train_bias in ("keep", "remove"), "data.train_bias",
         f"must be keep or remove, got {cfg.data.train_bias!r}")
    need(o.select_combine in ("max", "mean"), "optim.select_combine",
         f"must be max or mean, got {o.select_combine!r}")
    need(o.select in SELECT_METRICS, "optim.select", f"must be one of {', '.join(SELECT_METRICS)}, got {o.select!r}")
    need(cfg.threads >= 1, "threads", "must be at least 1")
    need(cfg.device == "auto" or cfg.device == "cpu" or cfg.device.startswith("cuda"), "device",
         f"expected auto, cpu, cuda or cuda:N, got {cfg.device!r}")
    need(cfg.model.layers >= 1 and cfg.model.hidden >= 1 and cfg.model.fc >= 1, "model", "sizes must be >= 1")
    need(cfg.loss.horizon_scale in ("none", "inverse"), "loss.horizon_scale",
         f"must be none or inverse, got {cfg.loss.horizon_scale!r}")
    need(o.trainable in ("all", "covariance"), "optim.trainable", f"must be all or covariance, got {o.trainable!r}")
    need(o.trainable == "all" or (cfg.model.covariance and bool(o.init)), "optim.trainable",
         "covariance needs model.covariance = true and optim.init (the frozen refiner)")
    need(cfg.loss.w_nll >= 0, "loss.w_nll", f"must be >= 0, got {cfg.loss.w_nll}")
    need(cfg.loss.w_nll == 0 or cfg.model.covariance, "loss.w_nll", "needs model.covariance = true")
    need(cfg.model.refine in REFINE_CHANNELS, "model.refine",
         f"must be one of {', '.join(REFINE_CHANNELS)}, got {cfg.model.refine!r}")


def to_toml(cfg: RunConfig) -> str:
    """The config as TOML (what ``configs/default.toml`` holds for the defaults)."""
    d = asdict(cfg)

    def val(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)

    lines = [f"{k} = {val(v)}" for k, v in d.items() if not isinstance(v, dict)]
    for sec in ("data", "model", "loss", "optim"):
        body = d[sec]
        lines.append(f"\n[{sec}]")
        lines += [f"{k} = {val(v)}" for k, v in body.items() if not isinstance(v, (dict, list)) or (isinstance(v, list) and not (v and isinstance(v[0], dict)))]
        for k, v in body.items():
            if isinstance(v, dict):
                lines.append(f"\n[{sec}.{k}]")
                lines += [f"{kk} = {val(vv)}" for kk, vv in v.items()]
        for k, v in body.items():
            if isinstance(v, list) and v and isinstance(v[0], dict):
                for item in v:
                    lines.append(f"\n[[{sec}.{k}]]")
                    lines += [f"{kk} = {val(vv)}" for kk, vv in item.items()]
    return "\n".join(lines) + "\n"
