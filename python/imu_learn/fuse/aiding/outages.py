"""Outages: time windows without aiding, one type for all of them (:class:`OutageWindow`): a scenario's
simulated outages, the navigator's ``--gaps``, the GNSS outage experiment's schedule, and the
scoring inside each. A window is half-open, [start, start + duration), in seconds from a reference
stamp (a recording's first sample, unless said otherwise)."""
from __future__ import annotations

from typing import List, NamedTuple, Tuple
from typing import Sequence as Seq

import numpy as np

from .types import Aiding


class OutageWindow(NamedTuple):
    """[``start_s``, ``start_s + duration_s``) seconds from a reference stamp."""

    start_s: float
    duration_s: float

    def bounds_ns(self, t0_ns: int) -> Tuple[int, int]:
        """The window as [start, end) stamps [ns] for the reference stamp ``t0_ns``."""
        return (int(t0_ns) + int(round(self.start_s * 1e9)),
                int(t0_ns) + int(round((self.start_s + self.duration_s) * 1e9)))


def windows(pairs: Seq[Seq[float]]) -> List[OutageWindow]:
    """``[[start_s, duration_s], ...]`` (a config's list) as windows."""
    return [OutageWindow(float(p[0]), float(p[1])) for p in pairs]


def in_windows(rel_s: np.ndarray, outages: Seq[Tuple[float, float]]) -> np.ndarray:
    """True for the times ``rel_s`` [s from the reference] inside any of the windows."""
    rel_s = np.asarray(rel_s)
    mask = np.zeros(len(rel_s), dtype=bool)
    for start, dur in outages:
        mask |= (rel_s >= start) & (rel_s < start + dur)
    return mask


def outage_mask(t_ns: np.ndarray, outages: Seq[Tuple[float, float]]) -> np.ndarray:
    """True for samples inside an outage (seconds from the first sample). A window running past
    either end of the recording covers only the samples it has (see :func:`clip_outages`)."""
    return in_windows((np.asarray(t_ns) - t_ns[0]) * 1e-9, outages)


def clip_outages(t_ns: np.ndarray, outages: Seq[Tuple[float, float]]) -> List[OutageWindow]:
    """The outage windows as they act on this recording: each clipped to [0, the recording's
    duration] (seconds from the first sample), so a window running past the end ends at the last
    sample; a window that misses the recording entirely is left out."""
    span = (int(t_ns[-1]) - int(t_ns[0])) * 1e-9
    out = []
    for start, dur in outages:
        start, end = float(start), float(start) + float(dur)
        if start <= span and end > 0:  # [start, end) meets [0, span]
            out.append(OutageWindow(max(start, 0.0), min(end, span) - max(start, 0.0)))
    return out


def apply_outages(aiding: Aiding, t_ns: np.ndarray, outages: Seq[Tuple[float, float]]) -> Aiding:
    """``aiding`` without the measurements inside any outage (a relative pose is dropped when
    either end is inside); how many it removed is added to ``dropped_outage``."""
    if not outages:
        return aiding
    mask = outage_mask(t_ns, outages)
    keep = ~(mask[aiding.i] | mask[aiding.j]) if hasattr(aiding, "R_ij") else ~mask[aiding.idx]
    return aiding.select(keep, dropped_outage=int((~keep).sum()))
