"""Evaluate IMU methods on held-out sequences: ``imu-learn evaluate``.

Reproduces the paper's Section V experiments (Table II: relative translation / rotation RMSE over
ten IMU frames; the integration-error-against-horizon figure) for any set of methods, plus
AirIMU's short-horizon figures, and writes a report folder.

Usage::

    imu-learn evaluate --config configs/eval_default.toml        # the shipped crops
    imu-learn evaluate --config configs/eval_euroc.toml --methods raw,traditional
    imu-learn evaluate --config configs/eval_euroc.toml --checkpoint runs/euroc/best.pt
    imu-learn evaluate --config configs/eval_euroc.toml --reuse  # reuse fitted methods
    imu-learn evaluate --config configs/eval_euroc.toml --fit.steps 100 --eval.stride 20 \\
        --data.split.test '["V1_01_easy"]'                                  # dotted overrides

The protocol (what is fitted on what, what each metric is) is :data:`imu_learn.score.protocol.PROTOCOL`,
which every report prints.

Output: ``<reports_dir>/<name>/`` (default ``reports/<config name>``) with ``report.md``, CSV
tables, PNG plots and ``methods/``; a summary table on the terminal. Known errors (config, data,
missing files, a method failing) print one line and exit with status 2.
"""
from __future__ import annotations

import json
import logging
import math
import platform
import random
import re
import sys
import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np
from tqdm import tqdm

from imu_learn._imu_core import __version__
from imu_learn.baselines.base import FitSettings, Method, PosePrediction, poses_from_imu
from imu_learn.baselines.noise_floor import NOISE_FLOOR_NAME, GroundTruthImu
from imu_learn.baselines.registry import DEFAULT_METHODS, REGISTRY, load_method_class, method_file, safe_name  # noqa: F401
from imu_learn.baselines.registry import PREFIX as PROFILE_PREFIX
from imu_learn.calib.correction import not_shipped
from imu_learn.calib.plausible import applied_floor_finding
from imu_learn.calib.profile import Profile
from imu_learn.core.quat import rotation_angle
from imu_learn.data.formats import read_recording
from imu_learn.data.splits import (
    data_root_dir,
    find_all,
    groundtruth_paths,
    make_split,
    parse_entry,
    recording_name,
    resolve_path,
    root_columns,
    split_signature,
)
from imu_learn.data.types import Segment, sample_rate_hz
from imu_learn.errors import (
    ConfigError,
    ImplausibleProfileError,
    ImuError,
    MethodError,
    one_line,
)
from imu_learn.eval import report
from imu_learn.infer import guard, rates
from imu_learn.score import peers
from imu_learn.score.metrics import fit_startup_bias, index_at, remove_bias, rmse, with_imu
from imu_learn.score.peers import PeerErrors, add_segment, summarise
from imu_learn.score.protocol import VARIANTS
from imu_learn.settings import hints_of, merge, nest
from imu_learn.train.config import (
    RunConfig,
    build_config,
    from_dict,
    parse_overrides,
    parse_value,
    read_toml,
    split_overrides,
)
from imu_learn.util.atomic import atomic_write_path, atomic_write_text
from imu_learn.util.extras import require_extra

logger = logging.getLogger(__name__)
CHECKPOINT_NAME = "proposed (fit run)"  # the row of a --checkpoint


# ---------------------------------------------------------------------------------------------
# configuration


@dataclass
class EvalSettings:
    horizons: List[int] = field(default_factory=lambda: [10, 50, 200])  # relative pose over n samples
    airimu_s: List[float] = field(default_factory=lambda: [0.5, 1.0, 2.0, 3.0])  # AirIMU's position horizons
    curve_min_s: float = 0.05  # integration error against horizon: shortest, longest, how many
    curve_max_s: float = 5.0
    curve_count: int = 12
    stride: int = 0  # window start step [samples]; 0: data.eval_stride
    startup_bias_s: float = 0.0  # seconds the start-up bias is fitted on (windows start after); 0: data.startup_bias_s
    noise_floor: str = "auto"  # auto (pose-only ground truth), always, never
    # The datasheet white noise the calibration table compares a learned covariance with
    # (continuous-time densities; default EuRoC's ADIS16448 sensor.yaml).
    gyro_noise_density: float = 1.6968e-4  # rad/s/sqrt(Hz)
    acc_noise_density: float = 2.0e-3  # m/s^2/sqrt(Hz)


@dataclass
class FitBudget:
    """The FitSettings every method gets (seed: the config's seed; gravity: data.gravity)."""

    window: int = 0  # 0: data.window
    batch_size: int = 32
    steps: int = 300
    lr: float = 1e-3
    device: str = "cpu"
    threads: int = 2


