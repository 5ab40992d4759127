"""Checkpoints: everything needed to rebuild a run, loaded without executing pickled code.

A checkpoint is a ``torch.save`` of a dict holding only tensors and plain Python values (str, int,
float, bool, list, dict, None), and is always loaded with ``weights_only=True``. It stores the model
args (so the model can be rebuilt), the model weights (normalisation buffers included), the
optimiser state, the full run config, epoch, step, best metric, and the code version.
Writes go through :mod:`imu_learn.util.atomic` (a temporary file renamed into place), so a kill never
leaves half a checkpoint over a good one. Every checkpoint also carries ``digest``, a sha256 of its
whole content (each tensor's dtype, shape and bytes, and every plain value), checked on load: a
truncated or modified file is a :class:`CheckpointError` naming it, never a model with altered
weights (torch's own zip reader does not notice a changed byte in a tensor's data).

A checkpoint is self-contained for inference: ``python -m imu_learn.refine`` needs nothing from the
run folder beside it (the normalisation is in the weights, the architecture in ``model_args``).
A run's ``best.pt`` also carries the optimiser state and the metrics history; to ship a model, strip
those (the result still loads everywhere a checkpoint does, but cannot be resumed)::

    imu-learn checkpoint strip runs/NAME/best.pt models/NAME.pt
    imu-learn checkpoint info models/NAME.pt      # what a checkpoint holds, for a model card

What the model is for (:func:`imu_record`): a checkpoint records the IMU it was trained on,
``sample_rate_hz`` (the one sample-rate rule, :func:`imu_learn.data.types.sample_rate_hz`, over the
training segments) and ``device`` (``data.device`` of the run config, else the training datasets'
names, e.g. ``euroc``), and, for a model trained on top of a device profile, ``profile`` (the
profile's content, applied before the model; or, where ``model_args["start"]`` is "profile", held
by the model itself as its fixed calibration and FIR shift, so applied once, inside it:
:func:`imu_record`'s ``profile_in_model``). Checkpoints written before that carry none of them;
their rate comes from their config: the training datasets' nominal rates (:data:`DATASET_RATE_HZ`).
``config["device"]`` is where the run trained (cpu, cuda), not the IMU.
"""
from __future__ import annotations

import hashlib
import json
import os
import warnings
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

import torch

from imu_learn._imu_core import __version__
from imu_learn.data.types import Segment, sample_rate_hz
from imu_learn.errors import CheckpointError  # noqa: F401  (defined with every error class)
from imu_learn.infer import guard
from imu_learn.infer.windowing import apply, attach, windowing_of_config
from imu_learn.nn.config import ARGS_BEFORE
from imu_learn.nn.model import ImuRefiner, ModelConfig
from imu_learn.util.atomic import atomic_write_bytes
from imu_learn.util.file_kind import mix_up
from imu_learn.util.outputs import check_replaceable

FORMAT = "imu_learn.checkpoint.v1"
# What the model is for (module doc), kept at the top level of a checkpoint when known.
RECORD_KEYS = ("sample_rate_hz", "device", "profile", "inputs")
# What the model adds is measured on at most this much of each training segment at each save [s].
RESIDUAL_MAX_S = 120.0
# What a stripped (shipped) checkpoint keeps: everything inference and a model card need (and the
# record's keys where the source has them).
STRIPPED_KEYS = ("format", "code_version", "model_args", "model", "config", "epoch", "step", "best_metric")
# The nominal IMU rate of each public dataset [Hz], for checkpoints that record no rate of their own.
DATASET_RATE_HZ: Dict[str, float] = {"euroc": 200.0, "tum-vi": 200.0, "blackbird": 100.0, "fetch": 100.0,
                                     "broad": 285.7}
STRIPPED_EXTRA = ("best_epoch", "elapsed_s", "world_size")
DIGEST_KEY = "digest"


