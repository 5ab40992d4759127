"""What fusion writes: trajectories as TUM files (:func:`write_trajectory`) and as bag topics
(:func:`write_trajectory_bag`), results files (:func:`write_json`, read back by :func:`read_runs`),
and the plots (an experiment setting's inputs against ground truth, :func:`plot_setting`; a
navigated recording against its aiding, :func:`plot_navigation`). Every file is written atomically.
Plots are drawn from the TUM files on disk, so resumed runs are plotted too; without matplotlib
they are left out (the functions return False)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn import _imu_core as core
from imu_learn.core.quat import xyzw_to_wxyz
from imu_learn.data.formats.rosbag import output_bag_path, write_odometry
from imu_learn.util.atomic import atomic_write_bytes, atomic_write_path, atomic_write_text
from imu_learn.util.extras import optional

from .aiding.tum import read_tum


def write_trajectory(path: Path, t_ns: np.ndarray, p: np.ndarray, R: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    q_wxyz = xyzw_to_wxyz(Rotation.from_matrix(R).as_quat())
    t_ns, p, q_wxyz = np.ascontiguousarray(t_ns, dtype=np.int64), np.ascontiguousarray(p), np.ascontiguousarray(q_wxyz)
    atomic_write_path(path, lambda tmp: core.write_tum(str(tmp), t_ns, p, q_wxyz))


def write_trajectory_bag(base: Path, t_ns: np.ndarray, p: np.ndarray, R: np.ndarray, like: Path,
                         topic: str = "/imu_learn/odometry") -> Path:
    """The trajectory as ``nav_msgs/msg/Odometry`` on ``topic`` (poses only) in a bag of the
    recording ``like``'s kind: ``base.bag`` for ROS 1, the folder ``base`` for ROS 2 (same storage
    plugin). Returns the bag written."""
    path = output_bag_path(base, like)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_odometry(path, topic, t_ns, p, xyzw_to_wxyz(Rotation.from_matrix(R).as_quat()), like=like)
    return path


def write_json(path: Path, results: Dict[str, object]) -> None:
    """``results`` as indented JSON in ``path`` (results.json, online.json), atomically; numpy scalars
    as floats."""
    atomic_write_text(Path(path), json.dumps(results, indent=1, default=float) + "\n")


def read_runs(path: Path, log: Callable[[str], None]) -> Dict[str, dict]:
    """The runs recorded in ``path`` (results.json or online.json); none when there is no file, and
    none, said through ``log``, when it cannot be read (its runs are done again and it is
    rewritten)."""
    if not path.exists():
        return {}
    try:
        runs = json.loads(path.read_text()).get("runs", {})
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError) as e:
        log(f"imu_learn.fuse: {path}: unreadable ({type(e).__name__}: {e}); its runs are done again")
        return {}
    return runs if isinstance(runs, dict) else {}


def plot_setting(out_png: Path, title: str, t_ns: np.ndarray, p_gt: np.ndarray,
                 runs: Sequence[Tuple[str, Path, Path]], outages: Sequence[Tuple[float, float]] = ()) -> bool:
    """``runs``: (input name, causal TUM, smoothed TUM). False (nothing written) without matplotlib."""
    matplotlib = optional("matplotlib")
    if matplotlib is None:
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
            tr = read_tum(path)
            idx = np.clip(np.searchsorted(t_ns, tr.t_ns), 0, len(t_ns) - 1)
            e = np.linalg.norm(tr.p - p_gt[idx], axis=1)
            top.plot(tr.p[:, 0], tr.p[:, 1], style, color=color, lw=1, label=f"{name} {kind}")
            err.plot((tr.t_ns - t0) * 1e-9, e, style, color=color, lw=1, label=f"{name} {kind}")
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


def plot_navigation(out_png: Path, title: str, kf_t: np.ndarray, res, rows, R_WA: np.ndarray,
         scores: Optional[dict], gaps: Sequence[Tuple[float, float]], t0_ns: int) -> bool:
    """Top view of the causal and smoothed trajectories and the aiding, and the causal estimate's
    distance from the smoothed one over time (gaps shaded). False (nothing written) without matplotlib."""
    matplotlib = optional("matplotlib")
    if matplotlib is None:
        return False
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, err) = plt.subplots(1, 2, figsize=(13, 5))
    pa = rows.p @ R_WA.T
    top.plot(pa[:, 0], pa[:, 1], ".", ms=1.5, color="grey", label="aiding (body)")
    top.plot(res.causal_p[:, 0], res.causal_p[:, 1], "-", lw=1, label="causal")
    top.plot(res.smoothed_p[:, 0], res.smoothed_p[:, 1], "--", lw=1, label="smoothed")
    top.set(xlabel="x [m]", ylabel="y [m]", title="top view (navigation frame, z up)")
    top.axis("equal")
    top.legend(fontsize=7)
    t = (kf_t - t0_ns) * 1e-9
    err.plot(t, np.linalg.norm(res.causal_p - res.smoothed_p, axis=1), lw=1, label="|causal - smoothed| [m]")
    for start, dur in gaps:
        err.axvspan(start, start + dur, color="grey", alpha=0.2, lw=0)
    sub = ""
    if scores:
        sub = (f"\n{'aligned' if scores['aligned'] else 'unaligned'} position RMSE against ground truth: causal "
               f"{scores['causal']['pos_rmse_m']:.3f} m, smoothed {scores['smoothed']['pos_rmse_m']:.3f} m")
    err.set(xlabel="time from the first IMU sample [s]", ylabel="[m]", yscale="log")
    err.set_title("causal estimate against the smoothed one" + sub, fontsize=9)
    err.legend(fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    atomic_write_bytes(out_png, lambda f: fig.savefig(f, format="png", dpi=90))
    plt.close(fig)
    return True