@dataclass
class EvalConfig:
    name: str = ""  # report folder name; default the config file's name without "eval_"
    base: str = ""  # fit config with the data and split (relative to this file, else as given)
    methods: List[str] = field(default_factory=lambda: list(DEFAULT_METHODS))
    seed: int = 0
    reports_dir: str = "reports"
    eval: EvalSettings = field(default_factory=EvalSettings)
    fit: FitBudget = field(default_factory=FitBudget)


@dataclass
class Resolved:
    cfg: EvalConfig
    run: RunConfig  # base fit config with [data] overrides: its .data is what is used
    path: Optional[Path]
    base_path: Optional[Path]

    @property
    def stride(self) -> int:
        return self.cfg.eval.stride or self.run.data.eval_stride

    @property
    def startup_bias_s(self) -> float:
        return self.cfg.eval.startup_bias_s or self.run.data.startup_bias_s

    def fit_settings(self) -> FitSettings:
        f = self.cfg.fit
        return FitSettings(window=f.window or self.run.data.window, batch_size=f.batch_size, steps=f.steps, lr=f.lr,
                           seed=self.cfg.seed, device=f.device, threads=f.threads, gravity=self.run.data.gravity,
                           horizons=tuple(sorted({int(n) for n in self.cfg.eval.horizons})))


def _resolve_base(base: str, cfg_path: Optional[Path]) -> Path:
    p = Path(base).expanduser()
    if not p.is_absolute() and cfg_path is not None and (cfg_path.parent / p).exists():
        return cfg_path.parent / p
    return resolve_path(base)


def _eval_field_type(key: str) -> Any:
    cls: Any = EvalConfig
    parts = key.split(".")
    for i, part in enumerate(parts):
        names = {f.name for f in fields(cls)} if hasattr(cls, "__dataclass_fields__") else set()
        if part not in names:
            where = ".".join(parts[:i]) or "top level"
            raise ConfigError(f"--{key}: unknown key (known in {where}: {', '.join(sorted(names)) or 'none'})")
        cls = hints_of(cls)[part]
    return cls


def load_eval_config(path: Optional[Path] = None, overrides: Seq[str] = ()) -> Resolved:
    """Defaults, then the eval TOML ``path``, then ``--key value`` overrides (``data.*`` go to the
    fit config's data; the rest to :class:`EvalConfig`)."""
    raw = dict(read_toml(Path(path))) if path else {}
    data_over = raw.pop("data", {})
    if not isinstance(data_over, dict):
        raise ConfigError("data: expected a table")
    flat_data: List[str] = []
    flat_eval: Dict[str, Any] = {}
    for key, text in split_overrides(overrides, usage="--key value"):
        if key.startswith("data."):
            flat_data += [f"--{key}", text]
        else:
            flat_eval[key] = parse_value(key, text, _eval_field_type(key))
    nested = nest(flat_eval)
    merged = merge(raw, nested)
    cfg = from_dict(EvalConfig, merged)
    base_path = _resolve_base(cfg.base, Path(path) if path else None) if cfg.base else None
    if base_path is not None and not base_path.is_file():
        raise ConfigError(f"{path or 'the config'}: base = {cfg.base!r}: no such run config (a path relative to the "
                          "config's folder, the working directory or the checkout)")
    base = read_toml(base_path) if base_path is not None else {}
    run = build_config(merge(base, {"data": data_over}), parse_overrides(flat_data))
    if not cfg.name:
        stem = Path(path).stem if path else "default"
        cfg.name = stem[5:] if stem.startswith("eval_") and len(stem) > 5 else stem
    _validate(cfg)
    return Resolved(cfg, run, Path(path) if path else None, base_path)


def _validate(cfg: EvalConfig) -> None:
    e, f = cfg.eval, cfg.fit

    def need(ok: bool, key: str, what: str) -> None:
        if not ok:
            raise ConfigError(f"{key}: {what}")

    need(len(cfg.methods) > 0, "methods", "give at least one method")
    need(len(e.horizons) > 0 and all(n >= 1 for n in e.horizons), "eval.horizons", "must be >= 1 samples")
    need(all(s > 0 for s in e.airimu_s), "eval.airimu_s", "must be positive")
    need(0 < e.curve_min_s < e.curve_max_s, "eval.curve_min_s", "need 0 < curve_min_s < curve_max_s")
    need(e.curve_count >= 2, "eval.curve_count", "must be at least 2")
    need(e.stride >= 0, "eval.stride", "must be >= 0")
    need(e.startup_bias_s >= 0, "eval.startup_bias_s", "must be >= 0")
    need(e.noise_floor in ("auto", "always", "never"), "eval.noise_floor", f"expected auto, always or never, got {e.noise_floor!r}")
    need(f.steps >= 0 and f.batch_size >= 1 and f.threads >= 1 and f.lr > 0 and f.window >= 0, "fit",
         "steps >= 0, batch_size >= 1, threads >= 1, lr > 0, window >= 0")
    need(re.fullmatch(r"[A-Za-z0-9_.\-]+", cfg.name) is not None, "name", f"{cfg.name!r}: use letters, digits, . _ -")


