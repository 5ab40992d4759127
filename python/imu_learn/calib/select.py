"""A device profile's terms chosen by the recordings they were not fitted on (``imu-learn calibrate``).

Levels. The floor (:mod:`imu_learn.baselines.traditional`, ``traditional+timing``) is cut into nested
levels per sensor, each adding terms to the one before:

    gyroscope      offset, bias, scale, affine, g_sensitivity, lowpass
    accelerometer  offset, bias, scale, affine, lowpass

``offset``: the time offset alone (the ``timing`` floor; the offset is one for both sensors, the IMU's
clock); ``bias``: + b; ``scale``: + the diagonal of M; ``affine``: + all of M; ``g_sensitivity``: + G
(gyroscope only); ``lowpass``: + the low-pass cut-off, chosen from the floor's grid on the validation
blocks as the floor's own fit chooses it. Each level is fitted by the floor's own estimator
(:func:`imu_learn.baselines.traditional._solve` on its exact residuals and Jacobians, the same windows,
Huber weights and prior), restricted to the level's parameters, warm-started from the level before.

Held out. Each recording in turn is held out (leave one recording out) where there are several;
a single recording is cut into four contiguous time blocks (:func:`imu_learn.calib.fit.time_blocks`),
each held out in turn. On each fold the time offset is fitted on the rest (the floor's search, within
±0.5 samples of the full fit's offset as the floor's own refits search, the whole grid where the minimum
lies at that edge; kept only where it lowers the validation cost), then every level; each level is scored on the held-out
recording (all its blocks, each segment from its own ground-truth start, as ``imu-learn evaluate``
scores: :mod:`imu_learn.score.metrics`, :mod:`imu_learn.score.peers`). The cells:

* gyroscope (the accelerometer at its full level, fitted once per fold with the full gyroscope: an
  uncalibrated accelerometer's errors would decide the translation cells): relative rotation and
  translation RMSE at every horizon
  (``settings.horizons``, else 10 and 200 samples; windows every 10 samples), start-up bias removed
  (:func:`~imu_learn.score.metrics.fit_startup_bias` on the first ``startup_bias_s`` = 10 s of each
  segment, at most 30 % of it), and the open-loop AOE (RMSE over every sample);
* accelerometer (the gyroscope at its chosen level): relative translation RMSE at every horizon with the
  start-up bias removed, and open loop (no AOE exists for it; without an open-loop cell no accelerometer
  bias could ever be chosen: the start-up bias removal absorbs it).

Each table scores only the cells its rule reads (profile.json's held-out figures hold those). The folds
are split between this process and a helper process, each fold's fits and held-out scores where the
fold is held (:class:`~imu_learn.util.helper.Split`; one thread per pool each): the same figures as one
after another.

The rule. Levels are visited from the simplest; ``chosen`` starts at ``offset``. A richer level L
becomes ``chosen`` only if (1) no simpler level beats it: in every held-out cell of every fold its
error is at most (1 + ``WORSE``) × that of every simpler level (``WORSE`` = 0.5 %, the tolerance of
"no worse"), and (2) it gains: in at least one held-out cell its error is at most (1 − ``GAIN``) ×
that of ``chosen`` (``GAIN`` = 1 %). A level that fails is skipped and the next richer one is still
tried against ``chosen``. So the chosen level is never beaten by a simpler one in any held-out cell.

The profile's floor is then fitted at the chosen levels on all the training recordings (the full fit
kept as it is where the chosen levels are all it has); profile.json's ``selection`` entry holds the
levels, the rule, and every held-out figure behind them.

A poses reference that cannot resolve accelerations (a 20 Hz VO; its source restricts the floor's
terms): its rotations are accurate, so the gyroscope's levels are chosen against them
(``SelectOptions.gyro_only``): up to ``g_sensitivity`` (no low-pass: a 20 Hz reference does not see
one), on the rotation cells only (rotation at every horizon and the open-loop AOE against the
reference's attitude: its positions over 10-200 IMU samples are its interpolation's), fitted and scored
on the IMU seen through the reference's interpolation as its floor is
(:meth:`~imu_learn.calib.sources.PosesSource.match_kernel`), the accelerometer at ``bias`` in every
fold. The accelerometer's level (:data:`POSITION_ACC_LEVELS`: no low-pass) is then chosen on the
source's fit from the positions (:func:`select_acc_from_positions`: each recording held out in turn,
its second-difference residual the cell) and refitted on all recordings at it; with
one recording the source's twelve terms stay.

No selection (the entry says why, the full floor kept): a positions or odometry reference (their
sources fix the terms they observe), and recordings too short to hold any out. A reference whose stamps were
moved by its own lag keeps the time offset's prior in every fold (not observed). The fits are the
floor's own (numpy, no torch).
"""
from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.baselines.affine import FLOOR_METHOD, Floor, TraditionalParams
from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.timing import RotationWindows, fit_offset_near, shifted
from imu_learn.baselines.traditional import (
    DEFAULT_CUTOFFS,
    Subset,
    _Data,
    _gyro_model,
    _rms,
    _RotResiduals,
    _solve,
    _VelResiduals,
)
from imu_learn.calib.acc_positions import (
    ATTITUDE,
    AccOptions,
    fit_acc_from_positions,
    fit_acc_from_rows,
    heldout_rms_rows,
    recording_rows,
)
from imu_learn.calib.fit import recordings_or_blocks, refit_groups, seed_all, spread, time_blocks
from imu_learn.calib.profile import FloorFit
from imu_learn.calib.sources import matched
from imu_learn.core.integration import preintegrate
from imu_learn.data.types import Segment, sample_rate_hz
from imu_learn.score.metrics import fit_startup_bias, index_at, relative_pose_errors, remove_bias, rmse, with_imu
from imu_learn.score.peers import attitude_errors
from imu_learn.util.helper import Split
from imu_learn.util.threads import thread_limits

