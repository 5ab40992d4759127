"""The "timing" floor: the raw IMU with one constant time offset, fitted on the training split.

Why a fitted offset and not the midpoint rule. The evaluation integrates with a zero-order hold:
sample i acts over [t_i, t_i+1]. A sensor that reports the rate *at* t_i is then half a sample
early on average; replacing each sample by the mean of it and the next (the midpoint rule) fixes
that, and docs/experiments/headroom_euroc.md measured it explains most of what the shipped EuRoC model gained.
The midpoint rule is the special case tau = 0.5 sample of resampling at t + tau; a fitted tau also
absorbs a real clock offset between the IMU and the ground truth (a temporal calibration, as Kalibr
fits for cameras) or a device whose samples are already interval means (tau ~ 0), and it costs a
1-D search. So this module fits tau and reports it (the fit log and the saved JSON carry it): a
fitted value near 0.5 says the midpoint rule was the whole story on that device.

Model: both sensors resampled by linear interpolation at t_i + tau * dt (dt the median sample
period; one offset for both, they share the IMU's clock; ends held at the first/last sample).
tau = 0 returns the input unchanged, bit for bit.

Fit (``fit``): the same increment residuals ``traditional`` uses for its gyro stage (the angle of
Δq_gt⁻¹ Δq̂ after the paper's fractions of ``window`` samples, windows spread over the training
sequences, at most ``max_windows``), Huber-weighted (``huber_rot`` rad) and averaged, but over
short windows (``window`` = 10 samples by default, not the training window): the timing error of
the zero-order hold is a boundary term that does not grow with the horizon, while the bias and
noise do, and over long windows the bias pulls the offset. Measured on EuRoC's paper split
(training flights, raw): 200-sample windows fit tau = 0.26, 10-sample windows 0.50, the same
search with each flight's own bias removed first 0.48 / 0.54, and the four test flights' own
optimum (start-up bias removed) is 0.46 / 0.50. The cost is
evaluated on a grid of tau from ``-max_shift`` to ``max_shift`` samples (step ``grid_step``), then
refined by golden-section search around the best grid point (to ``tol`` samples). Validation is
used for selection only: when the fitted offset does not lower the validation cost below tau = 0,
tau = 0 is kept. The rotation residuals alone choose tau because they do not depend on gravity or
the accelerometer bias; the accelerometer gets the same offset.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np

from imu_learn.baselines.base import FitSettings, Method
from imu_learn.core.integration import PAPER_FRACTIONS, offset_rotation_angles, window_labels
from imu_learn.data.types import Segment, median_period_ns

GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
OFFSET_BRACKET = 0.5  # a search from an earlier fit's offset stays within this many samples of it


def resample(t_ns: np.ndarray, x: np.ndarray, tau: float, period_ns: float) -> np.ndarray:
    """x (N, C) linearly interpolated at t + tau·period (ends held); tau = 0: a copy of x, bit for bit."""
    x = np.asarray(x, dtype=np.float64)
    if tau == 0.0 or len(x) < 2:
        return x.copy()
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])).astype(np.float64)
    tq = t + tau * period_ns
    return np.stack([np.interp(tq, t, x[:, c]) for c in range(x.shape[1])], axis=1)


def shifted(seq: Segment, tau: float) -> Segment:
    """``seq`` with gyro and accelerometer resampled at t + tau samples (ground truth unchanged)."""
    if tau == 0.0:
        return seq
    per = median_period_ns(seq.t_ns)
    return Segment(seq.name, seq.t_ns, resample(seq.t_ns, seq.gyro, tau, per),
                    resample(seq.t_ns, seq.acc, tau, per), seq.p, seq.v, seq.q_wxyz)


class RotationWindows:
    """Training (or validation) windows and their ground-truth rotation increments, so the gyro
    residual cost of any offset is one resample plus one integration per sequence."""

    def __init__(self, seqs: Seq[Segment], window: int, max_windows: int, gravity: float = 9.81) -> None:
        usable = [s for s in seqs if len(s) > window + 1]
        total = sum(len(s) - window for s in usable)
        self.stride = max(1, math.ceil(total / max_windows)) if max_windows > 0 else 1
        self.items = []
        for s in usable:
            lab = window_labels(s, window, self.stride, PAPER_FRACTIONS, gravity)
            if len(lab.starts):
                self.items.append((s, median_period_ns(s.t_ns), lab))

    def __len__(self) -> int:
        return sum(len(lab.starts) for _, _, lab in self.items)

    def angles(self, tau: float) -> np.ndarray:
        """Rotation residual angles [rad] of every window and horizon with the gyro shifted by tau."""
        out = [offset_rotation_angles(s.t_ns, s.gyro, lab, tau, per) for s, per, lab in self.items]
        return np.concatenate(out) if out else np.zeros(0)

    def cost(self, tau: float, delta: float) -> float:
        """Mean Huber loss of the residual angles (quadratic below ``delta`` rad, linear above)."""
        a = self.angles(tau)
        return float(np.mean(np.where(a <= delta, 0.5 * a * a, delta * (a - 0.5 * delta))))


def golden_section(f: Callable[[float], float], a: float, b: float, tol: float) -> Tuple[float, float]:
    """(x, f(x)) of the lower of the two last interior points of a golden-section search for a
    minimum of ``f`` in [a, b], stopped when the bracket is at most ``tol`` wide."""
    c, d = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
    fc, fd = f(c), f(d)
    while b - a > tol:
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - GOLDEN * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + GOLDEN * (b - a)
            fd = f(d)
    return (c, fc) if fc <= fd else (d, fd)


def fit_offset(windows: RotationWindows, max_shift: float, grid_step: float, tol: float,
               delta: float) -> Tuple[float, List[float], List[float]]:
    """(tau minimising ``windows.cost``, the grid, the cost at each grid point): grid, then golden
    section between the best grid point's neighbours."""
    k = int(round(max_shift / grid_step))
    grid = [i * grid_step for i in range(-k, k + 1)]
    costs = [windows.cost(t, delta) for t in grid]
    i = int(np.argmin(costs))
    x, fx = golden_section(lambda t: windows.cost(t, delta), grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)], tol)
    best = min([(costs[i], grid[i]), (fx, x)])
    return float(best[1]), grid, [float(x) for x in costs]