# ---------------------------------------------------------------------------------------------
# methods


class CheckpointRefiner(Method):
    """The refiner trained by ``python -m imu_learn.fit``, from its checkpoint (``best.pt``)."""

    name = "proposed"
    rotation_only = False

    def __init__(self, path: Path, device: str = "cpu") -> None:
        import torch

        from imu_learn.infer.checkpoint import imu_record, load_checkpoint, model_from_checkpoint

        self.path = Path(path)
        state = load_checkpoint(self.path, map_location=device)
        self.config = state.get("config") or {}
        self.sample_rate_hz: Optional[float] = imu_record(state)["sample_rate_hz"]  # None: not recorded
        self.device = torch.device(device)
        self.model = model_from_checkpoint(state).to(self.device)
        self.window = self.model.windowing.window  # the checkpoint's rule (imu_learn.infer.windowing)
        if not_shipped(self.path):
            logger.warning(not_shipped(self.path))

    def splits(self) -> Dict[str, List[str]]:
        sp = (self.config.get("data") or {}).get("split") or {}
        return {k: list(sp.get(k) or []) for k in ("train", "val", "test")}

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        from imu_learn.infer.windowing import apply

        gyro, acc, _ = apply(self.model, seq.gyro, seq.acc)
        return gyro, acc


def _recording(label: str) -> str:
    return parse_entry(label).name


def check_checkpoint_rate(m: CheckpointRefiner, test: Seq[Segment]) -> None:
    """Refused (before any fit) where a test recording's rate is more than the rates rule's tolerance off
    the one the model was made for (refine's and navigate's rule, :mod:`imu_learn.infer.rates`)."""
    made = m.sample_rate_hz
    for seg in test if made else ():
        rate = sample_rate_hz(seg.t_ns)
        if rate and abs(rate - made) > rates.TOLERANCE * made:
            raise ConfigError(f"--checkpoint {m.path}: made for {rates.hz(made)}, but test recording "
                              f"{_recording(seg.name)} is sampled at {rates.hz(rate)} (more than "
                              f"{rates.TOLERANCE * 100:.0f} % off): evaluate a model trained on this device and rate")


def check_checkpoint_split(m: CheckpointRefiner, test_entries: List[str]) -> None:
    seen = {_recording(e): k for k in ("train", "val") for e in m.splits()[k]}
    for t in test_entries:
        r = _recording(t)
        if r in seen:
            raise ConfigError(f"--checkpoint {m.path}: its {seen[r]} split uses {r}, a test recording here "
                              "(test sequences must never be seen in training or selection)")


def check_profiles(methods: List[str], test_entries: List[str], test: Seq[Segment]) -> None:
    """Each ``profile:PATH`` method, before any fit: refused where it was fitted on a test recording (the
    checkpoint's rule, :func:`check_checkpoint_split`: its ``sources``), and one warning per test recording
    that looks unlike the IMU it was fitted on (refine's guard, :func:`imu_learn.infer.guard.verdict`: the
    locations of the raw IMU's statistics, the profile's ``inputs``)."""
    tests = {_recording(t) for t in test_entries}
    for name in methods:
        if not name.startswith(PROFILE_PREFIX):
            continue
        path = name[len(PROFILE_PREFIX):]
        if not Path(path).is_file():  # before any method is fitted or written
            raise FileNotFoundError(2, "No such file or directory (--methods profile:PATH)", path)
        profile = Profile.load(path)  # malformed or edited: refine's reader names the field
        finding = applied_floor_finding(profile.floor, profile.gravity_mps2, name)
        if finding is not None:
            raise ImplausibleProfileError(finding[0], field=finding[1])
        fitted = {Path(str(s.get("recording", ""))).name for s in profile.sources or [] if isinstance(s, dict)}
        for r in sorted(tests & fitted):
            raise ConfigError(f"{name}: the profile was fitted on {r}, a test recording here (test sequences must "
                              "never be seen in training or selection): score it on recordings it did not see")
        for r, source in _same_stamps(profile.sources or [], test):
            raise ConfigError(f"{name}: the profile was fitted on {source}, whose stamps are test recording {r}'s (the "
                              "same data under another name; test sequences must never be seen in training or "
                              "selection): score it on recordings it did not see")
        seen = set()
        for seg in sorted(test, key=len, reverse=True):  # each test recording once, its longest segment
            rec = recording_name(seg.name)
            if rec in seen:
                continue
            seen.add(rec)
            # refine's rate rule: a profile's observed time offset and its low-pass belong to its rate
            for line in rates.check(rec, sample_rate_hz(seg.t_ns), None, [rates.MadeFor(
                    f"profile {path}", profile.sample_rate_hz, profile.device, profile.rate_terms())], forceable=False):
                logger.warning(line)
            _entry, warning, _info = guard.verdict(profile.inputs or None, guard.input_stats(seg.t_ns, seg.gyro, seg.acc),
                                                   f"profile {path}", device_only=True)
            if warning:
                logger.warning("%s: %s", rec, warning)


