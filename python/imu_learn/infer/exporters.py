"""Export a trained refiner for use outside Python/imu_learn: TorchScript, ONNX and a JSON card.

    imu-learn export --checkpoint CKPT --out DIR [--window 200] [--opset 17]

writes into DIR:

- ``model.ts``: TorchScript (``torch.jit.trace`` of the whole-window forward); load with
  ``torch.jit.load`` (Python) or ``torch::jit::load`` (C++).
- ``model.onnx``: ONNX, input ``imu`` and output ``refined``, both (batch, time, 6) float32, with
  dynamic batch and time axes.
- ``model.json``: inputs, outputs, channel order and units, the normalisation that is built into
  the model, the model args, and the largest difference of each export from the torch model
  measured right after export on the trace length and on a different length/batch.

Only an earlier export's files are replaced: a ``model.json`` in DIR that is no export card, or a
``model.ts``/``model.onnx`` whose sha256 is not the one the card beside it records, is refused before any work.

Both exports take RAW IMU (gyro rad/s then acc m/s^2, the order and units of the training data):
the per-channel mean/std normalisation is stored inside the model, and the output is the refined
IMU (raw + correction) in the same units. For the causal model the exports are the stateless
whole-window forward (state starts at zero in each call); carried-state streaming is available in
Python through ``ImuRefiner.step`` / ``forward_with_state``.
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import torch

from imu_learn.errors import ConfigError, InvalidInputError
from imu_learn.infer.checkpoint import load_checkpoint, model_from_checkpoint
from imu_learn.infer.windowing import windowing_of
from imu_learn.nn.model import ImuRefiner
from imu_learn.util.atomic import atomic_write_path, atomic_write_text
from imu_learn.util.digest import file_sha256
from imu_learn.util.outputs import check_replaceable
from imu_learn.util.staging import staged_dir

CHANNELS = ["gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z"]
UNITS = ["rad/s"] * 3 + ["m/s^2"] * 3
CARD_FORMAT = "imu_learn.export.v1"


class WithVariance(torch.nn.Module):
    """What is exported for a model with a covariance head: (refined, variance), both (B, T, 6)."""

    def __init__(self, model: ImuRefiner) -> None:
        super().__init__()
        self.model = model

    def forward(self, imu: torch.Tensor):
        return self.model.forward_with_variance(imu)


def exported_module(model: ImuRefiner) -> torch.nn.Module:
    return WithVariance(model) if model.cov_head is not None else model


def output_names(model: ImuRefiner) -> List[str]:
    return ["refined", "variance"] if model.cov_head is not None else ["refined"]


def export_torchscript(model: ImuRefiner, example: torch.Tensor, path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traced = torch.jit.trace(exported_module(model), (example,), check_trace=False)
        atomic_write_path(path, lambda tmp: torch.jit.save(traced, str(tmp)))


def export_onnx(model: ImuRefiner, example: torch.Tensor, path: Path, opset: int = 17) -> None:
    names = output_names(model)
    axes = {k: {0: "batch", 1: "time"} for k in ["imu", *names]}
    module = exported_module(model)

    def write(tmp: Path) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:  # the TorchScript-based exporter: no extra dependency, dynamic axes for LSTMs
                torch.onnx.export(
                    module, (example,), str(tmp), input_names=["imu"], output_names=names,
                    dynamic_axes=axes, opset_version=opset, dynamo=False,
                )
            except TypeError:  # a torch without the dynamo= switch
                torch.onnx.export(
                    module, (example,), str(tmp), input_names=["imu"], output_names=names,
                    dynamic_axes=axes, opset_version=opset,
                )

    atomic_write_path(path, write)


def _reference(model: ImuRefiner, x: torch.Tensor) -> List[np.ndarray]:
    with torch.no_grad():
        if model.cov_head is None:
            return [model(x).numpy()]
        return [t.numpy() for t in model.forward_with_variance(x)]


def _check(run, model: ImuRefiner, x: torch.Tensor) -> Optional[float]:
    """Largest difference of the export's outputs from the model's on x (absolute for the refined
    samples, relative for the variances, which are orders of magnitude below 1), or None when the
    export cannot run on x."""
    ref = _reference(model, x)
    try:
        out = [np.asarray(o) for o in run(x)]
    except Exception:
        return None
    if len(out) != len(ref) or any(o.shape != r.shape for o, r in zip(out, ref)):
        return None
    diffs = [float(np.abs(out[0] - ref[0]).max())]
    if len(ref) > 1:
        diffs.append(float((np.abs(out[1] - ref[1]) / ref[1]).max()))
    return max(diffs)


def example_inputs(model: ImuRefiner, window: int, seed: int = 0) -> Tuple[torch.Tensor, torch.Tensor]:
    """Two plausible raw-IMU inputs from the model's own mean/std (the export does not depend on
    them): (1, window, 6) to trace with, and another batch size and length to check dynamic axes."""
    gen = torch.Generator().manual_seed(seed)
    mean, std = model.mean.float(), model.std.float()

    def sample(b: int, w: int) -> torch.Tensor:
        return mean + std * torch.randn(b, w, 6, generator=gen)

    return sample(1, window), sample(3, window + window // 2 + 1)


def _checks(run, model: ImuRefiner, example: torch.Tensor, other: torch.Tensor) -> Dict[str, Any]:
    return {
        "trace_shape": list(example.shape), "max_abs_diff_trace_shape": _check(run, model, example),
        "other_shape": list(other.shape), "max_abs_diff_other_shape": _check(run, model, other),
    }


def torchscript_checked(model: ImuRefiner, example: torch.Tensor, other: torch.Tensor, path: Path) -> Dict[str, Any]:
    """Write the TorchScript export to ``path``, reload it and compare it with the torch model."""
    export_torchscript(model, example, path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch >= 2.9 marks torch.jit as deprecated
        ts = torch.jit.load(str(path))

    def run_ts(x: torch.Tensor) -> List[np.ndarray]:
        with torch.no_grad():
            y = ts(x)
        return [t.numpy() for t in (y if isinstance(y, (tuple, list)) else (y,))]

    return _checks(run_ts, model, example, other)


def onnx_checked(model: ImuRefiner, example: torch.Tensor, other: torch.Tensor, path: Path,
                 opset: int) -> Dict[str, Any]:
    """Write the ONNX export to ``path`` and compare it with the torch model under onnxruntime
    (a note instead when onnxruntime is not installed)."""
    export_onnx(model, example, path, opset)
    try:
        import onnxruntime as ort
    except ImportError:
        return {"runtime": None, "note": "onnxruntime not installed; export not verified"}
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])

    def run_onnx(x: torch.Tensor) -> List[np.ndarray]:
        return sess.run(output_names(model), {"imu": x.numpy()})

    return {"runtime": f"onnxruntime {ort.__version__}", **_checks(run_onnx, model, example, other)}


def _io_spec(model: ImuRefiner) -> Dict[str, Any]:
    """The card's inputs and outputs: names, dtypes, shapes, channels and units."""
    imu = {"dtype": "float32", "shape": ["batch", "time", 6], "channels": CHANNELS}
    outputs = [{"name": "refined", **imu, "units": UNITS,
                "description": "refined IMU = raw + correction, same order and units"}]
    if model.cov_head is not None:
        outputs.append({
            "name": "variance", **imu, "units": ["(rad/s)^2"] * 3 + ["(m/s^2)^2"] * 3,
            "description": "per-sample noise variance of each refined sample, discrete-time (the variance of one "
                           "sample); a filter that wants a noise density takes sqrt(variance * dt) "
                           "[rad/s/sqrt(Hz), m/s^2/sqrt(Hz)], GTSAM's PreintegrationParams variance * dt",
        })
    inputs = [{"name": "imu", **imu, "units": UNITS,
               "description": "raw IMU samples in time order (not normalised: normalisation is inside the model)"}]
    return {"inputs": inputs, "outputs": outputs}


