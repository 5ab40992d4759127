"""The fusion experiment: every recording x IMU input x aiding scenario of a :class:`FuseConfig`,
fused by :func:`imu_learn.fuse.graph.fuse` and scored against ground truth.

Every input of a recording and scenario sees the same aiding (one seeded draw per recording and
scenario), so rows differ only in the IMU. Results go to ``<out>/results.json`` after each run
(atomically), so an interrupted experiment resumes where it stopped when its settings are
unchanged; ``table.md`` and the trajectories (TUM files, causal and smoothed, at keyframes) are
written beside it.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from pathlib import Path
from typing import Callable, Dict, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn import _imu_core as core
from imu_learn.cache import atomic_write_bytes
from imu_learn.quat import wxyz_to_xyzw, xyzw_to_wxyz

from .aiding import apply_outages, leica_fixes, simulate_position, simulate_relative_pose
from .config import FuseConfig, RecordingSpec, ScenarioSpec
from .graph import fuse
from .noise import ImuNoise
from .score import score


def settings_hash(cfg: FuseConfig) -> str:
    d = asdict(cfg)
    d.pop("out_dir", None)
    ck = Path(cfg.checkpoint)
    d["checkpoint_bytes"] = hashlib.sha256(ck.read_bytes()).hexdigest() if "proposed" in cfg.inputs and ck.is_file() else ""
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]


def load_recording_for_fusion(cfg: FuseConfig, spec: RecordingSpec):
    """The recording's longest gap-free segment, its noise model, and its Leica fixes (or None)."""
    from imu_learn import AlignOptions, load_recording
    from imu_learn.formats.asl import LEICA_FILE, read_leica

    root = cfg.root()
    path = root / spec.path
    gt = root / spec.groundtruth if spec.groundtruth else None
    rec = load_recording(path, spec.format, groundtruth=gt, options=AlignOptions(max_gap_s=spec.max_gap_s))
    seq = max(rec.segments, key=len)
    yaml = path / "mav0" / "imu0" / "sensor.yaml"
    n = cfg.noise
    if n.source == "sensor.yaml" and yaml.exists():
        noise = ImuNoise.from_sensor_yaml(yaml)
    else:
        noise = ImuNoise(n.gyro_noise_density, n.acc_noise_density, n.gyro_random_walk, n.acc_random_walk,
                         source="config [noise]")
    leica = read_leica(path) if (path / LEICA_FILE).exists() else None
    return seq, noise, leica


def imu_input(name: str, seq, model) -> Tuple[np.ndarray, np.ndarray]:
    if name == "raw":
        return seq.gyro, seq.acc
    from imu_learn.refine import refine_arrays

    return refine_arrays(model, seq.gyro, seq.acc)


def make_aiding(scn: ScenarioSpec, seq, leica, rng: np.random.Generator):
    if scn.kind == "position":
        a = simulate_position(seq.t_ns, seq.p, scn.rate_hz, scn.sigma_m, rng)
    elif scn.kind == "relative_pose":
        a = simulate_relative_pose(seq.t_ns, seq.p, seq.q_wxyz, scn.rate_hz, scn.sigma_rot_deg, scn.sigma_trans_m, rng)
    else:
        if leica is None:
            return None
        t, p, lever = leica
        t = t + int(round(scn.time_offset_s * 1e9))
        a = leica_fixes(t, p, lever, seq.t_ns, scn.rate_hz or None, scn.sigma_m)
    return apply_outages(a, seq.t_ns, [tuple(o) for o in scn.outages])