def _same_stamps(sources: List[Any], test: Seq[Segment]) -> List[Tuple[str, str]]:
    """(test recording, profile source) pairs where a stretch the profile was fitted on (its ``sources``'
    ``train`` / ``val`` spans, stamps in ns) lies mostly (over half of it) inside a test segment's stamps: a
    test recording converted to a CSV is another name for the same data (a user's MH_04 as ``my_imu.csv``)."""
    out = []
    for src in sources:
        if not isinstance(src, dict):
            continue
        for part in (src.get("train") or []) + (src.get("val") or []):
            t0, t1 = part.get("t0_ns") if isinstance(part, dict) else None, part.get("t1_ns") if isinstance(part, dict) else None
            if not isinstance(t0, int) or not isinstance(t1, int) or t1 <= t0:
                continue
            for seg in test:
                inside = min(t1, int(seg.t_ns[-1])) - max(t0, int(seg.t_ns[0]))
                if inside > 0.5 * (t1 - t0):
                    pair = (recording_name(seg.name), str(src.get("recording", "?")))
                    if pair not in out:
                        out.append(pair)
    return out


# ---------------------------------------------------------------------------------------------
# metrics


def window_starts(seq: Segment, n: int, stride: int, first: int) -> np.ndarray:
    """Starts first, first+stride, ... with k + n <= len - 1 (the end state is a ground-truth sample)."""
    return np.arange(int(first), len(seq) - int(n), int(stride), dtype=np.int64)


def pose_errors(seq: Segment, starts: np.ndarray, n: int, pred: PosePrediction) -> Dict[str, np.ndarray]:
    """Per-window errors of ``pred`` (end states of windows of n samples) against the ground truth
    of ``seq``: ``rot_rad``, ``trans_m`` (nan without p), ``vel_mps`` (nan without v)."""
    j = np.asarray(starts, dtype=np.int64) + int(n)
    rot = rotation_angle(seq.q_wxyz[j], np.asarray(pred.q_wxyz, dtype=np.float64))
    nan = np.full(len(j), np.nan)
    trans = nan if pred.p is None else np.linalg.norm(np.asarray(pred.p) - seq.p[j], axis=-1)
    vel = nan if getattr(pred, "v", None) is None else np.linalg.norm(np.asarray(pred.v) - seq.v[j], axis=-1)
    return {"rot_rad": rot, "trans_m": trans, "vel_mps": vel}


def seconds_to_samples(seconds: float, rate: float) -> int:
    return max(1, int(round(seconds * rate)))


def curve_seconds(e: EvalSettings) -> List[float]:
    return [float(x) for x in np.geomspace(e.curve_min_s, e.curve_max_s, e.curve_count)]


def horizon_plan(seq: Segment, e: EvalSettings) -> Dict[str, Any]:
    """Horizons [samples] to evaluate on ``seq``: the table's n, and seconds -> samples."""
    rate = sample_rate_hz(seq.t_ns)
    secs = sorted(set([1.0] + list(e.airimu_s) + curve_seconds(e)))
    by_s = {float(s): seconds_to_samples(s, rate) for s in secs}
    return {"rate_hz": rate, "by_s": by_s, "n": sorted(set(int(n) for n in e.horizons) | set(by_s.values()))}


def is_refiner(method: Method) -> bool:
    return type(method).predict is Method.predict