def fit_offset_near(windows: RotationWindows, start: Optional[float], max_shift: float, grid_step: float, tol: float,
                    delta: float) -> float:
    """tau minimising ``windows.cost`` by a golden-section search within ±``OFFSET_BRACKET`` samples of
    ``start`` (an earlier fit's offset on overlapping data: a refit on part of it, a fold of held-out
    selection), or by :func:`fit_offset`'s whole search where ``start`` is None or not finite, or the
    minimum lies at that bracket's edge."""
    if start is not None and math.isfinite(start):
        lo, hi = start - OFFSET_BRACKET, start + OFFSET_BRACKET
        tau, _ = golden_section(lambda t: windows.cost(t, delta), lo, hi, tol)
        if lo + 2 * tol < tau < hi - 2 * tol:
            return float(tau)
    return fit_offset(windows, max_shift, grid_step, tol, delta)[0]


class Timing(Method):
    """Raw IMU resampled at a constant time offset ``tau`` [samples] fitted on the training split."""

    name = "timing"
    rotation_only = False
    save_suffix = ".json"

    def __init__(self, max_shift: float = 3.0, grid_step: float = 0.25, tol: float = 1e-3,
                 window: int = 10, max_windows: int = 5000, huber_rot: float = 0.01) -> None:
        self.max_shift = float(max_shift)
        self.grid_step = float(grid_step)
        self.tol = float(tol)
        self.window = window
        self.max_windows = int(max_windows)
        self.huber_rot = float(huber_rot)
        self.tau = 0.0

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        s = shifted(seq, self.tau)
        return np.ascontiguousarray(s.gyro, dtype=np.float64), np.ascontiguousarray(s.acc, dtype=np.float64)

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        if not any(len(s) > settings.window for s in train):  # the data shape every method is given
            raise ValueError(f"no training sequence is longer than the window ({settings.window} samples)")
        window = int(self.window)
        tr = RotationWindows(train, window, self.max_windows, settings.gravity)
        if len(tr) == 0:
            raise ValueError(f"no training sequence is longer than the offset window ({window} samples)")
        tau, grid, costs = fit_offset(tr, self.max_shift, self.grid_step, self.tol, self.huber_rot)
        va = RotationWindows(val, window, self.max_windows, settings.gravity) if val else tr
        if len(va) == 0:
            va = tr
        val_zero, val_tau = va.cost(0.0, self.huber_rot), va.cost(tau, self.huber_rot)
        self.tau = tau if val_tau < val_zero else 0.0
        train_zero, train_tau = tr.cost(0.0, self.huber_rot), tr.cost(self.tau, self.huber_rot)
        return {
            "tau_samples": [self.tau], "tau_fitted": [tau], "grid": grid, "grid_cost": costs,
            "val_cost": [val_zero, val_tau], "train_loss": [train_zero, train_tau],
            "train_windows": [len(tr)], "stride": [tr.stride],
        }

    def to_dict(self) -> dict:
        return {"method": self.name, "tau_samples": self.tau}

    def save(self, path: Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2))

    def load(self, path: Path) -> Timing:
        d = json.loads(Path(path).read_text())
        if d.get("method") != self.name:
            raise ValueError(f"{path} holds {d.get('method')!r} parameters, not {self.name!r}")
        self.tau = float(d["tau_samples"])
        return self