Progress = Callable[[str], None]
GYRO_LEVELS = ("offset", "bias", "scale", "affine", "g_sensitivity", "lowpass")
ACC_LEVELS = ("offset", "bias", "scale", "affine", "lowpass")
WORSE = 0.005  # "no worse": at most 0.5 % above a simpler level in every held-out cell
GAIN = 1e-2  # "better": at least 1 % below the level chosen so far in one held-out cell
PRIOR, HUBER_ROT, HUBER_VEL, MAX_ITER = 1e-3, 0.01, 0.1, 20  # the floor's (Traditional's defaults)
RULE = (f"levels visited from the simplest; a richer level is chosen only if in every held-out cell its error is at "
        f"most {1 + WORSE:g} x that of every simpler level, and in at least one cell at most {1 - GAIN:g} x that of "
        "the level chosen so far")


@dataclass(frozen=True)
class SelectOptions:
    horizons: Tuple[int, ...] = (10, 200)  # relative pose over n samples (the settings' horizons when given)
    stride: int = 10  # window starts [samples]
    startup_bias_s: float = 10.0  # start-up bias fitted on (at most 30 % of a held-out segment)
    max_windows: int = 1000  # the floor's window budget per fit
    tau: Optional[float] = None  # a fixed time offset [samples] (not observed); None: fitted per fold
    # the full fit's time offset [samples]: each fold searches within ±OFFSET_BRACKET of it (the refits' rule,
    # :func:`imu_learn.baselines.timing.fit_offset_near`; the whole grid where its minimum lies at the edge)
    tau_near: Optional[float] = None
    # a reference that cannot resolve accelerations (a 20 Hz VO): the gyroscope's levels only, up to
    # ``g_sensitivity`` (no low-pass: not observed), on the rotation cells (GYRO_ONLY_CELLS); the
    # accelerometer at ``bias`` (M_a = I) in every fold, and not selected
    gyro_only: bool = False
    # the richest gyroscope level tried (None: every one); a reference that turns about one axis only (a
    # ground robot) stops at ``bias``: held-out blocks of the same motion cannot tell a scale of the axes it
    # does not turn about from their noise (Fetch's one recording: x and y scales 0.55, "better" held out
    # because they shrink noise), nor a misalignment or g-sensitivity from the turn's
    gyro_upto: Optional[str] = None


@dataclass
class Fold:
    """Fitted on ``train`` (``val`` selects the offset and cut-offs), scored on ``held``."""

    name: str
    train: List[Segment]
    val: List[Segment]
    held: List[Segment]


def free_indices(sensor: str, level: str) -> np.ndarray:
    """The floor parameters a level fits: indices into θ_g (21: M_g − I row-major, b_g, G) or θ_a (12)."""
    nested = {"offset": [], "bias": [9, 10, 11], "scale": [0, 4, 8, 9, 10, 11], "affine": list(range(12))}
    if level in nested:
        return np.asarray(nested[level], dtype=np.int64)
    return np.arange(21 if sensor == "gyro" else 12)


def solve_level(res: Any, theta: np.ndarray, free: np.ndarray, huber: float) -> np.ndarray:
    """θ with its ``free`` entries solved from their current values (the floor's prior on M − I and G)."""
    out = np.zeros_like(theta)
    if free.size == 0:
        return out
    prior_idx = np.flatnonzero((free < 9) | (free >= 12))
    x = _solve(Subset(res, free, np.zeros_like(theta)), theta[free], prior_idx, PRIOR, huber, MAX_ITER)
    out[free] = x
    return out


def best_cutoff(residuals: Callable[[Optional[float]], Any], theta: np.ndarray, grid: Sequence[Optional[float]]
                ) -> Optional[float]:
    """The grid's cut-off with the lowest validation RMS at ``theta`` (the floor's rule)."""
    return grid[int(np.argmin([_rms(residuals(c), theta) for c in grid]))]


Levels = Dict[str, Tuple[np.ndarray, Optional[float]]]  # level -> (θ, cut-off)


def fit_gyro_levels(tr: _Data, va: _Data, grid: Sequence[Optional[float]], upto: str = "lowpass") -> Levels:
    """θ_g and the gyro cut-off of every level up to ``upto``, each warm-started from the one before."""
    out: Levels = {"offset": (np.zeros(21), None)}
    theta, res = np.zeros(21), _RotResiduals(tr.windows(None, None))
    for level in GYRO_LEVELS[1:GYRO_LEVELS.index(upto) + 1]:
        if level == "lowpass":
            c = best_cutoff(lambda c: _RotResiduals(va.windows(c, None)), theta, grid)
            theta = theta if c is None else solve_level(_RotResiduals(tr.windows(c, None)), theta, np.arange(21), HUBER_ROT)
            out[level] = (theta, c)
        else:
            theta = solve_level(res, theta, free_indices("gyro", level), HUBER_ROT)
            out[level] = (theta, None)
    return out


def _vel(data: _Data, theta_g: np.ndarray, c_g: Optional[float]) -> Callable[[Optional[float]], _VelResiduals]:
    """Accelerometer residuals at any acc cut-off with the gyro fixed (its rotations computed once)."""
    w = data.windows(c_g, None)
    rates = _gyro_model(theta_g, w.gyro, w.acc_g)
    return lambda c: _VelResiduals(rates, data.windows(c_g, c))