def evaluate_sequence(method: Method, seq: Segment, horizons: Seq[int], stride: int, startup_bias_s: float,
                      gravity: float = 9.81, peers: Optional[Dict[str, Any]] = None
                      ) -> Tuple[Dict[Tuple[str, int], Dict[str, np.ndarray]], Dict[str, Any]]:
    """Errors of ``method`` on ``seq``: {(variant, n): per-window errors} and the fitted start-up bias.

    Refiners: ``refine`` once; the bias is fitted on the refined samples and removed from them; both
    variants are integrated from the ground-truth start state. Regressors: the bias is fitted on the
    raw input and removed from it before ``predict``. ``peers`` (a dict), when given, is filled with the
    open-loop errors of :mod:`imu_learn.score.peers` on the whole segment (refiners: AOE from the refined
    samples and the 1 s windows; regressors: the 1 s windows from ``predict`` on the raw input, no AOE).
    """
    first = index_at(seq, startup_bias_s)
    refiner = is_refiner(method)
    if refiner:
        gyro, acc = method.refine(seq)
        base = with_imu(seq, gyro, acc)
    else:
        base = seq
    if peers is not None:
        peers.update(_peer_errors(method, base, refiner, gravity))
    bg, ba = fit_startup_bias(base, startup_bias_s, gravity=gravity)
    inputs = dict(zip(VARIANTS, (base, remove_bias(base, bg, ba))))
    out: Dict[Tuple[str, int], Dict[str, np.ndarray]] = {}
    for variant, s in inputs.items():
        for n in horizons:
            starts = window_starts(seq, n, stride, first)
            if starts.size == 0:
                continue
            if refiner:
                pred = poses_from_imu(s, s.gyro, s.acc, starts.astype(np.uint64), int(n), gravity)
                if method.rotation_only:
                    pred = PosePrediction(pred.q_wxyz, None, None)
            else:
                pred = method.predict(s, starts.astype(np.uint64), int(n), gravity)
            e = pose_errors(seq, starts, n, pred)
            e["starts"] = starts
            out[(variant, int(n))] = e
    bias = {"gyro": bg.tolist(), "acc": ba.tolist(), "fitted_on": "refined output" if refiner else "raw input"}
    return out, bias


def _peer_errors(method: Method, base: Segment, refiner: bool, gravity: float) -> Dict[str, Any]:
    """Open-loop peer errors of one segment (``base``: the refined samples of a refiner, the raw input
    of a regressor)."""
    if refiner:
        return peers.segment_errors(base, base.gyro, base.acc, gravity, position=not method.rotation_only)
    w = peers.window_samples(base)
    starts = peers.peer_window_starts(base, w)
    if starts.size == 0:
        return {"angle_rad": None, "yaw_rad": None, "rot_rad": np.zeros(0), "trans_m": np.zeros(0), "window": w}
    pred = method.predict(base, starts.astype(np.uint64), w, gravity)
    e = pose_errors(base, starts, w, pred)
    trans = None if pred.p is None else e["trans_m"]
    return {"angle_rad": None, "yaw_rad": None, "rot_rad": e["rot_rad"], "trans_m": trans, "window": w}


# ---------------------------------------------------------------------------------------------
# the run


def _ground_truth_kinds(run: RunConfig, test_entries: List[str]) -> Dict[str, str]:
    """Recording -> "pose-only (velocity derived)" or "with velocity", for the test recordings."""
    root_dir = data_root_dir(run.data)
    found = find_all(run.data.roots, root_dir)
    gt_paths = groundtruth_paths(run.data.roots, root_dir)
    out = {}
    for label in test_entries:
        rec = _recording(label)
        if rec in out or rec not in found:
            continue
        path, root = found[rec]
        _, gt = read_recording(path, root.format, gt_paths.get(id(root)), columns=root_columns(root))
        out[rec] = "pose-only (velocity derived)" if gt.v is None else "with velocity"
    return out


def _versions() -> Dict[str, str]:
    import polars
    import torch

    v = {"imu_learn": __version__, "torch": torch.__version__, "numpy": np.__version__,
         "polars": polars.__version__, "python": platform.python_version()}
    try:
        import matplotlib

        v["matplotlib"] = matplotlib.__version__
    except ImportError:  # pragma: no cover
        v["matplotlib"] = "not installed"
    return v


def _seed_all(seed: int) -> None:
    import torch

    random.seed(seed)
    np.random.seed(seed % (2**32))
    torch.manual_seed(seed)


