"""The floor against a reference: ``imu-learn evaluate``'s ``traditional+timing`` fit (the same
class, settings and seeding, so the same parameters), the spread of its parameters between the
recordings, and gravity.

Uncertainty: the floor is refitted on each group of segments alone (a group is a recording; a
single recording is cut into four time blocks), and the standard deviation of a parameter is the
spread of the per-group values over sqrt(groups): the standard error of a mean of independent
fits. It includes what really differs between recordings (EuRoC's gyro bias changes from flight to
flight), which is the uncertainty a user of the profile on a new recording faces. A group's refit
(:func:`refit_once`, :meth:`TraditionalTiming.refit`) searches its own time offset as the main fit
does, then solves the affine parameters again from the main fit's (warm start) with the main fit's
cutoffs: the cutoff grid is not searched again per group (the parameters barely depend on the
cutoff; a group's own choice on its small validation share was noise). The refits share the main
fit's window budget (``max_windows`` / groups each, at least 200); fewer windows add estimation
noise to each group's value, which makes the spread, if anything, larger. On EuRoC's five training
flights the standard deviations are 0.87-1.32× those of full refits (cutoffs chosen per flight),
the time offset's the same.

Gravity: with the floor applied, over windows of ``window`` samples, the vertical velocity change
the reference saw against the one the calibrated accelerometer explains (attitude from the
reference, the zero-order hold): g = -Σ(Δv_ref − Σ R_i a_i dt)_z / Σ T per window; its spread
over groups as above. The floor itself fixes g (``settings.gravity``) and fits the accelerometer
scale against it: the two are nearly degenerate, so this value is a consistency check of the
floor, not an independent measurement (the profile says so).

The fit is numpy (:mod:`imu_learn.baselines.traditional`): nothing here loads torch.
"""
from __future__ import annotations

import math
import random
import sys
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.baselines.affine import ESTIMATES, Floor, TraditionalParams
from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.traditional import TraditionalTiming
from imu_learn.calib.profile import FloorFit, apply_floor  # noqa: F401  (FloorFit: what fit_floor returns)
from imu_learn.core.quat import quat_rotate
from imu_learn.data.splits import cut
from imu_learn.data.types import Segment, median_period_ns
from imu_learn.util.helper import Split
from imu_learn.util.threads import thread_limits

Progress = Callable[[str], None]


def seed_all(seed: int) -> None:
    """What ``imu-learn evaluate`` seeds before each method's fit (torch's generator only where torch
    is already loaded: the floor's fit draws nothing from it)."""
    random.seed(seed)
    np.random.seed(seed % (2**32))
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.manual_seed(seed)


def fit_once(train: List[Segment], val: List[Segment], settings: FitSettings,
             max_windows: Optional[int] = None, terms: Optional[Dict[str, Any]] = None) -> Tuple[TraditionalTiming, Dict[str, list]]:
    """``imu-learn evaluate``'s fit of the floor (``max_windows``: the method's default unless given;
    ``terms``: keywords of :class:`TraditionalTiming` that restrict it to what the reference observes,
    e.g. no low-pass, the acc bias only; the method sizes its own threads: its ``threads``)."""
    seed_all(settings.seed)
    kw = dict(terms or {}, **({} if max_windows is None else {"max_windows": max_windows}))
    method = TraditionalTiming(**kw)
    log = method.fit(list(train), list(val), settings) or {}
    return method, log


def refit_once(method: TraditionalTiming, train: List[Segment], val: List[Segment], settings: FitSettings,
               max_windows: int) -> TraditionalTiming:
    """``method``'s floor refitted on a part of its data: the time offset searched again, the affine
    parameters solved again from ``method``'s (its cutoffs and what it holds at the prior kept;
    :meth:`TraditionalTiming.refit`)."""
    seed_all(settings.seed)
    m = TraditionalTiming(max_windows=max_windows, held=method.held)
    m.refit(list(train), list(val), method.params, settings)
    return m


GROUP_MIN_WINDOWS = 200


def group_segments(train: Sequence[Segment], val: Sequence[Segment], groups: Sequence[str],
                   val_groups: Sequence[str]) -> Dict[str, Tuple[List[Segment], List[Segment]]]:
    out: Dict[str, Tuple[List[Segment], List[Segment]]] = {}
    for s, g in zip(train, groups):
        out.setdefault(g, ([], []))[0].append(s)
    for s, g in zip(val, val_groups):
        if g in out:
            out[g][1].append(s)
    return out


def time_blocks(segments: Sequence[Segment], k: int = 4) -> Dict[str, Tuple[List[Segment], List[Segment]]]:
    """One recording's segments cut into ``k`` blocks of equal time (``block1`` .. ``blockk``)."""
    name = segments[0].name if segments else ""
    return {f"block{i + 1}": (cut(list(segments), i / k, (i + 1) / k, name), []) for i in range(k)}


def recordings_or_blocks(train: Sequence[Segment], val: Sequence[Segment], groups: Sequence[str],
                         val_groups: Sequence[str]) -> Tuple[Dict[str, Tuple[List[Segment], List[Segment]]], bool]:
    """The one rule of what a refit takes alone and a fold holds out: each recording (its training and
    validation segments) where there are several, else four time blocks of the single one (no validation
    segments); the second value says which (True: blocks)."""
    per = group_segments(train, val, groups, val_groups)
    return (per, False) if len(per) >= 2 else (time_blocks(train), True)


def refit_groups(train: Sequence[Segment], val: Sequence[Segment], groups: Sequence[str], val_groups: Sequence[str],
                 window: int) -> Dict[str, Tuple[List[Segment], List[Segment]]]:
    """The groups the uncertainty refits run on (module doc, :func:`recordings_or_blocks`); only those with a
    training segment longer than ``window`` samples."""
    per, _ = recordings_or_blocks(train, val, groups, val_groups)
    return {g: tv for g, tv in per.items() if any(len(s) > window + 1 for s in tv[0])}


