"""The simple floor of the TLIO-style displacement factors: "the device stays where it is".

``zero-displacement`` predicts the displacement of every 1 s window, p(t + 1 s) - p(t), as zero,
with the spread the training recordings' displacements have about zero as its covariance::

    d̂ = 0,   Σ = diag(σ_h², σ_h², σ_v²)
    σ_h² = mean over training windows of (d_x² + d_y²) / 2     σ_v² = mean of d_z²

(world frame, gravity along z; horizontal axes pooled, so Σ is the same in every heading and in
TLIO's local gravity-aligned frame). It reads no IMU sample: in fusion (:mod:`imu_learn.fuse.factors.displacement`,
the input ``zero-displacement``: the raw IMU plus these factors every 1 s) it is a motion prior
fitted to how far the training recordings' device moves in a second, the part of a learned
displacement model that needs no learning. A learned displacement model counts where it beats this.

In ``imu-learn evaluate`` its pose is the raw gyro's rotation from the ground-truth start and the
start position (it never moves); no velocity. Saved as JSON.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np

from imu_learn.baselines.base import FitSettings, Method, PosePrediction, poses_from_imu
from imu_learn.data.types import Segment, sample_rate_hz

FORMAT = "imu_learn.baselines.zero_displacement.v1"
WINDOW_S = 1.0  # as tlio-style's window


def displacement_variances(seqs: List[Segment], window: int) -> Tuple[float, float, int]:
    """(σ_h², σ_v², number of windows): the mean square displacement over every ``window``-sample
    window of the sequences (one per start sample), horizontal axes pooled."""
    sq = np.zeros(3)
    count = 0
    for s in seqs:
        if len(s) <= window:
            continue
        d = np.asarray(s.p[window:], dtype=np.float64) - np.asarray(s.p[:-window], dtype=np.float64)
        d = d[np.isfinite(d).all(axis=1)]
        sq += np.sum(d * d, axis=0)
        count += len(d)
    if count == 0:
        raise ValueError(f"zero-displacement: no training sequence longer than the window ({window} samples)")
    return float((sq[0] + sq[1]) / (2 * count)), float(sq[2] / count), count


class ZeroDisplacement(Method):
    """Zero displacement per 1 s window with the training recordings' spread (module docstring)."""

    name = "zero-displacement"
    rotation_only = False
    save_suffix = ".json"

    def __init__(self) -> None:
        self.window = 200  # W [samples] (set by fit / load)
        self.rate_hz = 200.0
        self.var_h = 1.0  # σ_h² [m²]
        self.var_v = 1.0  # σ_v² [m²]
        self.windows = 0

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        self.rate_hz = sample_rate_hz(*(s.t_ns for s in train))
        self.window = max(2, int(round(WINDOW_S * self.rate_hz)))
        self.var_h, self.var_v, self.windows = displacement_variances(train, self.window)
        # train_loss: the mean square displacement [m²] that predicting zero leaves on the training windows
        return {"train_loss": [2 * self.var_h + self.var_v], "window": [self.window], "sigma_h_m": [self.var_h ** 0.5],
                "sigma_v_m": [self.var_v ** 0.5], "windows": [self.windows]}

    def regress_window(self, imu_world: np.ndarray, R_last: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """The fusion hook's regressor (as :meth:`TlioStyle.regress_window`): (0, Σ), world frame."""
        return np.zeros(3), np.diag([self.var_h, self.var_h, self.var_v])

    def predict(self, seq: Segment, starts: np.ndarray, n: int, gravity: float = 9.81) -> PosePrediction:
        k = np.asarray(starts, dtype=np.int64)
        q = poses_from_imu(seq, seq.gyro, seq.acc, k.astype(np.uint64), int(n), gravity).q_wxyz
        return PosePrediction(q_wxyz=q, p=np.asarray(seq.p, dtype=np.float64)[k].copy(), v=None)

    def save(self, path: Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"format": FORMAT, "window": self.window, "rate_hz": self.rate_hz,
                                    "var_h_m2": self.var_h, "var_v_m2": self.var_v, "windows": self.windows}, indent=2))

    def load(self, path: Path) -> ZeroDisplacement:
        d = json.loads(Path(path).read_text())
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise ValueError(f"{path}: not a zero-displacement baseline file ({FORMAT})")
        self.window, self.rate_hz = int(d["window"]), float(d["rate_hz"])
        self.var_h, self.var_v, self.windows = float(d["var_h_m2"]), float(d["var_v_m2"]), int(d["windows"])
        return self