def prepare_method(name: str, factory: Callable[[], Method], res: Resolved, split: Any, methods_dir: Path,
                   settings: FitSettings, reuse: bool) -> Tuple[Method, Dict[str, Any]]:
    """Fit ``name`` on the train split (or load it with ``reuse``); returns the method and its record."""
    method = factory()
    fname = safe_name(name)
    rec_path = methods_dir / f"{fname}.record.json"  # not <name>.json: that is where e.g. traditional saves its fit
    file = method_file(methods_dir, name, method)
    sig = {"fit_settings": settings.record(), "split": split_signature(split.record, ("train", "val")), "class": type(method).__qualname__}
    if reuse and rec_path.exists():
        old = _read_record(rec_path)
        same = old is not None and all(old.get(k) == json.loads(json.dumps(v)) for k, v in sig.items())
        if same and old is not None:
            try:
                if old.get("file") and Path(old["file"]).exists():
                    method = method.load(Path(old["file"])) or method
            except Exception as e:
                raise MethodError(f"{name}: loading {old['file']}: {one_line(e)}") from e
            return method, {**old, "status": "reused"}
        logger.info("%s: saved fit does not match the settings or split; refitting", name)
    _seed_all(settings.seed)
    t0 = time.time()
    try:
        log = method.fit(list(split.train), list(split.val), settings) or {}
    except (ValueError, RuntimeError, ImuError) as e:
        raise MethodError(f"{name}: fit failed: {one_line(e)}") from e
    fit_s = time.time() - t0
    saved = save_method(method, file)
    record = {**sig, "method": name, "fit_s": round(fit_s, 2), "file": str(file) if saved else None,
              "log": _summarise_log(log)}
    # The record last: a record names only a saved fit that is complete.
    atomic_write_text(rec_path, json.dumps(record, indent=2, default=str))
    return method, {**record, "status": "fitted"}


def _read_record(path: Path) -> Optional[Dict[str, Any]]:
    """A fit record, or None (after saying so) when it cannot be read: the method is refitted."""
    try:
        record = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        logger.warning("%s: unreadable fit record (%s); refitting", path, one_line(e))
        return None
    return record if isinstance(record, dict) else None


def save_method(method: Method, file: Path) -> bool:
    """``method.save`` to ``file`` atomically (the method writes a temporary file beside it, which
    then replaces ``file``); False, writing nothing, for a method without a ``save`` of its own
    (nothing fitted to keep, e.g. raw)."""
    if type(method).save is Method.save:
        return False

    def fill(tmp: Path) -> None:
        method.save(tmp)
        if tmp.stat().st_size == 0:  # e.g. a writer that appended its own suffix to the name
            raise MethodError(f"{file}: {type(method).__name__}.save wrote nothing to the path it was given")

    atomic_write_path(file, fill)
    return True


def _summarise_log(log: Dict[str, Any]) -> Dict[str, Any]:
    """First/last values of list entries (a fit log can be long)."""
    out: Dict[str, Any] = {}
    for k, v in dict(log).items():
        if isinstance(v, (list, tuple)):
            vals = [x for x in v if isinstance(x, (int, float, str, type(None)))]
            out[k] = vals if len(vals) <= 6 else {"first": vals[0], "last": vals[-1], "count": len(vals)}
        elif isinstance(v, (int, float, str, bool, type(None))):
            out[k] = v
    return out


@dataclass
class _Rows:
    """The rows of an evaluation, in report order: (name, method), each one's record, the names
    whose module is not available, and the ``--checkpoint`` row's refiner (None without one)."""

    methods: List[Tuple[str, Method]] = field(default_factory=list)
    records: Dict[str, Dict[str, Any]] = field(default_factory=dict)
    skipped: List[str] = field(default_factory=list)
    checkpoint: Optional[CheckpointRefiner] = None

    def add(self, name: str, method: Method, record: Dict[str, Any]) -> None:
        self.methods.append((name, method))
        self.records[name] = record


def _fit_methods(res: Resolved, methods: List[str], split: Any, methods_dir: Path, settings: FitSettings,
                 reuse: bool) -> _Rows:
    """Resolve the methods, then fit (or load) each on the train split (val for its own selection)."""
    rows = _Rows()
    for name in methods:
        factory = load_method_class(name)
        if factory is None:
            rows.skipped.append(name)
            continue
        if name == "raw" or name.startswith(PROFILE_PREFIX):
            logger.info("%s: nothing to fit", name)
        else:
            logger.info("%s: %sfitting on the train split", name, "loading or " if reuse else "")
        rows.add(name, *prepare_method(name, factory, res, split, methods_dir, settings, reuse))
    return rows


def _checkpoint(checkpoint: Path, settings: FitSettings, test_entries: List[str], test: Seq[Segment]) -> CheckpointRefiner:
    """A full ``imu_learn.fit`` run (the row beside, not instead of, the same-budget "proposed"), checked
    before any fit: its splits against the test recordings, its rate against theirs."""
    ck = CheckpointRefiner(checkpoint, "cpu" if settings.device == "auto" else settings.device)
    check_checkpoint_split(ck, test_entries)
    check_checkpoint_rate(ck, test)
    return ck


def _add_checkpoint(rows: _Rows, ck: CheckpointRefiner) -> None:
    rows.add(CHECKPOINT_NAME, ck, {"status": "checkpoint", "file": str(ck.path), "checkpoint_split": ck.splits()})
    rows.checkpoint = ck


