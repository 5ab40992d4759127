"""The one rule by which a trained refiner is applied to a sequence of any length.

Every path that turns raw IMU into refined IMU with a checkpoint goes through this module: fit's
model selection (``optim.select = "val_pose"``) and final table, ``evaluate --checkpoint``, the
``proposed`` and ``airimu-style`` baselines, ``imu-learn refine`` (:func:`refine_arrays`,
:func:`refine_with_variance`), :mod:`imu_learn.infer.model_check` and ``imu-learn fuse``. So a
model is selected, scored and applied under the same stitching, and the same checkpoint gives
bit-identical refined samples through each of them (tests/test_windowing.py).

The window (:class:`Windowing`). ``window`` is the checkpoint's training window (its config's
``data.window``, :func:`windowing_of_config`), ``overlap = window // 2``, ``batch = 16`` windows per
forward pass: the model never sees more context than it was trained with, and each sample keeps at
least ``window // 4`` samples of context on either side. :func:`imu_learn.infer.checkpoint.model_from_checkpoint`
attaches this rule to the model it loads (:func:`attach`); a model built in memory without one
(:func:`windowing_of`) gets the rule of the default training window (``data.window = 200``).
Callers may override window or overlap (``imu-learn refine --window/--overlap``), but every
built-in path uses the checkpoint's rule.

Bidirectional model. A sequence of N samples is cut into windows of W samples starting every
S = W - O samples (O the overlap); the last window is moved back to end at N so that every window
is full length (N <= W: one window of N). Consecutive windows k, k+1 overlap on [s_{k+1}, e_k);
sample i of the overlap is taken from window k if i < b = (s_{k+1} + e_k) // 2 and from window k+1
otherwise: each sample comes from the window in which it lies farthest from a window edge (a
centre crop), and the first and last windows keep their outer edges, which are the sequence's own.
``batch`` windows run in one forward pass.

Causal model. Chunks of W samples (the remainder joined to the last chunk, :func:`causal_chunks`)
run one after the other with the LSTM state carried over (no overlap, no stitching; ``overlap`` is
unused): the whole-sequence causal forward, computed in chunks so that memory does not grow with
the recording. On the CPU it equals one forward pass over the whole sequence bit for bit
(tests/test_windowing.py). It is not guaranteed to: torch computes each chunk's input projections,
FC layers and head as one matrix product over the chunk's samples, and the BLAS kernel (and so the
float32 summation order) it picks depends on the number of rows; chunks of 1-3 samples were
measured to differ from the whole pass by up to ~1e-6 (one float32 rounding of the correction),
which is why no chunk is left shorter than the window.

Precision: the network runs in float32; its correction (model output minus its float32 input) is
added to the float64 raw samples, so a model whose correction is zero returns the input bit for
bit. The covariance head's variances (:func:`refine_with_variance`) are stitched like the samples.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any, List, Mapping, Optional, Tuple

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from imu_learn.data.types import Segment
from imu_learn.errors import InvalidInputError

DEFAULT_WINDOW = 200  # data.window's default: the training window of a model that names none
DEFAULT_BATCH = 16


@dataclass(frozen=True)
class Windowing:
    """Windows of ``window`` samples, consecutive ones overlapping by ``overlap`` (bidirectional
    models; unused by causal ones), ``batch`` windows per forward pass."""

    window: int = DEFAULT_WINDOW
    overlap: int = DEFAULT_WINDOW // 2
    batch: int = DEFAULT_BATCH

    def __post_init__(self) -> None:
        if self.window < 1:
            raise InvalidInputError(f"window must be >= 1, got {self.window}")
        if not 0 <= self.overlap < self.window:
            raise InvalidInputError(f"overlap must be in [0, window), got overlap {self.overlap} for window {self.window}")
        if self.batch < 1:
            raise InvalidInputError(f"batch must be >= 1, got {self.batch}")

    @classmethod
    def for_training_window(cls, window: int) -> Windowing:
        """The rule for a model trained on windows of ``window`` samples: that window, half overlap."""
        return cls(int(window), int(window) // 2)

    def replace(self, window: Optional[int] = None, overlap: Optional[int] = None,
                batch: Optional[int] = None) -> Windowing:
        """This rule with the given fields overridden (None: kept; a new window without a new overlap
        gets half of it)."""
        w = self.window if window is None else int(window)
        o = (self.overlap if window is None else w // 2) if overlap is None else int(overlap)
        return Windowing(w, o, self.batch if batch is None else int(batch))


def windowing_of_config(config: Optional[Mapping[str, Any]]) -> Windowing:
    """The rule of a checkpoint from its saved run config (``data.window``: the training window)."""
    data = (config or {}).get("data") or {}
    return Windowing.for_training_window(int(data.get("window") or DEFAULT_WINDOW))


def attach(model: nn.Module, windowing: Windowing) -> nn.Module:
    """Record on ``model`` the rule it is to be applied with (a plain attribute: not in its weights)."""
    model.windowing = windowing
    return model


def windowing_of(model: nn.Module) -> Windowing:
    """The rule attached to ``model`` (:func:`attach`), else the default training window's."""
    w = getattr(model, "windowing", None)
    return w if isinstance(w, Windowing) else Windowing()


