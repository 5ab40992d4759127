"""The one first-state type: where a run starts and from what state (:class:`Start`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict

import numpy as np

from ..settings import PriorSigmas


@dataclass
class Start:
    """The first fused sample (``start``, counted from the recording's first) and its state in the
    navigation frame W: attitude ``R`` (3, 3, body to W), position ``p`` and velocity ``v`` (3,), bias
    ``bias`` (6,) gyro then acc (the bias prior's mean), under ``prior``; the first sample scored
    (``score_from``: an alignment window before it used fixes still to come), whether scores are
    SE(3)-aligned (``align``: a gauge left free), the aiding world's rotation into W (``R_WA``:
    identity for aiding already in W), and where each came from (``info``, JSON-ready)."""

    start: int
    score_from: int
    R: np.ndarray
    p: np.ndarray
    v: np.ndarray
    bias: np.ndarray
    prior: PriorSigmas = field(default_factory=PriorSigmas)
    align: bool = False
    info: Dict[str, object] = field(default_factory=dict)
    R_WA: np.ndarray = field(default_factory=lambda: np.eye(3))

    @property
    def pose(self) -> tuple:
        """(R, p, v): the graph's first state."""
        return self.R, self.p, self.v


def groundtruth_start(R0: np.ndarray, p0: np.ndarray, v0: np.ndarray, bias0) -> Start:
    """The controlled setting: ground truth's pose and velocity of the first sample under the graph's
    tight default prior (``bias0`` None: zero)."""
    return Start(0, 0, R0, p0, v0, np.zeros(6) if bias0 is None else bias0, PriorSigmas(), False,
                 {"source": "ground truth: pose and velocity of the first sample"})