def fit_acc_levels(tr: _Data, va: _Data, grid: Sequence[Optional[float]], gyro: Tuple[np.ndarray, Optional[float]],
                   upto: str = "lowpass") -> Levels:
    """θ_a and the acc cut-off of every level up to ``upto`` with the gyro fixed at ``gyro`` (θ_g, cut-off)."""
    out: Levels = {"offset": (np.zeros(12), None)}
    res_tr, res_va = _vel(tr, *gyro), _vel(va, *gyro)
    theta, res = np.zeros(12), res_tr(None)
    for level in ACC_LEVELS[1:ACC_LEVELS.index(upto) + 1]:
        if level == "lowpass":
            c = best_cutoff(res_va, theta, grid)
            theta = theta if c is None else solve_level(res_tr(c), theta, np.arange(12), HUBER_VEL)
            out[level] = (theta, c)
        else:
            theta = solve_level(res, theta, free_indices("acc", level), HUBER_VEL)
            out[level] = (theta, None)
    return out


def floor_of(gyro: Tuple[np.ndarray, Optional[float]], acc: Tuple[np.ndarray, Optional[float]], tau: float) -> Floor:
    """The floor of (θ_g, gyro cut-off), (θ_a, acc cut-off) and the time offset [samples]."""
    (tg, cg), (ta, ca) = gyro, acc
    p = TraditionalParams(M_g=np.eye(3) + tg[:9].reshape(3, 3), b_g=tg[9:12].copy(), G=tg[12:21].reshape(3, 3).copy(),
                          M_a=np.eye(3) + ta[:9].reshape(3, 3), b_a=ta[9:12].copy(), cutoff_gyro=cg, cutoff_acc=ca,
                          time_offset=float(tau))
    return Floor(p, FLOOR_METHOD, 2)


def fit_tau(train: List[Segment], val: List[Segment], gravity: float, max_windows: int,
            near: Optional[float] = None) -> float:
    """The floor's time offset [samples]: its 1-D search on 10-sample gyro windows (near ``near``, where
    given), kept only where it lowers the validation cost
    (:meth:`imu_learn.baselines.traditional.Traditional._fit_time_offset`)."""
    tr = RotationWindows(train, 10, 5 * max_windows, gravity)
    tau = fit_offset_near(tr, near, 3.0, 0.25, 1e-3, HUBER_ROT)
    va = RotationWindows(val, 10, 5 * max_windows, gravity) if val else tr
    va = va if len(va) else tr
    return float(tau) if va.cost(tau, HUBER_ROT) < va.cost(0.0, HUBER_ROT) else 0.0


@dataclass
class Prepared:
    """A fold's time offset and its windows (the floor's), shifted by it, with the cut-off grid."""

    fold: Fold
    tau: float
    tr: _Data
    va: _Data
    grid: List[Optional[float]]
    gyro: Levels = field(default_factory=dict)
    acc: Levels = field(default_factory=dict)


def prepare(fold: Fold, settings: FitSettings, opts: SelectOptions) -> Prepared:
    seed_all(settings.seed)
    tau = (opts.tau if opts.tau is not None
           else fit_tau(fold.train, fold.val, settings.gravity, opts.max_windows, opts.tau_near))
    train, val = [shifted(s, tau) for s in fold.train], [shifted(s, tau) for s in fold.val]
    tr = _Data(train, settings.window, opts.max_windows, settings.gravity, 2)
    if len(tr) == 0:
        raise ValueError(f"selection, fold {fold.name}: no training segment longer than the window ({settings.window})")
    va = _Data(val, settings.window, opts.max_windows, settings.gravity, 2) if val else tr
    va = va if len(va) else tr
    fs = min(sample_rate_hz(s.t_ns) for s in train)
    grid = [c for c in DEFAULT_CUTOFFS if c is None or c < 0.5 * fs] or [None]
    return Prepared(fold, float(tau), tr, va, grid)


def folds(train: List[Segment], val: List[Segment], groups: Sequence[str], val_groups: Sequence[str]) -> List[Fold]:
    """Leave one recording out (several recordings), else four contiguous time blocks of the one
    (:func:`~imu_learn.calib.fit.recordings_or_blocks`; blocks validate on the recording's ``val``)."""
    per, blocks = recordings_or_blocks(train, val, groups, val_groups)
    return [Fold(g, [s for h, (tr, _) in per.items() if h != g for s in tr],
                 list(val) if blocks else [s for h, (_, va) in per.items() if h != g for s in va], tr_g + va_g)
            for g, (tr_g, va_g) in per.items()]


def _pool(out: Dict[str, List[np.ndarray]], key: str, x: np.ndarray) -> None:
    out.setdefault(key, []).append(np.asarray(x, dtype=np.float64))


CELLS = {"gyro": ("rot_deg", "trans_m", "aoe_deg"), "acc": ("trans_m", "open_trans_m")}
SCORED = tuple(dict.fromkeys(c for cs in CELLS.values() for c in cs))  # every cell a table reads