def windowing_card(model: ImuRefiner) -> Dict[str, Any]:
    """How ``imu-learn refine`` applies the model (:mod:`imu_learn.infer.windowing`), for a runtime that is to
    give the same samples: the exported graph is one window's forward pass."""
    w = windowing_of(model)
    if model.cfg.causal:
        return {"window": w.window, "overlap": 0, "rule": "causal: chunks of `window` samples (the remainder joined "
                "to the last) run in order with the LSTM state carried from one to the next; the exported graph "
                "starts each call from zero state, so run the whole sequence in one call to match refine"}
    return {"window": w.window, "overlap": w.overlap,
            "rule": "windows of `window` samples starting every window - overlap samples, the last moved back to end "
                    "at the sequence's end (a sequence of at most `window` samples: one call); in the overlap of "
                    "windows k and k+1, sample i comes from window k if i < (start of k+1 + end of k) // 2, else from "
                    "window k+1; the first and last windows keep their outer edges. Any other window gives other "
                    "samples (the model was trained on windows of this length)"}


def trained_on(state: Dict[str, Any]) -> Dict[str, Any]:
    """The training recordings' names and sample rates (the checkpoint's guard record): apply the model to
    this device at this rate (``imu-learn refine`` refuses one more than 5 % off)."""
    recs = (state.get("inputs") or {}).get("recordings") or []
    rates = [r.get("rate_hz") for r in recs if isinstance(r, dict) and r.get("rate_hz")]
    return {"recordings": [str(r.get("name")) for r in recs if isinstance(r, dict)],
            "sample_rate_hz": float(np.median(rates)) if rates else None}


