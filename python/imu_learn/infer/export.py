"""Export a trained refiner for use outside Python/imu_learn: TorchScript, ONNX and a JSON card.

    python -m imu_learn.export --checkpoint CKPT --out DIR [--window 200] [--opset 17]

writes into DIR:

- ``model.ts``: TorchScript (``torch.jit.trace`` of the whole-window forward); load with
  ``torch.jit.load`` (Python) or ``torch::jit::load`` (C++).
- ``model.onnx``: ONNX, input ``imu`` and output ``refined``, both (batch, time, 6) float32, with
  dynamic batch and time axes.
- ``model.json``: inputs, outputs, channel order and units, the normalisation that is built into
  the model, the model args, and the largest difference of each export from the torch model
  measured right after export on the trace length and on a different length/batch.

Both exports take RAW IMU (gyro rad/s then acc m/s^2, the order and units of the training data):
the per-channel mean/std normalisation is stored inside the model, and the output is the refined
IMU (raw + correction) in the same units. For the causal model the exports are the stateless
whole-window forward (state starts at zero in each call); carried-state streaming is available in
Python through ``ImuRefiner.step`` / ``forward_with_state``.
"""
from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np
import torch

from imu_learn.nn.model import ImuRefiner
from imu_learn.util.atomic import atomic_write_path, atomic_write_text
from imu_learn.util.digest import file_sha256

CHANNELS = ["gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z"]
UNITS = ["rad/s"] * 3 + ["m/s^2"] * 3
CARD_FORMAT = "imu_learn.infer.export.v1"


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


