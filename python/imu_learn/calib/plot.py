"""``calibration.png``: the Allan deviations a profile came from. Top row: the residuals against the
reference, raw IMU (before, dashed) and with the floor (after, solid), with the power-law fit's
white-noise and random-walk lines; bottom row: the still stretches' Allan deviation with the
standard slope lines (N at τ = 1 s, K at τ = 3 s). A row without data says so. Needs matplotlib
(the eval extra); without it nothing is written and :func:`plot_calibration` returns False."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from imu_learn.calib.noise import MIN_RANDOM_WALK_TAU_S, AllanNoise, ResidualNoise
from imu_learn.util.atomic import atomic_write_path
from imu_learn.util.extras import optional

AXES = "xyz"


def _residual_panel(ax, before: Optional[ResidualNoise], after: Optional[ResidualNoise], key: str, unit: str) -> None:
    dev_a = getattr(after, f"{key}_dev") if after else None
    if dev_a is None:
        ax.text(0.5, 0.5, "no reference: no residuals", ha="center", va="center", transform=ax.transAxes)
        return
    dev_b = getattr(before, f"{key}_dev") if before else None
    fit = getattr(after, key)
    for j in range(3):
        ax.loglog(dev_a.tau_s, dev_a.adev[:, j], "-", color=f"C{j}", label=f"{AXES[j]} with the floor")
        if dev_b is not None:
            ax.loglog(dev_b.tau_s, dev_b.adev[:, j], "--", color=f"C{j}", alpha=0.5, label=f"{AXES[j]} raw")
        for term, style in (("white", ":"), ("random_walk", "-.")):
            c = fit.curve.get(term) if fit else None
            if c is not None and np.isfinite(c[:, j]).any():
                ax.loglog(dev_a.tau_s, c[:, j], style, color=f"C{j}", lw=0.8)
    ax.set_title(f"{key} residual vs reference (dotted: white fit, dash-dot: random walk)", fontsize=9)
    ax.set_xlabel("tau [s]")
    ax.set_ylabel(f"Allan deviation [{unit}]")
    ax.legend(fontsize=6, ncol=2)
    ax.grid(True, which="both", alpha=0.3)


def _still_panel(ax, allan: Optional[AllanNoise], cols: slice, name: str, unit: str) -> None:
    if allan is None:
        ax.text(0.5, 0.5, "no still stretch found", ha="center", va="center", transform=ax.transAxes)
        return
    d, f = allan.dev, allan.fit
    for j, c in enumerate(range(cols.start, cols.stop)):
        ax.loglog(d.tau_s, d.adev[:, c], "-", color=f"C{j}", label=f"{AXES[j]}")
        n, k = f.white.value[c], f.random_walk.value[c]
        if np.isfinite(n):
            ax.loglog(d.tau_s, n / np.sqrt(d.tau_s), ":", color=f"C{j}", lw=0.8)
        if np.isfinite(k) and f.random_walk.tau_lo[c] >= MIN_RANDOM_WALK_TAU_S:
            ax.loglog(d.tau_s, k * np.sqrt(d.tau_s / 3.0), "-.", color=f"C{j}", lw=0.8)
    ax.set_title(f"{name}, still stretches ({allan.seconds:.0f} s; dotted: N, dash-dot: K)", fontsize=9)
    ax.set_xlabel("tau [s]")
    ax.set_ylabel(f"Allan deviation [{unit}]")
    ax.legend(fontsize=6)
    ax.grid(True, which="both", alpha=0.3)


def plot_calibration(path: Path, device: str, before: Optional[ResidualNoise], after: Optional[ResidualNoise],
                     allan: Optional[AllanNoise]) -> bool:
    """Write the figure to ``path`` atomically; False (nothing written) without matplotlib."""
    matplotlib = optional("matplotlib")
    if matplotlib is None:
        return False
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(12, 9))
    _residual_panel(ax[0, 0], before, after, "gyro", "rad/s")
    _residual_panel(ax[0, 1], before, after, "acc", "m/s^2")
    _still_panel(ax[1, 0], allan, slice(0, 3), "gyroscope", "rad/s")
    _still_panel(ax[1, 1], allan, slice(3, 6), "accelerometer", "m/s^2")
    fig.suptitle(f"imu-learn calibrate: {device}")
    fig.tight_layout()
    try:
        atomic_write_path(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))
    finally:
        plt.close(fig)
    return True