def model_card(model: ImuRefiner, state: Dict[str, Any], checkpoint: Path, files: Dict[str, Path], window: int,
               opset: int, checks: Dict[str, Any]) -> Dict[str, Any]:
    """The JSON card of an export: I/O, normalisation, model args, checks, source checkpoint, digests.
    ``files``: {"torchscript": path, "onnx": path}."""
    def dyn(c: Dict[str, Any]) -> bool:
        d = c.get("max_abs_diff_other_shape")
        return d is not None and d < 1e-4

    dynamic = dyn(checks["torchscript"]) and dyn(checks["onnx"])
    return {
        "format": CARD_FORMAT,
        "files": {k: p.name for k, p in files.items()},
        **_io_spec(model),
        "normalisation": {
            "inside_model": True,
            "mean": [float(v) for v in model.mean.float()], "std": [float(v) for v in model.std.float()],
            "rule": ("cal = A imu + c where model.calib (the floor's affine calibration, inside the model; else cal = "
                     "imu); x_norm = (cal - mean) / std; refined = cal + std * (refined_channels * output_scale * "
                     "head(network(x_norm)) + fir(x_norm)) (fir: the floor's shift and low-pass where model.fir_taps, "
                     "on every channel with model.calib)"),
            "output_scale": float(model.cfg.output_scale),
        },
        "model_args": model.model_args(),
        "causal": bool(model.cfg.causal),
        "state": "each call starts from zero LSTM state; the bidirectional model needs context on both sides"
        " (windowing)",
        "windowing": windowing_card(model),
        "trained_on": trained_on(state),
        "trace_window": int(window),
        "trace_window_is": "the window the export was traced and checked at (--window), not the one to apply it "
                           "with: that is windowing.window",
        "dynamic_axes": {"batch": dynamic, "time": dynamic},
        "onnx_opset": int(opset),
        "checks": checks,
        "source_checkpoint": {
            "path": str(Path(checkpoint)), "sha256": file_sha256(Path(checkpoint)),
            "epoch": state.get("epoch"), "step": state.get("step"), "best_metric": state.get("best_metric"),
            "code_version": state.get("code_version"),
        },
        "torch_version": torch.__version__,
        "sha256": {p.name: file_sha256(p) for p in files.values()},
    }