def fit_floor(train: List[Segment], val: List[Segment], settings: FitSettings, groups: Sequence[str],
              val_groups: Sequence[str], progress: Progress = lambda s: None, uncertainty: bool = True,
              terms: Optional[Dict[str, Any]] = None) -> FloorFit:
    """The floor on all of ``train`` (``val`` for its selection; ``terms``: :func:`fit_once`'s), then on
    each group alone (``uncertainty=False``: not; every standard deviation NaN)."""
    n = len(train)
    progress(f"fitting the floor (traditional+timing) on {n} segment{'s' if n != 1 else ''}, "
             f"{sum(len(s) for s in train)} samples")
    method, log = fit_once(train, val, settings, terms=terms)
    floor = Floor.from_dict(method.to_dict())
    if not uncertainty:
        return FloorFit(floor, log, TraditionalParams.unknown(), [])
    usable = list(refit_groups(train, val, groups, val_groups, settings.window).items())

    def refit_progress(i: int) -> None:
        progress(f"uncertainty: refitting on {usable[i][0]} alone ({i + 1}/{len(usable)})")

    max_windows = max(GROUP_MIN_WINDOWS, method.max_windows // max(1, len(usable)))
    with Split([tv for _, tv in usable]) as split:  # with the command's helper process where it has one
        fits = split.step(_refit_params, method, settings, max_windows, on_item=refit_progress)
    info = [{"group": g, "segments": len(tr), "samples": int(sum(len(s) for s in tr)),
             "time_offset_samples": float(p.time_offset), "b_g": p.b_g.tolist(), "b_a": p.b_a.tolist()}
            for (g, (tr, _)), p in zip(usable, fits)]
    return FloorFit(floor, log, spread(fits), info)


def _refit_params(item: Tuple[List[Segment], List[Segment]], state: Dict[str, Any], method: TraditionalTiming,
                  settings: FitSettings, max_windows: int) -> TraditionalParams:
    """One group's refit (:func:`refit_once`) as its parameters, one thread per pool (the other process
    works beside it)."""
    with thread_limits(1):
        return TraditionalParams.from_dict(refit_once(method, item[0], item[1], settings, max_windows).to_dict())


def spread(fits: Sequence[TraditionalParams]) -> TraditionalParams:
    """Per estimate, the standard error of the mean of ``fits`` (their spread over sqrt(n)); every
    one NaN with fewer than two."""
    if len(fits) < 2:
        return TraditionalParams.unknown()
    std = {k: np.std(np.stack([p.estimate(k) for p in fits]), axis=0, ddof=1) / math.sqrt(len(fits))
           for k in ESTIMATES}
    return TraditionalParams(**std)


def world_specific_force_sums(seg: Segment, acc: np.ndarray) -> np.ndarray:
    """Cumulative Σ R_i a_i dt (N, 3), row j = the sum over samples 0..j-1 (the zero-order hold)."""
    dt = (np.diff(seg.t_ns.astype(np.int64)) * 1e-9)[:, None]
    f = quat_rotate(seg.q_wxyz[:-1], acc[:-1]) * dt
    return np.concatenate([np.zeros((1, 3)), np.cumsum(f, axis=0)])


def gravity_per_window(seg: Segment, acc: np.ndarray, window: int) -> np.ndarray:
    """Gravity [m/s^2] implied by each non-overlapping window of ``window`` samples."""
    n = len(seg)
    if n <= window:
        return np.zeros(0)
    c = world_specific_force_sums(seg, acc)
    i0 = np.arange(0, n - window, window)
    i1 = i0 + window
    T = (seg.t_ns[i1] - seg.t_ns[i0]).astype(np.float64) * 1e-9
    dv = seg.v[i1] - seg.v[i0]
    return -(dv[:, 2] - (c[i1, 2] - c[i0, 2])) / T


def fit_gravity(segments: Sequence[Segment], floor: Floor, groups: Sequence[str],
                window_s: float = 1.0) -> Tuple[float, float, Dict[str, float]]:
    """(g, its standard deviation over groups, g per group) from the floor-calibrated accelerometer."""
    per: Dict[str, List[np.ndarray]] = {}
    for s, g in zip(segments, groups):
        window = max(2, int(round(window_s / (median_period_ns(s.t_ns) * 1e-9))))
        _, acc = apply_floor(floor, s.t_ns, s.gyro, s.acc)
        per.setdefault(g, []).append(gravity_per_window(s, acc, window))
    means = {g: float(np.median(np.concatenate(v))) for g, v in per.items() if sum(len(x) for x in v)}
    if not means:
        return math.nan, math.nan, {}
    allw = np.concatenate([x for v in per.values() for x in v])
    g = float(np.median(allw))
    vals = np.array(list(means.values()))
    std = float(np.std(vals, ddof=1) / math.sqrt(len(vals))) if len(vals) >= 2 else float(
        1.4826 * np.median(np.abs(allw - g)) / math.sqrt(len(allw)))
    return g, std, means


def calibrated(segments: Sequence[Segment], floor: Any, lowpass: bool) -> List[Tuple[np.ndarray, np.ndarray]]:
    """Each segment's floor-calibrated (gyro, acc) (``floor``: a Floor or its saved dict);
    ``lowpass=False`` leaves the floor's filter out (the noise is measured on the unfiltered samples)."""
    f = Floor.of(floor)
    assert f is not None, "calibrated: no floor"
    f = f if lowpass else f.without_lowpass()
    return [f.apply(s.t_ns, s.gyro, s.acc) for s in segments]

