"""One PNG per recording and aiding setting: top view of every input's fused trajectory against
ground truth, and the position error over time (causal solid, smoothed dashed) with the outages
shaded. Drawn from the TUM files the experiment wrote, so resumed runs are plotted too."""
from __future__ import annotations

from pathlib import Path
from typing import List, Sequence, Tuple

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.util.atomic import atomic_write_bytes


def plot_setting(out_png: Path, title: str, t_ns: np.ndarray, p_gt: np.ndarray,
                 runs: Sequence[Tuple[str, Path, Path]], outages: Sequence[Tuple[float, float]] = ()) -> bool:
    """``runs``: (input name, causal TUM, smoothed TUM). False (nothing written) without matplotlib."""
    try:
        import matplotlib
    except ImportError:
        return False
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, err) = plt.subplots(1, 2, figsize=(13, 5))
    top.plot(p_gt[:, 0], p_gt[:, 1], "k-", lw=2, alpha=0.5, label="ground truth")
    t0 = t_ns[0]
    for i, (name, causal, smoothed) in enumerate(runs):
        color = f"C{i}"
        for path, style, kind in ((causal, "-", "causal"), (smoothed, "--", "smoothed")):
            if not path.exists():
                continue
            tr = core.read_tum(str(path))
            idx = np.clip(np.searchsorted(t_ns, tr["t_ns"]), 0, len(t_ns) - 1)
            e = np.linalg.norm(tr["p"] - p_gt[idx], axis=1)
            top.plot(tr["p"][:, 0], tr["p"][:, 1], style, color=color, lw=1, label=f"{name} {kind}")
            err.plot((tr["t_ns"] - t0) * 1e-9, e, style, color=color, lw=1, label=f"{name} {kind}")
    for start, dur in outages:
        err.axvspan(start, start + dur, color="grey", alpha=0.2, lw=0)
    top.set(xlabel="x [m]", ylabel="y [m]", title="top view")
    top.axis("equal")
    err.set(xlabel="time from start [s]", ylabel="position error [m]", yscale="log",
            title="position error" + (" (outages shaded)" if outages else ""))
    if err.lines:
        err.legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    atomic_write_bytes(out_png, lambda f: fig.savefig(f, format="png", dpi=90))
    plt.close(fig)
    return True


def runs_of(traj_dir: Path, stem: str, inputs: List[str]) -> List[Tuple[str, Path, Path]]:
    """``stem``: the runs' file stem with ``{input}`` where the input's name goes."""
    return [(i, traj_dir / f"{stem.format(input=i)}_causal.tum", traj_dir / f"{stem.format(input=i)}_smoothed.tum")
            for i in inputs]