def score(floor: Floor, held: Sequence[Segment], horizons: Sequence[int], opts: SelectOptions,
          gravity: float, cells: Tuple[str, ...] = SCORED) -> Dict[str, float]:
    """The held-out cells of ``floor`` on ``held`` (module doc): ``rot_deg n=N``, ``trans_m n=N`` (start-up
    bias removed), ``open_trans_m n=N`` (open loop), ``aoe_deg``, those named in ``cells`` (a table's
    rule reads no other); segments pooled, NaN where none scored."""
    pooled: Dict[str, List[np.ndarray]] = {}
    fixed_cells = {"rot_deg", "trans_m"}.intersection(cells)
    for s in held:
        bias_s = min(opts.startup_bias_s, 0.3 * s.duration_s)
        first = index_at(s, bias_s)
        if first + min(horizons) >= len(s) - 1:
            continue
        g, a = floor.apply(s.t_ns, s.gyro, s.acc)
        cal = with_imu(s, g, a)
        fixed = remove_bias(cal, *fit_startup_bias(cal, bias_s, gravity=gravity)) if fixed_cells else cal
        # each variant integrated once, every horizon's windows composed from it
        pre_fixed = preintegrate(fixed.t_ns, fixed.gyro, fixed.acc) if fixed_cells else None
        pre_cal = preintegrate(cal.t_ns, cal.gyro, cal.acc) if "open_trans_m" in cells else None
        for n in horizons:
            if fixed_cells:
                e = relative_pose_errors(fixed, int(n), opts.stride, gravity, first, pre=pre_fixed)
                for c, key in (("rot_deg", "rot_rad"), ("trans_m", "trans_m")):
                    if c in cells:
                        _pool(pooled, f"{c} n={n}", e[key])
            if "open_trans_m" in cells:
                e = relative_pose_errors(cal, int(n), opts.stride, gravity, first, pre=pre_cal)
                _pool(pooled, f"open_trans_m n={n}", e["trans_m"])
        if "aoe_deg" in cells:
            _pool(pooled, "aoe_deg", attitude_errors(s, g)["angle_rad"])
    out = {k: rmse(np.concatenate(v)) for k, v in pooled.items()}
    return {k: math.degrees(v) if k.startswith(("rot", "aoe")) else v for k, v in out.items()}


GYRO_ONLY_LEVELS = GYRO_LEVELS[:-1]  # a reference that cannot resolve accelerations: no low-pass level
GYRO_ONLY_CELLS = ("rot_deg", "aoe_deg")  # its positions over 10-200 IMU samples are its interpolation's
# its accelerometer from the positions (calib.acc_positions): no low-pass level (not observed), one cell,
# the held-out recording's second-difference residual (RMS of its 3-vector's norm, as the translation
# cells score a position error; its world tilt fitted alone)
POSITION_ACC_LEVELS = ACC_LEVELS[:-1]
POSITION_ACC_CELLS = ("positions_rms_mps",)

Table = Dict[str, Dict[str, Dict[str, float]]]  # level -> fold -> cell -> error


def _ratios(table: Table, a: str, b: str, cells: Tuple[str, ...]) -> List[Tuple[float, str, str]]:
    """(error of level a / error of level b, fold, cell) over every held-out cell both have."""
    out = []
    for f, row in table[a].items():
        for c, v in row.items():
            w = table[b].get(f, {}).get(c, math.nan)
            if c.startswith(cells) and math.isfinite(v) and math.isfinite(w) and w > 0:
                out.append((v / w, f, c))
    return out


def choose(levels: Sequence[str], table: Table, cells: Tuple[str, ...]) -> Tuple[str, List[Dict[str, Any]]]:
    """The chosen level by the rule (module doc) and each step's reason."""
    chosen, steps = levels[0], []
    for i, level in enumerate(levels[1:], 1):
        worst = max([(r, f, c, s) for s in levels[:i] for r, f, c in _ratios(table, level, s, cells)], default=None)
        best = min(_ratios(table, level, chosen, cells), default=None)
        keep = worst is not None and best is not None and worst[0] <= 1 + WORSE and best[0] <= 1 - GAIN
        steps.append({"level": level, "against": chosen, "chosen": keep,
                      "worst_vs_simpler": None if worst is None else {"ratio": worst[0], "fold": worst[1], "cell": worst[2],
                                                                      "simpler": worst[3]},
                      "best_vs_chosen": None if best is None else {"ratio": best[0], "fold": best[1], "cell": best[2]}})
        chosen = level if keep else chosen
    return chosen, steps


@dataclass
class Selection:
    """The chosen level per sensor, the folds and every held-out figure behind the choice."""

    gyro: str
    acc: str
    kind: str  # "leave one recording out" or "four time blocks of one recording"
    folds: List[Dict[str, Any]]
    figures: Dict[str, Table]
    steps: Dict[str, List[Dict[str, Any]]]
    horizons: Tuple[int, ...]
    seconds: float = 0.0
    gyro_levels: Tuple[str, ...] = GYRO_LEVELS
    gyro_cells: Tuple[str, ...] = CELLS["gyro"]

    def to_dict(self) -> Dict[str, Any]:
        gyro_only = self.gyro_cells != CELLS["gyro"]
        return {"gyro": self.gyro, "acc": self.acc,
                "levels": {"gyro": list(self.gyro_levels), "acc": [] if gyro_only else list(ACC_LEVELS)},
                "rule": RULE, "held_out": self.kind, "horizons": list(self.horizons),
                "cells": {"gyro": list(self.gyro_cells), "acc": [] if gyro_only else list(CELLS["acc"])},
                "folds": self.folds, "steps": self.steps, "held_out_figures": self.figures,
                "seconds": round(self.seconds, 1)}


Rows = Dict[str, Dict[str, float]]  # one fold's: level -> cell -> error


def distinct(floors: Dict[str, Floor]) -> Tuple[List[Floor], Dict[str, int]]:
    """A fold's floors once each (a low-pass level whose cut-off came out None is the level below it),
    and each level's index among them."""
    keys: Dict[str, int] = {}
    unique: List[Floor] = []
    where = {}
    for level, floor in floors.items():
        key = json.dumps(floor.to_dict(), sort_keys=True)
        if key not in keys:
            keys[key] = len(unique)
            unique.append(floor)
        where[level] = keys[key]
    return unique, where


def fold_rows(floors: Dict[str, Floor], held: Sequence[Segment], horizons: Tuple[int, ...], opts: SelectOptions,
              gravity: float, cells: Tuple[str, ...]) -> Rows:
    """Every level's held-out cells on one fold, each distinct floor scored once."""
    unique, where = distinct(floors)
    scored = [score(f, held, horizons, opts, gravity, cells) for f in unique]
    return {level: dict(scored[k]) for level, k in where.items()}


