"""The interface every evaluated method implements, so evaluation treats them all alike.

Protocol (README "Evaluation"): a method is fitted on the training split only (validation for its
own model selection); at test time each window starts from the ground-truth state (p, v, R) at its
first sample and the method sees only IMU samples from then on.

Two kinds of method:
- refiners return corrected IMU samples (``refine``); their poses come from integrating those
  samples from the ground-truth start state (``predict`` below does that);
- regressors (end-to-end learning) override ``predict`` and return poses directly.
"""
from __future__ import annotations

import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Dict, Iterable, List, Optional, Tuple

import numpy as np
from tqdm import tqdm

from imu_learn.core.integration import integrate_windows
from imu_learn.core.quat import quat_mul, quat_rotate  # noqa: F401  (re-exported: baselines use them from here)
from imu_learn.data.types import Segment


@dataclass(frozen=True)
class FitSettings:
    """Budget and data shape shared by the learned baselines (each may ignore what it does not use)."""

    window: int = 200
    batch_size: int = 32
    steps: int = 2000
    lr: float = 1e-3
    seed: int = 0
    device: str = "cpu"
    threads: int = 2
    gravity: float = 9.81
    # The horizons [IMU samples] the evaluation scores in its table (eval.horizons): a regressor
    # may fit one model per horizon (the end-to-end baseline does); empty: ``window`` only.
    horizons: Tuple[int, ...] = ()
    # A bar on stderr while a learned baseline trains (evaluate's progress); not part of what a fit is
    # (:meth:`record` leaves it out, so a saved fit is reused with or without it).
    progress: bool = False

    def record(self) -> Dict[str, Any]:
        """The settings that make a fit, as plain values (the fit records' signature)."""
        d = asdict(self)
        d.pop("progress")
        return d


def fit_steps(steps: int, settings: FitSettings, what: str) -> Iterable[int]:
    """``range(steps)`` of a learned baseline's training loop, with a progress bar on stderr where
    ``settings.progress`` (evaluate's --quiet turns it off)."""
    return tqdm(range(int(steps)), desc=f"{what}: fit", unit="step", disable=not settings.progress, leave=False,
                dynamic_ncols=True, file=sys.stderr, mininterval=1.0)


@dataclass(frozen=True)
class PosePrediction:
    """End states of windows started at ground truth: ``q_wxyz`` (W, 4) world orientation,
    ``p`` (W, 3) world position; ``p`` is None for rotation-only methods. ``v`` (W, 3) world
    velocity, optional: None where a method does not predict it (evaluation then reports no
    velocity error for it)."""

    q_wxyz: np.ndarray
    p: Optional[np.ndarray]
    v: Optional[np.ndarray] = None


def poses_from_imu(
    seq: Segment, gyro: np.ndarray, acc: np.ndarray, starts: np.ndarray, n: int, gravity: float = 9.81
) -> PosePrediction:
    """Integrate (gyro, acc) for n samples from the ground-truth state at each start (end
    orientation, position and velocity)."""
    s = Segment(seq.name, seq.t_ns, np.ascontiguousarray(gyro), np.ascontiguousarray(acc), seq.p, seq.v, seq.q_wxyz)
    inc = integrate_windows(s, np.asarray(starts, dtype=np.uint64), np.array([n], dtype=np.uint64))
    k = np.asarray(starts, dtype=np.int64)
    qk = seq.q_wxyz[k]
    dt = inc.dt[:, 0, None]
    g = np.array([0.0, 0.0, -gravity])
    q_end = quat_mul(qk, inc.dq_wxyz[:, 0])
    p_end = seq.p[k] + seq.v[k] * dt + 0.5 * g * dt**2 + quat_rotate(qk, inc.dp[:, 0])
    v_end = seq.v[k] + g * dt + quat_rotate(qk, inc.dv[:, 0])
    return PosePrediction(q_wxyz=q_end, p=p_end, v=v_end)


class Method:
    """Base class: a refiner by default (identity = raw IMU)."""

    name = "method"
    rotation_only = False

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        """Fit on ``train`` (``val`` for model selection); returns a log, e.g. {"train_loss": [...]}."""
        return {}

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        """Corrected (gyro, acc), each (N, 3) float64."""
        return seq.gyro, seq.acc

    def predict(self, seq: Segment, starts: np.ndarray, n: int, gravity: float = 9.81) -> PosePrediction:
        gyro, acc = self.refine(seq)
        pred = poses_from_imu(seq, gyro, acc, starts, n, gravity)
        if self.rotation_only:
            return PosePrediction(pred.q_wxyz, None, None)
        return PosePrediction(pred.q_wxyz, pred.p, pred.v)

    def save(self, path: Path) -> None:
        """Persist what ``fit`` learned (weights_only-loadable torch file or npz)."""

    def load(self, path: Path) -> Method:
        return self


class Raw(Method):
    """The IMU as recorded."""

    name = "raw"