def _add_noise_floor(rows: _Rows, noise_floor: str, gt_kinds: Dict[str, str], gravity: float) -> None:
    """The ground-truth IMU row (``eval.noise_floor``; "auto": where a test ground truth is pose-only)."""
    if noise_floor == "always" or (noise_floor == "auto" and any(k.startswith("pose-only") for k in gt_kinds.values())):
        rows.add(NOISE_FLOOR_NAME, GroundTruthImu(gravity),
                 {"status": "reference (synthesised from the test ground truth)"})


def _bias_row(name: str, seg: str, rec: str, bias: Dict[str, Any]) -> Dict[str, Any]:
    return {"method": name, "segment": seg, "recording": rec, "fitted_on": bias["fitted_on"],
            **{f"gyro_bias_{a}": b for a, b in zip("xyz", bias["gyro"])},
            **{f"acc_bias_{a}": b for a, b in zip("xyz", bias["acc"])}}


def _evaluate_all(rows: _Rows, test: List[Segment], plans: Dict[str, Dict[str, Any]], stride: int, bias_s: float,
                  gravity: float, progress: bool, peer_out: Optional[Dict[Tuple[str, str], Any]] = None
                  ) -> Tuple[Dict[Tuple[str, str, str, int], List[Dict[str, np.ndarray]]], List[Dict[str, Any]]]:
    """Every row on every test segment: per-window errors by (method, variant, recording, n), the
    fitted start-up biases; each row's evaluation time goes into its record (``eval_s``). ``peer_out``
    (when given) collects the open-loop peer errors by (method, recording), segments pooled."""

    errors: Dict[Tuple[str, str, str, int], List[Dict[str, np.ndarray]]] = {}
    biases: List[Dict[str, Any]] = []
    tasks = [(name, m, s) for name, m in rows.methods for s in test]
    bar = tqdm(tasks, desc="evaluate", unit="seq", disable=not progress, dynamic_ncols=True, file=sys.stderr)
    t_eval: Dict[str, float] = {}
    for name, m, s in bar:
        bar.set_postfix_str(f"{name} / {s.name}", refresh=True)
        t0 = time.time()
        try:
            seg_peers: Optional[Dict[str, Any]] = {} if peer_out is not None else None
            errs, bias = evaluate_sequence(m, s, plans[s.name]["n"], stride, bias_s, gravity, peers=seg_peers)
        except (ValueError, RuntimeError) as e:
            raise MethodError(f"{name} on {s.name}: {one_line(e)}") from e
        t_eval[name] = t_eval.get(name, 0.0) + time.time() - t0
        rec = s.name.split("#")[0]
        for (variant, n), e in errs.items():
            errors.setdefault((name, variant, rec, n), []).append(e)
        biases.append(_bias_row(name, s.name, rec, bias))
        if peer_out is not None and seg_peers:
            add_segment(peer_out.setdefault((name, rec), PeerErrors()), seg_peers)
    bar.close()
    for name in t_eval:
        rows.records.setdefault(name, {})["eval_s"] = round(t_eval[name], 2)
    return errors, biases


def _calibration(rows: _Rows, test: List[Segment], e: EvalSettings, stride: int, bias_s: float,
                 gravity: float) -> List[Dict[str, Any]]:
    """The calibration table of a ``--checkpoint`` with a covariance head (else none)."""
    ck = rows.checkpoint
    if ck is None or ck.model.cov_head is None:
        return []
    from imu_learn.eval.calibration import evaluate_calibration

    logger.info("calibration of the learned covariance of %s", ck.path)
    return evaluate_calibration(ck.model, test, list(e.horizons), stride, bias_s,
                                e.gyro_noise_density, e.acc_noise_density, gravity)


def _per_recording(test: List[Segment], plans: Dict[str, Dict[str, Any]]) -> Tuple[Dict[str, float], Dict[str, Any]]:
    """Sample rate and horizon plan (seconds -> samples) of each test recording."""
    rates: Dict[str, float] = {}
    for s in test:
        rates.setdefault(s.name.split("#")[0], plans[s.name]["rate_hz"])
    by_s: Dict[str, Any] = {rec: {} for rec in rates}
    for s in test:
        by_s[s.name.split("#")[0]] = plans[s.name]["by_s"]
    return rates, by_s


def _error_rows(errors: Dict[Tuple[str, str, str, int], List[Dict[str, np.ndarray]]],
                rates: Dict[str, float]) -> List[Dict[str, Any]]:
    """RMSE of each (method, variant, recording, n) over its windows (all segments pooled)."""
    rows = []
    for (name, variant, rec, n), es in sorted(errors.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2], kv[0][3])):
        cat = {k: np.concatenate([e[k] for e in es]) for k in ("rot_rad", "trans_m", "vel_mps")}
        r = rmse(cat["rot_rad"])
        rows.append({"method": name, "variant": variant, "sequence": rec, "n": n, "horizon_s": n / rates[rec],
                     "rot_rad": r, "rot_deg": math.degrees(r), "trans_m": rmse(cat["trans_m"]),
                     "vel_mps": rmse(cat["vel_mps"]), "windows": int(cat["rot_rad"].size)})
    return rows