def save_checkpoint(
    path: Path,
    model: ImuRefiner,
    config: Dict[str, Any],
    epoch: int,
    step: int,
    best_metric: Optional[float],
    optimizer: Optional[torch.optim.Optimizer] = None,
    extra: Optional[Dict[str, Any]] = None,
    record: Optional[Dict[str, Any]] = None,
) -> None:
    """``record``: what the model is for (:func:`training_record`; module doc), stored at the top level;
    where it holds the training inputs, what ``model`` adds to them is measured now (:func:`with_residual`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {
        "format": FORMAT,
        "code_version": __version__,
        "model_args": model.model_args(),
        "model": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "optimizer": None if optimizer is None else optimizer.state_dict(),
        "config": config,
        "epoch": int(epoch),
        "step": int(step),
        "best_metric": None if best_metric is None else float(best_metric),
        "extra": extra or {},
    }
    record = measured_record(record, model, config)
    state.update({k: v for k, v in (record or {}).items() if k in RECORD_KEYS and v is not None})
    write_checkpoint(path, state)


def measured_record(record: Optional[Dict[str, Any]], model: ImuRefiner,
                    config: Optional[Dict[str, Any]]) -> Optional[Dict[str, Any]]:
    """``record`` with what ``model`` adds to its training inputs measured (:func:`with_residual`) and
    the training IMU it was measured on dropped; a record without that IMU is returned as it is. A
    caller saving the same model twice (best.pt and last.pt of one epoch) measures once with this."""
    if not (record and record.get("inputs") and record.get(PROBE_KEY)):
        return record
    rest = {k: v for k, v in record.items() if k != PROBE_KEY}
    return {**rest, "inputs": with_residual(record["inputs"], model, record[PROBE_KEY], config)}


# --------------------------------------------------------------------------------------------
# What a model is for: the IMU's rate and device
# --------------------------------------------------------------------------------------------


def dataset_names(config: Optional[Dict[str, Any]]) -> List[str]:
    """The datasets a run config trained on, in order: each root's format where it names a dataset
    (euroc, tum-vi, blackbird, broad, fetch), else its path's first folder."""
    data = (config or {}).get("data") or {}
    names: List[str] = []
    for root in data.get("roots") or []:
        if not isinstance(root, dict):
            continue
        fmt, path = str(root.get("format") or ""), str(root.get("path") or "")
        name = fmt if fmt in DATASET_RATE_HZ else (Path(path).parts[0] if path and not Path(path).is_absolute() else fmt)
        if name and name not in names:
            names.append(name)
    return names


def configured_device(config: Optional[Dict[str, Any]]) -> Optional[str]:
    """``data.device`` of a run config, else its datasets' names joined by ``+`` (None: neither)."""
    data = (config or {}).get("data") or {}
    if isinstance(data.get("device"), str) and data["device"]:
        return data["device"]
    return "+".join(dataset_names(config)) or None


def training_record(segments: Sequence[Segment], config: Optional[Dict[str, Any]],
                    profile: Optional[Dict[str, Any]] = None, inputs: bool = False) -> Dict[str, Any]:
    """What a new checkpoint records of its training IMU: the one sample-rate rule over the training
    segments' stamps, the device (:func:`configured_device`), and the profile it trained on top of;
    with ``inputs``, the statistics of the segments' IMU for refine's guard (:func:`training_inputs_record`)."""
    rate = sample_rate_hz(*(s.t_ns for s in segments))
    record = {"sample_rate_hz": rate if rate > 0 else None, "device": configured_device(config), "profile": profile}
    return {**record, **training_inputs_record(segments)} if inputs else record


def training_inputs_record(segments: Sequence[Segment]) -> Dict[str, Any]:
    """The record's statistics of each training segment's IMU (``inputs``,
    :func:`imu_learn.infer.guard.training_inputs`), for refine's guard; ``PROBE_KEY`` holds the
    segments' IMU (not saved) for :func:`save_checkpoint` to measure what the model adds to it."""
    if not segments:
        return {}
    imu = [(s.name, s.t_ns, s.gyro, s.acc) for s in segments]
    return {"inputs": guard.training_inputs(imu), PROBE_KEY: imu}


PROBE_KEY = "_training_imu"


def with_residual(inputs: Dict[str, Any], model: ImuRefiner, recordings: Sequence[Any],
                  config: Optional[Dict[str, Any]]) -> Dict[str, Any]:
    """``inputs`` with ``residual_rms``: per training recording (name, t_ns, gyro, acc), the RMS per
    axis of what ``model`` adds (:func:`imu_learn.infer.guard.residual_rms`) over at most
    :data:`RESIDUAL_MAX_S` of it, by the windowing rule of ``config`` (the model's mode is restored)."""
    rule, was_training = windowing_of_config(config), model.training
    model.eval()
    out = []
    try:
        for name, t_ns, gyro, acc in recordings:
            n = len(gyro)
            if t_ns is not None and len(t_ns) > 1:
                n = int(min(n, RESIDUAL_MAX_S * sample_rate_hz(t_ns) + 1))
            g, a, _ = apply(model, gyro[:n], acc[:n], rule)
            out.append({"name": name, **guard.residual_rms(gyro[:n], acc[:n], g, a)})
    finally:
        model.train(was_training)
    return {**inputs, "residual_rms": out}


