"""The recordings a per-recording gyro-bias estimator is trained and measured on (numpy, no torch):
a config's training recordings whole (its ``data.split.train`` names, time blocks dropped) and its
test recordings, each segment with its own constant gyro bias fitted on ground truth over the whole
segment (:func:`imu_learn.score.metrics.fit_startup_bias`), and the training mean of those biases
(what a device profile's floor or a model that learns one device bias knows).
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import Dict, List, Sequence

import numpy as np

from imu_learn.data.splits import make_split
from imu_learn.data.types import Segment
from imu_learn.score.metrics import fit_startup_bias
from imu_learn.train.config import load_config

# dataset -> (config, training recordings (None: the config's train names), held-out recordings)
DEVICES: Dict[str, str] = {
    "fetch": "configs/fetch.toml",
    "tumvi": "configs/tumvi.toml",
    "euroc": "configs/euroc_paper.toml",
    "broad": "configs/broad.toml",
}


@dataclass
class Recording:
    """One gap-free segment with its whole-segment ground-truth gyro bias [rad/s]."""

    seg: Segment
    gyro_bias: np.ndarray
    gravity: float


def _names(entries: Sequence[str]) -> List[str]:
    seen: List[str] = []
    for e in entries:
        n = re.sub(r"\[.*\]$", "", e)
        if n not in seen:
            seen.append(n)
    return seen


def load_device(device: str, data_root: str) -> Dict[str, List[Recording]]:
    """{"train": [...], "test": [...]} for ``device`` (a key of :data:`DEVICES`)."""
    cfg = load_config(DEVICES[device], [])
    train, test = _names(cfg.data.split.train), _names(cfg.data.split.test)
    # the last training recording's final 1 % is the (unused) val split make_split asks for
    over = ["--data.data_root", data_root, "--data.split.train", json.dumps(train[:-1] + [f"{train[-1]}[0:0.99]"]),
            "--data.split.val", json.dumps([f"{train[-1]}[0.99:1]"]), "--data.split.test", json.dumps(test)]
    cfg = load_config(DEVICES[device], over)
    split = make_split(cfg.data, min_len=20)
    g = float(cfg.data.gravity)

    def rec(s: Segment) -> Recording:
        bg, _ = fit_startup_bias(s, s.duration_s + 1.0, gravity=g)
        return Recording(s, np.asarray(bg, dtype=np.float64), g)

    return {"train": [rec(s) for s in split.train], "test": [rec(s) for s in split.test]}


def training_mean(recs: Sequence[Recording]) -> np.ndarray:
    """The mean of the training segments' ground-truth gyro biases, weighted by their samples."""
    w = np.array([len(r.seg.t_ns) for r in recs], dtype=np.float64)
    return np.average(np.stack([r.gyro_bias for r in recs]), axis=0, weights=w)