def write_trajectory(path: Path, t_ns: np.ndarray, p: np.ndarray, R: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    q_wxyz = xyzw_to_wxyz(Rotation.from_matrix(R).as_quat())
    core.write_tum(str(path), np.ascontiguousarray(t_ns, dtype=np.int64), np.ascontiguousarray(p),
                   np.ascontiguousarray(q_wxyz))


def run_experiment(cfg: FuseConfig, out: Path, log: Callable[[str], None] = print) -> Dict[str, dict]:
    out.mkdir(parents=True, exist_ok=True)
    res_path = out / "results.json"
    settings = settings_hash(cfg)
    results: Dict[str, dict] = {}
    if res_path.exists():
        old = json.loads(res_path.read_text())
        if old.get("settings") == settings:
            results = old.get("runs", {})
            if results:
                log(f"imu_learn.fuse: resuming: {len(results)} runs already in {res_path}")
    model = None
    if "proposed" in cfg.inputs:
        from imu_learn.checkpoint import load_model

        model = load_model(Path(cfg.checkpoint))
    total = len(cfg.recordings) * len(cfg.scenarios) * len(cfg.inputs)
    done = 0
    for ri, spec in enumerate(cfg.recordings):
        seq, noise, leica = load_recording_for_fusion(cfg, spec)
        rname = Path(spec.path).name
        inputs = {name: imu_input(name, seq, model) for name in cfg.inputs}
        R0 = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix()
        for si, scn in enumerate(cfg.scenarios):
            rng = np.random.default_rng([cfg.seed, ri, si])
            aiding = make_aiding(scn, seq, leica, rng)
            for name, (gyro, acc) in inputs.items():
                done += 1
                key = f"{rname}|{scn.name}|{name}"
                if aiding is None or key in results:
                    continue
                res = fuse(seq.t_ns, gyro, acc, (R0, seq.p[0], seq.v[0]), [aiding], noise, cfg.gravity,
                           cfg.keyframe_hz)
                s = score(res, seq.t_ns, seq.p, seq.q_wxyz, [tuple(o) for o in scn.outages])
                results[key] = {"recording": rname, "scenario": scn.name, "input": name, "aiding": aiding.label,
                                "aiding_count": len(aiding), "duration_s": seq.duration_s,
                                "noise": noise.source, "seconds": round(res.seconds, 2), **s}
                stem = key.replace("|", "_")
                write_trajectory(out / "trajectories" / f"{stem}_causal.tum", seq.t_ns[res.kf_idx], res.causal_p,
                                 res.causal_R)
                write_trajectory(out / "trajectories" / f"{stem}_smoothed.tum", seq.t_ns[res.kf_idx],
                                 res.smoothed_p, res.smoothed_R)
                blob = json.dumps({"settings": settings, "config": asdict(cfg), "runs": results}, indent=1).encode()
                atomic_write_bytes(res_path, lambda f, b=blob: f.write(b))
                log(f"[{done}/{total}] {key}: position RMSE causal {s['causal']['pos_rmse_m']:.3f} m, "
                    f"smoothed {s['smoothed']['pos_rmse_m']:.3f} m ({res.seconds:.0f} s)")
    table = format_table(cfg, results)
    atomic_write_bytes(out / "table.md", lambda f: f.write(table.encode()))
    return results


def format_table(cfg: FuseConfig, results: Dict[str, dict]) -> str:
    lines = [f"# {cfg.name}: position RMSE [m] (rotation RMSE [deg]) at keyframes, causal / smoothed", ""]
    for scn in cfg.scenarios:
        rows = [r for r in results.values() if r["scenario"] == scn.name]
        if not rows:
            continue
        lines += [f"## {scn.name}: {rows[0]['aiding']}" + (f", outages {scn.outages}" if scn.outages else ""), ""]
        head = "| recording | " + " | ".join(f"{i} causal | {i} smoothed" for i in cfg.inputs) + " |"
        lines += [head, "|" + "---|" * (1 + 2 * len(cfg.inputs))]
        for rec in dict.fromkeys(r["recording"] for r in rows):
            cells = []
            for i in cfg.inputs:
                r = results.get(f"{rec}|{scn.name}|{i}")
                for k in ("causal", "smoothed"):
                    cells.append("–" if r is None else f"{r[k]['pos_rmse_m']:.3f} ({r[k]['rot_rmse_deg']:.2f})")
            lines.append(f"| {rec} | " + " | ".join(cells) + " |")
        if scn.outages:
            lines += ["", "Drift inside each outage (causal: RMSE / max position error [m]):", ""]
            for rec in dict.fromkeys(r["recording"] for r in rows):
                for i in cfg.inputs:
                    r = results.get(f"{rec}|{scn.name}|{i}")
                    if r is not None:
                        o = "; ".join(f"{x['start_s']:g}+{x['duration_s']:g} s: {x['rmse_m']:.3f} / {x['max_m']:.3f}"
                                      for x in r["causal"]["outages"])
                        lines.append(f"- {rec}, {i}: {o}")
        lines.append("")
    return "\n".join(lines)