@dataclass(frozen=True)
class Scoring:
    """How a step scores its fold's levels: at once where it runs in the helper process; where it runs
    in ``defer_pid`` (this process, which holds more folds), the floors go back unscored and their
    scores are shared by both processes (:meth:`~imu_learn.util.helper.Split.step_and_share`)."""

    horizons: Tuple[int, ...]
    opts: SelectOptions
    gravity: float
    cells: Tuple[str, ...]
    defer_pid: int

    def rows(self, floors: Dict[str, Floor], held: Sequence[Segment]) -> Tuple[Optional[Rows], Dict[str, Floor]]:
        if os.getpid() == self.defer_pid:
            return None, floors
        with thread_limits(1):
            return fold_rows(floors, held, self.horizons, self.opts, self.gravity, self.cells), {}


class SharedScores:
    """The scores :class:`Scoring` deferred: the jobs of this process's folds (``jobs``, the ``then`` of
    :meth:`~imu_learn.util.helper.Split.step_and_share`), then every fold's rows (``table``); a fold
    deferred after the jobs were made (the helper's, run here because the helper was lost) is
    scored there."""

    def __init__(self, fs: Sequence[Fold], scoring: Scoring) -> None:
        self.fs, self.scoring = fs, scoring
        self.folds: List[int] = []  # this process's folds, in the jobs' order

    def _args(self, i: int, f: Floor) -> Tuple[Any, ...]:
        sc = self.scoring
        return f, self.fs[i].held, sc.horizons, sc.opts, sc.gravity, sc.cells

    def jobs(self, done: Dict[int, Tuple[Optional[Rows], Dict[str, Floor]]]
             ) -> Tuple[Callable[..., Any], List[Tuple[Any, ...]]]:
        self.folds = sorted(i for i, (rows, _) in done.items() if rows is None)
        return score_job, [self._args(i, f) for i in self.folds for f in distinct(done[i][1])[0]]

    def table(self, out: Sequence[Tuple[Optional[Rows], Dict[str, Floor]]], scores: Sequence[Dict[str, float]],
              levels: Sequence[str]) -> Table:
        shared = iter(scores)
        rows = []
        for i, (r, floors) in enumerate(out):
            if r is None:
                unique, where = distinct(floors)
                got = [next(shared) if i in self.folds else score_job(*self._args(i, f)) for f in unique]
                r = {level: dict(got[j]) for level, j in where.items()}
            rows.append(r)
        return {lv: {f.name: r[lv] for f, r in zip(self.fs, rows)} for lv in levels}


def score_job(floor: Floor, held: Sequence[Segment], horizons: Tuple[int, ...], opts: SelectOptions, gravity: float,
              cells: Tuple[str, ...]) -> Dict[str, float]:
    """:func:`score` at one thread per pool (a shared job, in either process)."""
    with thread_limits(1):
        return score(floor, held, horizons, opts, gravity, cells)


def _fold_info(p: Prepared, top: str) -> Dict[str, Any]:
    return {"held_out": p.fold.name, "time_offset_samples": p.tau, "cutoff_gyro": p.gyro[top][1],
            "train_segments": len(p.fold.train), "held_out_samples": int(sum(len(s) for s in p.fold.held))}


def _gyro_step(fold: Fold, state: Dict[str, Any], settings: FitSettings, opts: SelectOptions, levels: Tuple[str, ...],
               gyro_only: bool, scoring: Scoring) -> Tuple[Tuple[Optional[Rows], Dict[str, Floor]], Dict[str, Any]]:
    """A fold's time offset, its gyroscope's levels (the accelerometer at its full level, or at ``bias``
    for a reference that cannot resolve accelerations) and their held-out rows (or floors:
    :class:`Scoring`); the fold kept in ``state``."""
    with thread_limits(1):
        top = levels[-1]
        p = prepare(fold, settings, opts)
        if gyro_only:
            p.grid = [None]
        p.gyro = fit_gyro_levels(p.tr, p.va, p.grid, top)
        acc = ("bias", "bias") if gyro_only else ("lowpass", "full")
        p.acc = {acc[1]: fit_acc_levels(p.tr, p.va, p.grid, p.gyro[top], acc[0])[acc[0]]}
        state["prep"] = p
        floors = {lv: floor_of(p.gyro[lv], p.acc[acc[1]], p.tau) for lv in levels}
        info = _fold_info(p, top)
        if gyro_only:
            info["cutoff_gyro"] = None
    return scoring.rows(floors, fold.held), info


def _acc_step(fold: Fold, state: Dict[str, Any], g_level: str, scoring: Scoring
              ) -> Tuple[Optional[Rows], Dict[str, Floor]]:
    """A fold's accelerometer levels with the gyroscope at ``g_level``, and their held-out rows (or floors)."""
    with thread_limits(1):
        p: Prepared = state["prep"]
        p.acc = fit_acc_levels(p.tr, p.va, p.grid, p.gyro[g_level])
        floors = {lv: floor_of(p.gyro[g_level], p.acc[lv], p.tau) for lv in ACC_LEVELS}
    return scoring.rows(floors, fold.held)


