"""Factors beyond the IMU and the aiding, each joining the graph through the one hook
:class:`ExtraFactors`: :mod:`.nhc` (the non-holonomic constraint of a wheeled vehicle),
:mod:`.displacement` (learned displacements, TLIO-style) and :mod:`.velocity` (GNSS velocities).
:mod:`.held` solves a graph with such Python factors by Levenberg-Marquardt at a native graph's cost."""
from __future__ import annotations

from typing import Any, List, Optional, Protocol


class ExtraFactors(Protocol):
    """The graph's ``extra_factors`` hook: called as ``hook(fusion, k, s)`` at keyframe ``k`` (IMU sample
    ``s``) of :class:`~imu_learn.fuse.graph.IncrementalFusion`, before its update; returns the factors
    to add there (they count as new information: iSAM2 updates at that keyframe)."""

    def __call__(self, fusion: Any, k: int, s: int) -> List[Any]: ...


def chain(*hooks: Optional[ExtraFactors]) -> Optional[ExtraFactors]:
    """One hook of several (None entries left out): each one's factors at every keyframe, in order;
    None when there is none."""
    live = [h for h in hooks if h is not None]
    if len(live) <= 1:
        return live[0] if live else None
    return lambda fusion, k, s: [f for h in live for f in h(fusion, k, s)]