def with_training_inputs(state: Dict[str, Any], recordings: Sequence[Any]) -> Dict[str, Any]:
    """A loaded checkpoint ``state`` with the statistics of its training recordings (each (name,
    t_ns, gyro, acc), read the way it was trained) and what its model adds to them: for a checkpoint
    written before they were recorded (then :func:`write_checkpoint`)."""
    model = model_from_checkpoint(state)
    inputs = guard.training_inputs(recordings)
    return {**state, "inputs": with_residual(inputs, model, recordings, state.get("config"))}


def imu_record(state: Dict[str, Any]) -> Dict[str, Any]:
    """What a loaded checkpoint is for: ``sample_rate_hz`` (None: unknown), ``device`` (None:
    unknown), ``profile`` (a dict or None), ``inputs`` (its training statistics, None: not recorded)
    and ``source``: "recorded" (written with the checkpoint)
    or "config" (an older checkpoint: its training datasets' nominal rate, :data:`DATASET_RATE_HZ`;
    unknown where they disagree or none is known); ``profile_in_model``: the model holds the profile's
    floor itself (``model_args["start"]`` = "profile"), so nothing applies it before the model."""
    cfg = state.get("config") or {}
    in_model = (state.get("model_args") or {}).get("start") == "profile"
    if state.get("sample_rate_hz") is not None:
        return {"sample_rate_hz": float(state["sample_rate_hz"]), "device": state.get("device"),
                "profile": state.get("profile"), "profile_in_model": in_model, "inputs": state.get("inputs"),
                "source": "recorded"}
    rates = {DATASET_RATE_HZ.get(n) for n in dataset_names(cfg)}
    rate = rates.pop() if len(rates) == 1 else None
    return {"sample_rate_hz": rate, "device": state.get("device") or configured_device(cfg),
            "profile": state.get("profile"), "profile_in_model": in_model, "inputs": state.get("inputs"),
            "source": "config"}


def content_digest(state: Dict[str, Any]) -> str:
    """sha256 of a checkpoint's content without its ``digest`` entry: every key and plain value,
    and each tensor's dtype, shape and bytes, in a fixed order (the same after a save and load)."""
    h = hashlib.sha256()
    _hash_value(h, {k: v for k, v in state.items() if k != DIGEST_KEY})
    return h.hexdigest()