def select_levels(train: List[Segment], val: List[Segment], groups: Sequence[str], val_groups: Sequence[str],
                  settings: FitSettings, opts: SelectOptions = SelectOptions(),
                  progress: Progress = lambda s: None) -> Selection:
    """Each level fitted on every fold and scored on its held-out part; the gyro's level chosen first
    (the accelerometer at its full level), then the accelerometer's (the gyro at its chosen level).
    The folds are split between this process and a helper process (:class:`~imu_learn.util.helper.Split`:
    the same figures as one after another)."""
    t0 = time.time()
    horizons = tuple(sorted({int(n) for n in settings.horizons})) or opts.horizons
    fs = folds(train, val, groups, val_groups)
    kind = "leave one recording out" if len(set(groups)) >= 2 else "four time blocks of one recording"
    names, top = (GYRO_ONLY_LEVELS, opts.gyro_upto if opts.gyro_upto in GYRO_ONLY_LEVELS else GYRO_ONLY_LEVELS[-1]) \
        if opts.gyro_only else (GYRO_LEVELS, opts.gyro_upto or GYRO_LEVELS[-1])
    levels = names[:names.index(top) + 1]
    cells = GYRO_ONLY_CELLS if opts.gyro_only else CELLS["gyro"]
    what = "the gyroscope's levels" + (" (rotation only)" if opts.gyro_only else "")
    gyro_scoring = Scoring(horizons, opts, settings.gravity, cells, os.getpid())
    acc_scoring = replace(gyro_scoring, cells=CELLS["acc"])
    with Split(fs, start=True) as split:  # each step and scoring job holds its pools at one thread
        if split.theirs:
            progress(f"selection: {len(fs)} folds, " + ", ".join(fs[i].name for i in split.theirs)
                     + " held out in a helper process")

        def fold_progress(i: int) -> None:
            progress(f"selection: {fs[i].name} held out ({i + 1}/{len(fs)}): {what}")

        shared = SharedScores(fs, gyro_scoring)
        out, scores = split.step_and_share(_gyro_step, (settings, opts, levels, opts.gyro_only, gyro_scoring),
                                           fold_progress, lambda done: shared.jobs({i: r for i, (r, _) in done.items()}))
        gyro_t = shared.table([r for r, _ in out], scores, levels)
        if not any(math.isfinite(v) for row in gyro_t["offset"].values() for v in row.values()):
            raise ValueError(f"no held-out segment is longer than the start-up bias span and {min(horizons)} samples")
        g_level, g_steps = choose(levels, gyro_t, cells)
        fold_info = [info for _, info in out]
        if opts.gyro_only:
            progress(f"selection: gyroscope {g_level}; the accelerometer from the reference's positions next")
            return Selection(g_level, "not selected", kind, fold_info, {"gyro": gyro_t, "acc": {}},
                             {"gyro": g_steps, "acc": []}, horizons, time.time() - t0, levels, GYRO_ONLY_CELLS)
        progress(f"selection: gyroscope {g_level}; the accelerometer's levels")
        shared = SharedScores(fs, acc_scoring)
        out, scores = split.step_and_share(_acc_step, (g_level, acc_scoring), then=shared.jobs)
        acc_t = shared.table(out, scores, ACC_LEVELS)
    a_level, a_steps = choose(ACC_LEVELS, acc_t, CELLS["acc"])
    return Selection(g_level, a_level, kind, fold_info, {"gyro": gyro_t, "acc": acc_t},
                     {"gyro": g_steps, "acc": a_steps}, horizons, time.time() - t0, levels)


def fit_at_levels(train: List[Segment], val: List[Segment], settings: FitSettings, levels: Tuple[str, str],
                  tau: float, opts: SelectOptions = SelectOptions()) -> Floor:
    """The floor at (gyro level, acc level) on all of ``train`` (``val`` selects a cut-off), offset ``tau``."""
    with thread_limits(1):
        return _fit_levels(train, val, settings, levels, tau, opts)


def _fit_levels(train: List[Segment], val: List[Segment], settings: FitSettings, levels: Tuple[str, str],
                tau: float, opts: SelectOptions) -> Floor:
    """:func:`fit_at_levels` inside the caller's thread limits."""
    p = prepare(Fold("all", train, val, []), settings, replace(opts, tau=tau))
    g = fit_gyro_levels(p.tr, p.va, p.grid, levels[0])[levels[0]]
    a = fit_acc_levels(p.tr, p.va, p.grid, g, levels[1])[levels[1]]
    return floor_of(g, a, tau)


def _level_refit(item: Tuple[List[Segment], List[Segment]], state: Dict[str, Any], settings: FitSettings,
                 levels: Tuple[str, str], tau: float, opts: SelectOptions) -> TraditionalParams:
    """One recording's (or time block's) refit at the chosen levels (:func:`level_spread`)."""
    with thread_limits(1):
        return _fit_levels(item[0], item[1], settings, levels, tau, opts).params


def level_spread(train: List[Segment], val: List[Segment], groups: Sequence[str], val_groups: Sequence[str],
                 settings: FitSettings, levels: Tuple[str, str], tau: float, std: TraditionalParams,
                 opts: SelectOptions = SelectOptions(), progress: Progress = lambda s: None) -> TraditionalParams:
    """``std`` with the parameters the chosen ``levels`` fit replaced by their spread over the groups
    (:func:`imu_learn.calib.fit.fit_floor`'s rule: each recording, or four time blocks of one, refitted
    alone, at the levels and the time offset ``tau``; the standard error of their mean), the rest NaN
    (:func:`masked_std`); the time offset's and the cut-offs' kept. The full floor's spread misstates a
    level's: a bias refitted with every term trades with terms the motion barely excites (a level
    robot's g-sensitivity: Fetch's gyro bias spread 34-138 mrad/s with every term, a few at ``bias``)."""
    usable = list(refit_groups(train, val, groups, val_groups, settings.window).items())

    def refit_progress(i: int) -> None:
        progress(f"uncertainty at the chosen levels: refitting on {usable[i][0]} alone ({i + 1}/{len(usable)})")

    with Split([tv for _, tv in usable]) as split:  # with the command's helper process where it has one
        fits = split.step(_level_refit, settings, levels, tau, opts, on_item=refit_progress)
    out = masked_std(std, levels)
    if len(fits) < 2:
        return out
    return replace(masked_std(spread(fits), levels), time_offset=std.time_offset, cutoff_gyro=std.cutoff_gyro,
                   cutoff_acc=std.cutoff_acc)