def export(checkpoint: Path, out: Path, window: int = 200, opset: int = 17, seed: int = 0) -> Dict[str, Any]:
    """Write model.ts, model.onnx and model.json into ``out``; returns the JSON card."""
    from imu_learn.train.checkpoint import load_checkpoint, model_from_checkpoint

    if window < 2:
        raise ValueError(f"--window must be >= 2, got {window}")
    state = load_checkpoint(Path(checkpoint))
    model = model_from_checkpoint(state).cpu().float().eval()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    # A plausible raw-IMU window: the model's own mean/std (the export does not depend on it).
    gen = torch.Generator().manual_seed(seed)
    mean, std = model.mean.float(), model.std.float()

    def sample(b: int, w: int) -> torch.Tensor:
        return mean + std * torch.randn(b, w, 6, generator=gen)

    example = sample(1, window)
    other = sample(3, window + window // 2 + 1)  # another batch size and length

    ts_path, onnx_path = out / "model.ts", out / "model.onnx"
    export_torchscript(model, example, ts_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch >= 2.9 marks torch.jit as deprecated
        ts = torch.jit.load(str(ts_path))
    checks: Dict[str, Any] = {}

    def run_ts(x: torch.Tensor) -> List[np.ndarray]:
        with torch.no_grad():
            y = ts(x)
        return [t.numpy() for t in (y if isinstance(y, (tuple, list)) else (y,))]

    checks["torchscript"] = {
        "trace_shape": list(example.shape), "max_abs_diff_trace_shape": _check(run_ts, model, example),
        "other_shape": list(other.shape), "max_abs_diff_other_shape": _check(run_ts, model, other),
    }

    export_onnx(model, example, onnx_path, opset)
    try:
        import onnxruntime as ort
    except ImportError:
        ort = None
    if ort is not None:
        sess = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])

        def run_onnx(x: torch.Tensor) -> List[np.ndarray]:
            return sess.run(output_names(model), {"imu": x.numpy()})

        checks["onnx"] = {
            "runtime": f"onnxruntime {ort.__version__}",
            "trace_shape": list(example.shape), "max_abs_diff_trace_shape": _check(run_onnx, model, example),
            "other_shape": list(other.shape), "max_abs_diff_other_shape": _check(run_onnx, model, other),
        }
    else:
        checks["onnx"] = {"runtime": None, "note": "onnxruntime not installed; export not verified"}

    def dyn(c: Dict[str, Any]) -> bool:
        d = c.get("max_abs_diff_other_shape")
        return d is not None and d < 1e-4

    card: Dict[str, Any] = {
        "format": CARD_FORMAT,
        "files": {"torchscript": ts_path.name, "onnx": onnx_path.name},
        "inputs": [{
            "name": "imu", "dtype": "float32", "shape": ["batch", "time", 6],
            "channels": CHANNELS, "units": UNITS,
            "description": "raw IMU samples in time order (not normalised: normalisation is inside the model)",
        }],
        "outputs": [{
            "name": "refined", "dtype": "float32", "shape": ["batch", "time", 6],
            "channels": CHANNELS, "units": UNITS,
            "description": "refined IMU = raw + correction, same order and units",
        }] + ([{
            "name": "variance", "dtype": "float32", "shape": ["batch", "time", 6],
            "channels": CHANNELS, "units": ["(rad/s)^2"] * 3 + ["(m/s^2)^2"] * 3,
            "description": "per-sample noise variance of each refined sample, discrete-time (the variance of one "
                           "sample); a filter that wants a noise density takes sqrt(variance * dt) "
                           "[rad/s/sqrt(Hz), m/s^2/sqrt(Hz)], GTSAM's PreintegrationParams variance * dt",
        }] if model.cov_head is not None else []),
        "normalisation": {
            "inside_model": True,
            "mean": [float(v) for v in mean], "std": [float(v) for v in std],
            "rule": "x_norm = (imu - mean) / std; refined = imu + output_scale * std * head(network(x_norm))",
            "output_scale": float(model.cfg.output_scale),
        },
        "model_args": model.model_args(),
        "causal": bool(model.cfg.causal),
        "state": "each call starts from zero LSTM state; the bidirectional model needs context on both sides"
        " (see imu_learn.infer.refine for windowing)",
        "trace_window": int(window),
        "dynamic_axes": {"batch": dyn(checks["torchscript"]) and dyn(checks["onnx"]),
                         "time": dyn(checks["torchscript"]) and dyn(checks["onnx"])},
        "onnx_opset": int(opset),
        "checks": checks,
        "source_checkpoint": {
            "path": str(Path(checkpoint)), "sha256": file_sha256(Path(checkpoint)),
            "epoch": state.get("epoch"), "step": state.get("step"), "best_metric": state.get("best_metric"),
            "code_version": state.get("code_version"),
        },
        "torch_version": torch.__version__,
        "sha256": {"model.ts": file_sha256(ts_path), "model.onnx": file_sha256(onnx_path)},
    }
    atomic_write_text(out / "model.json", json.dumps(card, indent=2) + "\n")
    return card


def main(argv: Optional[List[str]] = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m imu_learn.export", description="Export a refiner to TorchScript and ONNX."
    )
    p.add_argument("--checkpoint", required=True, type=Path)
    p.add_argument("--out", required=True, type=Path, help="folder for model.ts, model.onnx, model.json")
    p.add_argument("--window", type=int, default=200, help="time length of the example used for tracing")
    p.add_argument("--opset", type=int, default=17, help="ONNX opset (default 17)")
    args = p.parse_args(argv)
    try:
        card = export(args.checkpoint, args.out, args.window, args.opset)
    except Exception as e:  # one line, status 2
        msg = " ".join(str(e).split()) or type(e).__name__
        print(f"error: {type(e).__name__}: {msg}", file=sys.stderr)
        return 2
    c = card["checks"]
    print(f"wrote {args.out / 'model.ts'}, {args.out / 'model.onnx'}, {args.out / 'model.json'}")
    for name in ("torchscript", "onnx"):
        r = c[name]
        print(
            f"  {name}: max |export - torch| {r.get('max_abs_diff_trace_shape')} at {r.get('trace_shape')}, "
            f"{r.get('max_abs_diff_other_shape')} at {r.get('other_shape')}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