def _hash_value(h: Any, value: Any) -> None:
    if isinstance(value, torch.Tensor):
        t = value.detach().cpu().contiguous()
        h.update(f"tensor|{t.dtype}|{tuple(t.shape)}|".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
    elif isinstance(value, dict):
        # optimizer state has int keys, everything else str keys: sort by type name, then value
        items = sorted(value.items(), key=lambda kv: (type(kv[0]).__name__, str(kv[0])))
        h.update(f"dict|{len(items)}|".encode())
        for k, v in items:
            _hash_value(h, k)
            _hash_value(h, v)
    elif isinstance(value, (list, tuple)):
        h.update(f"list|{len(value)}|".encode())
        for v in value:
            _hash_value(h, v)
    else:  # str, int, float, bool, None: their repr is exact (floats round-trip)
        h.update(f"{type(value).__name__}|{value!r}|".encode())


def write_checkpoint(path: Path, state: Dict[str, Any]) -> None:
    """``state`` with its content digest, saved atomically to ``path``."""
    signed = {**state, DIGEST_KEY: content_digest(state)}
    atomic_write_bytes(path, lambda f: torch.save(signed, f))


def load_checkpoint(path: Path, map_location: str = "cpu") -> Dict[str, Any]:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    try:
        # A damaged file can make torch warn (e.g. bytes that read as an unknown pickle protocol)
        # before it raises: the one error line below says it all, so its warnings are not shown.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            state = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as e:  # torch raises many kinds for a damaged file; all mean "corrupt"
        what = mix_up(path, "checkpoint")
        first = str(e).strip().splitlines()[0] if str(e).strip() else ""
        # torch's advice to load with weights_only=False (arbitrary code) is no fix for a file that is not a checkpoint
        why = "" if what else (" (torch cannot read it as a checkpoint)" if first.startswith("Weights only load failed")
                               else _not_torch(path) or (" (truncated: the torch archive has no end; copy it again)"
                                                         if "central directory" in first
                                                         else f" ({type(e).__name__}: {first[:200]})"))
        raise CheckpointError(f"{path}: not a readable checkpoint{what}{why}") from e
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not an imu_learn checkpoint of format {FORMAT}")
    # Checkpoints written before digests (the shipped models/*.pt among them) have none and are
    # accepted as they are; every checkpoint written since carries one.
    if DIGEST_KEY in state and state[DIGEST_KEY] != content_digest(state):
        raise CheckpointError(f"{path}: truncated or modified: its content does not match the sha256 "
                              "recorded when it was written")
    check_content(path, state)
    return state


def _not_torch(path: Path) -> str:
    """Words for a file that is not a torch save at all (neither a zip archive nor a pickle), else ""."""
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError:
        return ""
    if head.startswith(b"PK") or head.startswith(b"\x80"):
        return ""
    return " (not a torch file: it holds text)" if head and all(32 <= b < 127 or b in (9, 10, 13) for b in head) \
        else " (not a torch file)"


def check_content(path: Path, state: Dict[str, Any]) -> None:
    """What the digest cannot vouch for (a checkpoint edited and saved without one, or written before
    digests): the weights present, finite, a positive input normalisation, and the model they rebuild
    (``model_args`` against their shapes); a CheckpointError naming the field otherwise."""
    weights = state.get("model")
    if not isinstance(weights, dict) or not weights:
        raise CheckpointError(f"{path}: field 'model' (the weights) is missing or empty: not a usable checkpoint")
    if not isinstance(state.get("model_args"), dict):
        raise CheckpointError(f"{path}: field 'model_args' is missing: the model cannot be rebuilt")
    for key, value in weights.items():
        if not torch.is_tensor(value):
            raise CheckpointError(f"{path}: field 'model.{key}' is a {type(value).__name__}, not a tensor")
        if value.is_floating_point() and not bool(torch.isfinite(value).all()):
            raise CheckpointError(f"{path}: field 'model.{key}' holds NaN or infinite values: the model would "
                                  "write NaN for every sample")
    std = weights.get("std")
    if torch.is_tensor(std) and bool((std <= 0).any()):
        raise CheckpointError(f"{path}: field 'model.std' (the input normalisation) is not positive: "
                              f"{[round(float(x), 6) for x in std.flatten()]}")
    try:
        model_from_checkpoint(state)
    except (TypeError, ValueError, KeyError, RuntimeError) as e:
        lines = [ln.strip() for ln in str(e).strip().splitlines() if ln.strip()]
        why = " ".join(lines[:2])[:300]
        raise CheckpointError(f"{path}: its model_args do not rebuild its weights ({type(e).__name__}: {why})") from e


def model_from_checkpoint(state: Dict[str, Any]) -> ImuRefiner:
    """The checkpoint's model in eval mode, with its windowing rule attached (the training window:
    :func:`imu_learn.infer.windowing.windowing_of_config`), so every path applies it alike."""
    model = ImuRefiner(ModelConfig(**{**ARGS_BEFORE, **state["model_args"]}))
    model.load_state_dict(state["model"])
    model.eval()
    attach(model, windowing_of_config(state.get("config")))
    return model


def load_model(path: Path, map_location: str = "cpu") -> ImuRefiner:
    """The trained model of a checkpoint, in eval mode."""
    return model_from_checkpoint(load_checkpoint(path, map_location))


def without_machine_paths(config: Dict[str, Any]) -> Dict[str, Any]:
    """A copy of a run config fit to ship: the training machine's absolute folders go (``data.data_root``
    and ``data.cache`` become "", ``runs_dir`` "runs"); recording paths stay (relative to the data
    root in every shipped config)."""
    cfg = json.loads(json.dumps(config))
    data = cfg.get("data") if isinstance(cfg.get("data"), dict) else {}
    for key, empty in (("data_root", ""), ("cache", "")):
        if isinstance(data.get(key), str) and Path(data[key]).is_absolute():
            data[key] = empty
    if isinstance(cfg.get("runs_dir"), str) and Path(cfg["runs_dir"]).is_absolute():
        cfg["runs_dir"] = "runs"
    return cfg


def strip_checkpoint(src: Path, dst: Path) -> Dict[str, Any]:
    """Write to ``dst`` (atomically) a copy of checkpoint ``src`` with only what inference needs:
    model args, weights (normalisation buffers included), config, epoch, step, best metric, code
    version, and from ``extra`` the best epoch, training time and world size. The optimiser state
    and the metrics history are dropped; ``extra["stripped_from"]`` names the source
    (``<run folder name>/<file>``; a stripped source keeps its own, the run it came from); the config
    loses the machine's absolute folders (:func:`without_machine_paths`). Weights are copied unchanged,
    so refining with the stripped checkpoint gives bit-identical output. ``dst`` may be an earlier
    stripped copy (it carries ``stripped_from``), never another file (:func:`check_replaceable`).
    Returns the stripped state."""
    src, dst = Path(src), Path(dst)
    if src.exists() and dst.exists() and os.path.samefile(src, dst):
        raise CheckpointError(f"{dst}: is the source checkpoint; write the stripped copy elsewhere")
    check_replaceable([dst], _not_stripped, "checkpoint strip", "remove it or give DST a new name")
    state = load_checkpoint(src)
    out: Dict[str, Any] = {k: state.get(k) for k in STRIPPED_KEYS}
    out.update({k: state[k] for k in RECORD_KEYS if state.get(k) is not None})
    out["config"] = without_machine_paths(state.get("config") or {})
    out["model"] = {k: v.detach().cpu().clone() for k, v in state["model"].items()}
    out["optimizer"] = None
    extra = state.get("extra") or {}
    out["extra"] = {k: extra[k] for k in STRIPPED_EXTRA if k in extra}
    out["extra"]["stripped_from"] = extra.get("stripped_from") or f"{src.resolve().parent.name}/{src.name}"
    model_from_checkpoint(out)  # refuse to write something that does not rebuild

    write_checkpoint(dst, out)
    return out


def _not_stripped(path: Path) -> Optional[str]:
    """None where ``path`` is a checkpoint that :func:`strip_checkpoint` wrote (``extra.stripped_from``),
    else what it is instead."""
    try:
        with open(path, "rb") as f:
            if f.read(2) != b"PK":  # not a torch archive: nothing to load
                return "not a checkpoint"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:  # unreadable, or not a torch save: not one of strip's outputs either way
        return "not a checkpoint"
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        return "not an imu_learn checkpoint"
    extra = state.get("extra")
    if not (isinstance(extra, dict) and extra.get("stripped_from")):
        return "a checkpoint without extra.stripped_from, which a stripped copy carries"
    return None


def describe(state: Dict[str, Any]) -> Dict[str, Any]:
    """A summary of a loaded checkpoint (plain values), as ``imu-learn checkpoint info`` prints."""
    cfg = state.get("config") or {}
    data = cfg.get("data") or {}
    n_params = sum(int(v.numel()) for k, v in state["model"].items() if k not in ("mean", "std"))
    return {
        "format": state.get("format"),
        "code_version": state.get("code_version"),
        "model_args": state.get("model_args"),
        "parameters": n_params,
        "normalisation": {k: [float(x) for x in state["model"][k]] for k in ("mean", "std") if k in state["model"]},
        "epoch": state.get("epoch"),
        "step": state.get("step"),
        "best_metric": state.get("best_metric"),
        "selected_on": (cfg.get("optim") or {}).get("select"),
        "has_optimizer": state.get("optimizer") is not None,
        "split": data.get("split"),
        "roots": [r.get("path") for r in data.get("roots") or []],
        "window": data.get("window"),
        "imu": {k: v for k, v in imu_record(state).items() if k not in ("profile", "profile_in_model", "inputs")},
        "training_statistics": [r.get("name") for r in (state.get("inputs") or {}).get("recordings", [])] or None,
        "profile": (state.get("profile") or {}).get("device"),
        "extra": {k: v for k, v in (state.get("extra") or {}).items() if k not in ("history", "partial")},
    }