OPSETS = (9, 20)  # the ONNX opsets torch's TorchScript-based exporter writes and this model's ops need
OUTPUTS = ("model.ts", "model.onnx", "model.json")


def _card(path: Path) -> Optional[Dict[str, Any]]:
    """The export card in the file ``path`` (this format, or one written before cards named their format:
    every card holds ``source_checkpoint`` and the exports' ``sha256``), else None."""
    try:
        card = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    if not (isinstance(card, dict) and card.get("format", CARD_FORMAT) == CARD_FORMAT
            and isinstance(card.get("source_checkpoint"), dict) and isinstance(card.get("sha256"), dict)):
        return None
    return card


def check_out(out: Path) -> None:
    """Before any work: each of :data:`OUTPUTS` already in ``out`` is an earlier export's, else the
    InvalidInputError naming it (:func:`imu_learn.util.outputs.check_replaceable`). An earlier export is
    its card ``model.json``, and the ``model.ts`` and ``model.onnx`` whose sha256 that card records."""
    out = Path(out)
    card = _card(out / "model.json")

    def not_own(path: Path) -> Optional[str]:
        if card is None:
            return "no export card model.json beside it" if path.name != "model.json" else "not an export's card"
        if path.name == "model.json":
            return None
        try:
            digest = file_sha256(path)
        except OSError:
            return "it cannot be read"
        if card["sha256"].get(path.name) != digest:
            return "its sha256 is not the one the export card model.json beside it records"
        return None

    # the card first: without it neither export can be told an earlier one
    check_replaceable([out / name for name in ("model.json", "model.ts", "model.onnx")], not_own, "export",
                      "remove it or give --out a new folder")


def export(checkpoint: Path, out: Path, window: int = 200, opset: int = 17, seed: int = 0) -> Dict[str, Any]:
    """Write model.ts, model.onnx and model.json into ``out``, all three or none (a staging folder swapped
    in at the end: a Ctrl-C or a failed export leaves ``out`` as it was); returns the JSON card. Files of
    ``out`` an earlier export did not write are refused first (:func:`check_out`)."""
    if window < 2:
        raise InvalidInputError(f"--window must be >= 2, got {window}")
    if not OPSETS[0] <= int(opset) <= OPSETS[1]:
        raise ConfigError(f"--opset {opset}: the exporter writes ONNX opsets {OPSETS[0]}-{OPSETS[1]} (default 17)")
    check_out(Path(out))
    state = load_checkpoint(Path(checkpoint))
    model = model_from_checkpoint(state).cpu().float().eval()
    example, other = example_inputs(model, window, seed)
    with staged_dir(Path(out), OUTPUTS) as stage:
        files = {"torchscript": stage / "model.ts", "onnx": stage / "model.onnx"}
        checks = {"torchscript": torchscript_checked(model, example, other, files["torchscript"])}
        try:
            checks["onnx"] = onnx_checked(model, example, other, files["onnx"], opset)
        except (RuntimeError, ValueError) as e:  # torch's exporter or onnxruntime refusing the graph
            raise ConfigError(f"--opset {opset}: the ONNX export failed ({str(e).splitlines()[0][:200]}); "
                              "the default 17 is tested") from e
        card = model_card(model, state, Path(checkpoint), files, window, opset, checks)
        atomic_write_text(stage / "model.json", json.dumps(card, indent=2) + "\n")
    return card


def summary(card: Dict[str, Any], out: Path) -> str:
    """What ``imu-learn export`` prints: the files written and each export's largest difference."""
    lines = [f"wrote {out / 'model.ts'}, {out / 'model.onnx'}, {out / 'model.json'}"]
    for name in ("torchscript", "onnx"):
        r = card["checks"][name]
        lines.append(f"  {name}: max |export - torch| {r.get('max_abs_diff_trace_shape')} at {r.get('trace_shape')}, "
                     f"{r.get('max_abs_diff_other_shape')} at {r.get('other_shape')}")
    return "\n".join(lines)