def full_levels(floor: Floor) -> Tuple[str, str]:
    """The levels the full floor's fit amounts to (its low-pass only where it chose a cut-off)."""
    p = floor.params
    return ("lowpass" if p.cutoff_gyro is not None else "g_sensitivity",
            "lowpass" if p.cutoff_acc is not None else "affine")


def masked_std(std: TraditionalParams, levels: Tuple[str, str]) -> TraditionalParams:
    """``std`` with the parameters the chosen levels do not fit set to NaN (held at their prior)."""
    g = np.concatenate([std.M_g.ravel(), std.b_g, std.G.ravel()]).astype(np.float64)
    a = np.concatenate([std.M_a.ravel(), std.b_a]).astype(np.float64)
    keep_g, keep_a = np.zeros(21, bool), np.zeros(12, bool)
    keep_g[free_indices("gyro", levels[0])] = True
    keep_a[free_indices("acc", levels[1])] = True
    g[~keep_g], a[~keep_a] = np.nan, np.nan
    return replace(std, M_g=g[:9].reshape(3, 3), b_g=g[9:12], G=g[12:21].reshape(3, 3), M_a=a[:9].reshape(3, 3),
                   b_a=a[9:12])


def skip_reason(inp: Any) -> Optional[str]:
    """Why calibrate's inputs get no selection (None: they do; a poses reference that cannot resolve
    accelerations gets the gyroscope's, :func:`gyro_only`)."""
    if inp.source.kind != "poses":
        return f"a {inp.source.kind} reference: its source fits the floor it observes"
    return None


def gyro_only(inp: Any) -> bool:
    """A poses reference that cannot resolve accelerations (its source restricts the floor's terms: a
    20 Hz VO): its rotations are accurate, so the gyroscope's levels are chosen against them; the
    accelerometer keeps what its source fitted (from the positions)."""
    return bool(inp.source.floor_terms())


def select_floor(inp: Any, fit: FloorFit, progress: Progress = lambda s: None,
                 opts: Optional[SelectOptions] = None) -> Tuple[FloorFit, Dict[str, Any]]:
    """calibrate's step: the levels chosen on held-out recordings (:func:`select_levels`) and the floor
    at them (``fit`` as it is where they are all it has); returns the floor fit and the ``selection`` entry.
    A reference that cannot resolve accelerations (:func:`gyro_only`): the gyroscope's levels, fitted
    and scored on the IMU seen through the reference's interpolation as its floor was
    (:meth:`~imu_learn.calib.sources.PosesSource.match_kernel`), the accelerometer the source's."""
    why = skip_reason(inp)
    if why is not None:
        return fit, {"skipped": why}
    tau = fit.floor.params.time_offset
    fixed = "time_offset_fitted_on_the_moved_reference" in fit.log
    only = gyro_only(inp)
    frame = getattr(inp.source, "frame", None)
    upto = "bias" if frame is not None and frame.turns_about_one_axis else None
    opts = opts or SelectOptions(tau=tau if fixed else None, tau_near=tau, gyro_only=only, gyro_upto=upto)
    kernel = inp.source.match_kernel(inp) if only and hasattr(inp.source, "match_kernel") else np.ones(1)
    data = matched(inp, kernel) if len(kernel) > 1 else inp
    try:
        sel = select_levels(data.train, data.val, data.groups, data.val_groups, data.settings, opts, progress)
    except ValueError as e:  # too little data to hold any out: the full floor, and why
        return fit, {"skipped": f"no selection: {e}"}
    entry = sel.to_dict()
    if only:
        return _gyro_only_floor(inp, data, fit, sel, entry, tau, opts, progress)
    levels = (sel.gyro, sel.acc)
    if levels == full_levels(fit.floor):
        entry["floor"] = "the full floor's fit: the chosen levels are all it has"
        return fit, entry
    progress(f"the floor at gyroscope {sel.gyro}, accelerometer {sel.acc} on all the training recordings")
    floor = fit_at_levels(inp.train, inp.val, inp.settings, levels, tau, opts)
    std = level_spread(inp.train, inp.val, inp.groups, inp.val_groups, inp.settings, levels, tau, fit.std, opts, progress)
    entry["floor"] = ("refitted at the chosen levels on all the training recordings (the time offset the full fit's); "
                      "standard deviations: the spread of refits at the chosen levels on each recording alone "
                      "(the time offset's the full floor's), null for what the levels hold at its prior")
    return replace(fit, floor=floor, std=std), entry


def _gyro_only_floor(inp: Any, data: Any, fit: FloorFit, sel: Selection, entry: Dict[str, Any], tau: float,
                     opts: SelectOptions, progress: Progress) -> Tuple[FloorFit, Dict[str, Any]]:
    """The floor at the chosen gyroscope level on all the training recordings; the accelerometer (matrix,
    bias, no low-pass) the source's fit's, at the level its positions choose (:func:`select_acc_from_positions`)."""
    if sel.gyro == GYRO_ONLY_LEVELS[-1]:
        entry["floor"] = "the full floor's fit: the chosen gyroscope level is all it has"
    else:
        progress(f"the floor at gyroscope {sel.gyro} on all the training recordings")
        floor = fit_at_levels(data.train, data.val, data.settings, (sel.gyro, "bias"), tau, opts)
        p = fit.floor.params
        floor = floor.with_params(M_a=p.M_a.copy(), b_a=p.b_a.copy(), cutoff_acc=p.cutoff_acc, cutoff_gyro=None)
        entry["floor"] = ("gyroscope refitted at the chosen level on all the training recordings (the time offset the "
                          "full fit's); the accelerometer the source's fit's; the gyroscope's standard deviations: the "
                          "spread of refits at its level on each recording alone, null for the terms it holds at its prior")
        g = level_spread(data.train, data.val, data.groups, data.val_groups, data.settings, (sel.gyro, "bias"), tau,
                         fit.std, opts, progress)
        fit = replace(fit, floor=floor, std=replace(fit.std, M_g=g.M_g, b_g=g.b_g, G=g.G))
    return _positions_acc_level(inp, fit, entry, progress), entry