def _peer_rows(rows: _Rows, peer_out: Dict[Tuple[str, str], Any], recordings: List[str]) -> List[Dict[str, Any]]:
    """One row per (method, test recording): the peers' open-loop metrics (:mod:`imu_learn.score.peers`)."""
    return [{"method": name, "sequence": rec, **summarise(peer_out[(name, rec)])}
            for name, _ in rows.methods for rec in recordings if (name, rec) in peer_out]


def _result(res: Resolved, settings: FitSettings, methods: List[str], split: Any, rows: _Rows,
            plans: Dict[str, Dict[str, Any]], gt_kinds: Dict[str, str], measured: Dict[str, Any]) -> Dict[str, Any]:
    """The result dict the report is written from (``measured``: rows, calibration, biases)."""
    cfg, data = res.cfg, res.run.data
    rates, by_s = _per_recording(split.test, plans)
    return {
        "config_name": cfg.name,
        "config_path": str(res.path) if res.path else None,
        "base_path": str(res.base_path) if res.base_path else None,
        "eval": asdict(cfg.eval),
        "stride": res.stride,
        "startup_bias_s": res.startup_bias_s,
        "fit_settings": settings.record(),
        "seed": cfg.seed,
        "methods": [n for n, _ in rows.methods],
        "requested": list(methods),
        "skipped": rows.skipped,
        "records": rows.records,
        "split": split.record,
        "test_sequences": list(rates),
        "test_segments": [{"name": s.name, "samples": len(s), "duration_s": round(s.duration_s, 3)} for s in split.test],
        "ground_truth": gt_kinds,
        "rates_hz": rates,
        "horizons_by_s": by_s,
        "curve_s": curve_seconds(cfg.eval),
        "rows": _error_rows(measured["errors"], rates),
        "calibration": measured["calibration"],
        "biases": measured["biases"],
        "peers": measured.get("peers", []),
        "versions": _versions(),
        "roots": [asdict(r) for r in data.roots],
        "data_root": split.record.get("data_root"),
        "gravity": data.gravity,
    }


def run_evaluation(res: Resolved, methods: List[str], out_dir: Path, reuse: bool = False,
                   checkpoint: Optional[Path] = None, progress: bool = True,
                   t_start: Optional[float] = None) -> Dict[str, Any]:
    """Fit (or reuse) the methods, evaluate them on the test split, write the report; returns the result.
    ``t_start``: when the command started (wall time is measured from it; default now)."""
    require_extra("eval", "evaluate")  # torch, and polars and matplotlib for the report
    import torch

    t_start = time.time() if t_start is None else t_start
    cfg, data = res.cfg, res.run.data
    settings = replace(res.fit_settings(), progress=progress)
    torch.set_num_threads(settings.threads)
    split = make_split(data)
    if not split.test:
        raise ConfigError("data.split.test: no test sequence (of at least one window)")
    test_entries = list(data.split.test)
    ck = None if checkpoint is None else _checkpoint(checkpoint, settings, test_entries, split.test)
    check_profiles(methods, test_entries, split.test)
    out_dir.mkdir(parents=True, exist_ok=True)
    methods_dir = out_dir / "methods"
    methods_dir.mkdir(exist_ok=True)

    rows = _fit_methods(res, methods, split, methods_dir, settings, reuse)
    if ck is not None:
        _add_checkpoint(rows, ck)
    gt_kinds = _ground_truth_kinds(res.run, test_entries)
    _add_noise_floor(rows, cfg.eval.noise_floor, gt_kinds, data.gravity)

    stride, bias_s = res.stride, res.startup_bias_s
    plans = {s.name: horizon_plan(s, cfg.eval) for s in split.test}
    peer_out: Dict[Tuple[str, str], Any] = {}
    errors, biases = _evaluate_all(rows, split.test, plans, stride, bias_s, data.gravity, progress, peer_out)
    calibration = _calibration(rows, split.test, cfg.eval, stride, bias_s, data.gravity)
    result = _result(res, settings, methods, split, rows, plans, gt_kinds,
                     {"errors": errors, "calibration": calibration, "biases": biases,
                      "peers": _peer_rows(rows, peer_out, list(dict.fromkeys(s.name.split("#")[0] for s in split.test)))})
    result["wall_s"] = time.time() - t_start
    report.write_report(out_dir, result)
    result["wall_s"] = time.time() - t_start
    return result