def window_plan(n: int, window: int, overlap: int) -> List[Tuple[int, int, int, int]]:
    """The windows of the stitching rule: (start, end, keep_from, keep_to) per window, where the
    window covers samples [start, end) and contributes samples [keep_from, keep_to) to the output.
    The kept ranges tile [0, n) in order."""
    Windowing(window, overlap)  # validates
    if n <= window:
        return [(0, n, 0, n)] if n > 0 else []
    stride = window - overlap
    starts = list(range(0, n - window + 1, stride))
    if starts[-1] + window < n:
        starts.append(n - window)
    plan = []
    for k, s in enumerate(starts):
        e = s + window
        keep_from = 0 if k == 0 else (s + starts[k - 1] + window) // 2
        keep_to = n if k == len(starts) - 1 else (starts[k + 1] + e) // 2
        plan.append((s, e, keep_from, keep_to))
    return plan


def causal_chunks(n: int, window: int) -> List[Tuple[int, int]]:
    """The causal rule's chunks [start, end): ``window`` samples each, the remainder joined to the
    last one (so no chunk but a sequence shorter than the window is short: the BLAS kernels that
    run a chunk's per-sample layers change their summation order for a handful of rows)."""
    if window < 1:
        raise InvalidInputError(f"window must be >= 1, got {window}")
    starts = list(range(0, n, window))
    if len(starts) > 1 and n - starts[-1] < window:
        starts.pop()
    return [(s, starts[k + 1] if k + 1 < len(starts) else n) for k, s in enumerate(starts)]


def _device_of(model: nn.Module) -> torch.device:
    return next(iter(model.parameters())).device


def _progress(total: int, enabled: bool, desc: str):
    return tqdm(total=total, disable=not enabled, desc=desc, unit="sample", unit_scale=True, file=sys.stderr)


@torch.no_grad()
def corrections(model: nn.Module, imu32: np.ndarray, windowing: Optional[Windowing] = None, progress: bool = False,
                variance: bool = False) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """Corrections (N, 6) = model output - input and, with ``variance``, the covariance head's
    variances (N, 6), both float32, by the rule (``windowing``; None: :func:`windowing_of`)."""
    wr = windowing if windowing is not None else windowing_of(model)
    n = len(imu32)
    out = np.zeros((n, 6), dtype=np.float32)
    var_out = np.zeros((n, 6), dtype=np.float32) if variance else None
    if variance and getattr(model, "cov_head", None) is None:
        raise InvalidInputError("this model has no covariance head (trained with model.covariance = false)")
    if n == 0:
        return out, var_out
    x_all = torch.from_numpy(np.ascontiguousarray(imu32, dtype=np.float32)).to(_device_of(model))
    was_training = model.training
    model.eval()
    try:
        if getattr(model.cfg, "causal", False):
            state = None
            with _progress(n, progress, "refine (causal)") as bar:
                for s, e in causal_chunks(n, wr.window):
                    x = x_all[None, s:e]
                    if var_out is not None:
                        y, v, state = model.forward_full(x, state)
                        var_out[s:e] = v[0].float().cpu().numpy()
                    else:  # any model with forward_with_state (the baselines' nets too)
                        y, state = model.forward_with_state(x, state)
                    out[s:e] = (y - x)[0].float().cpu().numpy()
                    bar.update(e - s)
            return out, var_out
        plan = window_plan(n, wr.window, wr.overlap)
        with _progress(n, progress, "refine") as bar:
            for b0 in range(0, len(plan), wr.batch):
                chunk = plan[b0 : b0 + wr.batch]
                x = torch.stack([x_all[s:e] for s, e, _, _ in chunk])
                if var_out is not None:
                    y, v = model(x, with_variance=True)
                    vv = v.float().cpu().numpy()
                else:  # any model mapping (B, W, 6) to (B, W, 6) (the baselines' nets too)
                    y, vv = model(x), None
                corr = (y - x).float().cpu().numpy()
                for j, (s, _e, kf, kt) in enumerate(chunk):
                    out[kf:kt] = corr[j, kf - s : kt - s]
                    if var_out is not None and vv is not None:
                        var_out[kf:kt] = vv[j, kf - s : kt - s]
                bar.update(chunk[-1][3] - chunk[0][2])
    finally:
        model.train(was_training)
    return out, var_out


def apply(model: nn.Module, gyro: np.ndarray, acc: np.ndarray, windowing: Optional[Windowing] = None,
          progress: bool = False, variance: bool = False) -> Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
    """Raw gyro [rad/s] and acc [m/s^2] (N, 3) -> refined (gyro, acc) float64 (N, 3) and, with
    ``variance``, the per-sample variances (N, 6) float64 (else None), by the rule."""
    gyro = np.asarray(gyro, dtype=np.float64)
    acc = np.asarray(acc, dtype=np.float64)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or acc.shape != gyro.shape:
        raise InvalidInputError(f"gyro and acc must both be (N, 3); got {gyro.shape} and {acc.shape}")
    raw = np.concatenate([gyro, acc], axis=1)
    if not np.isfinite(raw).all():
        raise InvalidInputError(f"IMU row {int(np.flatnonzero(~np.isfinite(raw).all(1))[0])} is not finite")
    corr, var = corrections(model, raw.astype(np.float32), windowing, progress, variance)
    refined = raw + corr.astype(np.float64)
    return (np.ascontiguousarray(refined[:, :3]), np.ascontiguousarray(refined[:, 3:]),
            None if var is None else var.astype(np.float64))


def refine_sequence(model: nn.Module, seq: Segment, windowing: Optional[Windowing] = None) -> Segment:
    """``seq`` with its IMU refined by the rule (timestamps and ground truth kept)."""
    g, a, _ = apply(model, seq.gyro, seq.acc, windowing)
    return Segment(seq.name, seq.t_ns, g, a, seq.p, seq.v, seq.q_wxyz)