def select_acc_from_positions(names: Sequence[str], recs: Sequence[Sequence[Segment]],
                              gyros: Sequence[Sequence[np.ndarray]], options: AccOptions, tau: float, gravity: float,
                              levels: Tuple[str, ...] = POSITION_ACC_LEVELS) -> Tuple[str, Table, List[Dict[str, Any]]]:
    """The accelerometer's level from a reference's positions: each recording held out in turn, every
    level of ``levels`` (:data:`POSITION_ACC_LEVELS`) fitted on the others (:func:`fit_acc_from_positions`) and scored by
    its second-difference residual on the held-out one (:func:`heldout_rms`, the RMS of the residual
    3-vector's norm); the rule of :func:`choose`. Each segment's rows are built once
    (:func:`recording_rows`: they depend on neither the level nor the fold)."""
    rows = recording_rows(recs, options, tau, gravity, gyros)
    with Split(list(range(len(names)))) as split:  # with the command's helper process where it has one
        held = split.step(_positions_fold, rows, options, levels)
    table: Table = {lv: {name: {POSITION_ACC_CELLS[0]: h[lv]} for name, h in zip(names, held)} for lv in levels}
    level, steps = choose(levels, table, POSITION_ACC_CELLS)
    return level, table, steps


def _positions_fold(r: int, state: Dict[str, Any], rows: Sequence[Sequence[Any]], options: AccOptions,
                    levels: Tuple[str, ...] = POSITION_ACC_LEVELS) -> Dict[str, float]:
    """Recording ``r`` held out: each level's fit on the others' rows, its held-out residual."""
    rest = [x for i, x in enumerate(rows) if i != r]
    with thread_limits(1):
        return {lv: heldout_rms_rows(fit_acc_from_rows(rest, options, free_indices("acc", lv), ATTITUDE[True]), rows[r])
                for lv in levels}


def _positions_acc_level(inp: Any, fit: FloorFit, entry: Dict[str, Any], progress: Progress) -> FloorFit:
    """``fit`` with the accelerometer the source fitted from the positions (all twelve terms) refitted at
    the level :func:`select_acc_from_positions` chooses; as it is with fewer than two recordings or no
    positions' fit (the entry's ``acc`` says why)."""
    source = inp.source
    acc_full = getattr(source, "acc_fit", None)
    names, recs, gyros = source.positions_data(inp, fit.floor) if acc_full is not None else ([], [], [])
    if acc_full is None:
        refused = getattr(source, "acc_refused", None)
        frame = getattr(source, "frame", None)
        dense = frame is not None and frame.resolves_acceleration  # held for its estimated scale, not its rate
        entry["acc"] = _source_acc(fit, f"refused, {refused}" if refused else
                                   "not needed (its velocity resolves accelerations; the matrix is not observed: "
                                   "its scale was estimated)" if dense else "not fitted")
        return fit
    held = (names, recs, gyros)
    if len(recs) < 2:  # one recording: four time blocks of it held out in turn (the gyroscope's rule)
        blocks = {k: v[0] for k, v in time_blocks(recs[0]).items() if v[0]}
        held = (list(blocks), list(blocks.values()),
                [[fit.floor.apply(x.t_ns, x.gyro, x.acc)[0] for x in segs] for segs in blocks.values()])
    progress("selection: the accelerometer's levels from the reference's positions (each "
             + ("recording" if len(recs) >= 2 else "time block of the one recording") + " held out)")
    tau, gravity = float(fit.floor.params.time_offset), inp.settings.gravity
    # a reference whose scale was estimated from this accelerometer: its matrix held at the identity
    upto = "bias" if source.acc_matrix_unobserved() else POSITION_ACC_LEVELS[-1]
    levels = POSITION_ACC_LEVELS[:POSITION_ACC_LEVELS.index(upto) + 1]
    try:
        level, table, steps = select_acc_from_positions(*held, acc_full.options, tau, gravity, levels)
        acc = fit_acc_from_positions(recs, acc_full.options, tau, gravity, gyros, free_indices("acc", level))
    except ValueError as e:
        entry["acc"] = _source_acc(fit, str(e))
        return fit
    progress(f"selection: accelerometer {level} (from the positions)")
    entry["acc"] = level
    entry["levels"] = {**entry.get("levels", {}), "acc": list(levels)}
    entry["cells"] = {**entry.get("cells", {}), "acc": list(POSITION_ACC_CELLS)}
    entry["held_out_figures"] = {**entry.get("held_out_figures", {}), "acc": table}
    entry["steps"] = {**entry.get("steps", {}), "acc": steps}
    source.acc_fit = acc
    a = masked_std(fit.std, ("affine", level))
    return replace(fit, floor=fit.floor.with_params(M_a=acc.M_a.copy(), b_a=acc.b_a.copy()),
                   std=replace(fit.std, M_a=a.M_a, b_a=a.b_a))


def _source_acc(fit: FloorFit, why: str) -> str:
    """The selection entry's ``acc`` where no level was chosen from the positions: what the floor holds (the
    source's fit: a bias with the matrix at its prior for a reference that cannot resolve accelerations)."""
    p = fit.floor.params
    held = "bias, the matrix at its prior (identity)" if np.array_equal(p.M_a, np.eye(3)) else "bias and matrix"
    return f"the floor's fit ({held}); the accelerometer from the reference's positions {why}"
