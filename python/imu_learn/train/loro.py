"""Leave-one-recording-out validation of the one recipe: a refiner trained on top of the device
profile's floor (``imu-learn fit --config C --loro OUT``).

For each recording R of the device (the config's training and validation recordings, or those
named): the fold's profile is the floor (``traditional+timing``, low-pass included: what
``imu-learn calibrate`` fits, without its per-recording uncertainty refits) fitted on the other
recordings, their first part fitting and their last part selecting (the config's own cut of each
recording, else 85 / 15 %); the refiner is trained on top of that profile on the same parts exactly
as ``imu-learn calibrate --learned`` trains it (:mod:`imu_learn.train.on_profile`: residual on the
floor, so the untrained model is the floor; selected on the other recordings' validation parts
against the floor, epoch 0 kept when no epoch beats it), once per seed; then both are scored on R,
which neither saw: relative pose RMSE at ``data.eval_horizons``, rotation and translation, open loop
and with R's start-up bias removed (:func:`imu_learn.train.on_profile.versus_floor`), and the open-loop
AOE (:func:`aoe_cell`: the gyro integrated over each whole gap-free stretch of R from its ground-truth
attitude, RMSE of the angle error over all its samples, :mod:`imu_learn.score.peers`). What the recipe
gives on R is the model where the fold's validation shipped it (at least 1 % better than the floor in
every validation cell), else the profile alone (ratio 1): :func:`recipe_cells`; the model's own
held-out cells are kept beside (``model_cells``), shipped or not.

The verdict (:func:`verdict`): a learned model ships for the device only when, on every held-out
recording and in every cell (the open-loop AOE included), the mean over seeds of model / floor is below
:data:`imu_learn.train.on_profile.BEAT` and no seed is above 1. Otherwise the profile alone ships. A
held-out recording without its AOE cell (a run scored before the AOE was a cell) leaves the verdict
incomplete, which never ships.

Files under OUT, each written atomically: ``<R>/profile.json`` (the fold's floor),
``<R>/seed<S>/`` (``fit/`` the run, ``learned.json`` the validation verdict, ``heldout.json`` the
held-out cells), ``loro.json`` (every cell, the summary and the verdict) and ``loro.md`` (the table a
model card quotes). A rerun skips every fold whose ``heldout.json`` exists; a fold interrupted
before that restarts from scratch. A ``heldout.json`` written before the AOE was a cell is completed
on the rerun: the AOE scored from the fold's own ``fit/best.pt`` and ``profile.json`` (no retraining);
where the run's files are gone it stays without, and the verdict says incomplete.
:func:`read_loro` reads any ``loro.json``, an older one included, and judges it by the rules here.
"""
from __future__ import annotations

import json
import shutil
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable, Dict, List, Sequence, Tuple

import numpy as np

from imu_learn.baselines.base import FitSettings
from imu_learn.calib.profile import Profile
from imu_learn.calib.run import CalibInputs, floor_profile
from imu_learn.data.splits import make_split, parse_entry, recording_name
from imu_learn.data.types import Segment
from imu_learn.errors import ConfigError
from imu_learn.infer.checkpoint import load_model
from imu_learn.score import peers
from imu_learn.train import on_profile, trainer
from imu_learn.train.config import RunConfig, build_config
from imu_learn.util.atomic import atomic_write_text

Progress = Callable[[str], None]
DEFAULT_VAL_FRACTION = 0.15
# The cells' terms: (ratio key prefix, figure key); a cell holds the terms it scores (the relative
# pose cells rotation and translation, the AOE cell its angle).
TERMS = (("rot", "rot_deg"), ("trans", "trans_m"), ("aoe", "aoe_deg"))
AOE_N, AOE_PROTOCOL = "whole", "open-loop AOE"


@dataclass(frozen=True)
class LoroSettings:
    seeds: Tuple[int, ...] = (0, 1, 2)
    recordings: Tuple[str, ...] = ()  # default: the config's training and validation recordings
    jobs: int = 1  # folds trained at once (processes; each with the config's threads)


@dataclass
class Fold:
    """Recording ``held_out`` scored; the others' first parts ``train``, their last parts ``val``."""

    held_out: str
    train: List[Segment]
    val: List[Segment]
    test: List[Segment]

    @property
    def trained_on(self) -> List[str]:
        return sorted({recording_name(s.name) for s in self.train})


def recording_cuts(cfg: RunConfig, names: Sequence[str]) -> Dict[str, float]:
    """Where each recording's training part ends: the config's own cut (the stop of its training
    entry), else 1 - :data:`DEFAULT_VAL_FRACTION`."""
    cuts = {}
    for text in cfg.data.split.train:
        e = parse_entry(text)
        if e.start == 0.0 and e.stop < 1.0:
            cuts[e.name] = e.stop
    return {n: cuts.get(n, 1.0 - DEFAULT_VAL_FRACTION) for n in names}


def loro_recordings(cfg: RunConfig, named: Sequence[str]) -> List[str]:
    if named:
        return list(dict.fromkeys(named))
    out = [parse_entry(t).name for t in list(cfg.data.split.train) + list(cfg.data.split.val)]
    return list(dict.fromkeys(out))


def load_folds(cfg: RunConfig, names: Sequence[str]) -> List[Fold]:
    """Every recording read once (its two parts) and the folds made of them."""
    if len(names) < 2:
        raise ConfigError(f"--loro: needs at least two recordings, got {list(names)} (name them with --recordings)")
    cuts = recording_cuts(cfg, names)
    split = {"train": [f"{n}[0:{cuts[n]:g}]" for n in names], "val": [f"{n}[{cuts[n]:g}:1]" for n in names], "test": []}
    data_cfg = build_config(cfg.to_dict(), {f"data.split.{k}": v for k, v in split.items()}).data
    loaded = make_split(data_cfg)
    folds = []
    for n in names:
        tr = [s for s in loaded.train if recording_name(s.name) != n]
        va = [s for s in loaded.val if recording_name(s.name) != n]
        te = [s for s in loaded.train + loaded.val if recording_name(s.name) == n]
        if not te:
            raise ConfigError(f"--loro: recording {n} has no segment long enough to score")
        folds.append(Fold(n, tr, va, te))
    return folds


def fold_profile(fold: Fold, cfg: RunConfig, path: Path, device: str) -> Path:
    """The fold's floor as a device profile at ``path`` (kept when it exists)."""
    if path.exists():
        return path
    settings = FitSettings(window=cfg.data.window, seed=cfg.seed, gravity=cfg.data.gravity, threads=cfg.threads)
    inp = CalibInputs(fold.train, fold.val, [recording_name(s.name) for s in fold.train],
                      [recording_name(s.name) for s in fold.val], [], settings, device,
                      [{"recordings": fold.trained_on, "held_out": fold.held_out}])
    prof, _, _ = floor_profile(inp, lambda s: None, uncertainty=False)
    prof.sources = inp.sources
    path.parent.mkdir(parents=True, exist_ok=True)
    prof.save(path)
    return path


def fold_config(base: RunConfig, profile: Path, seed: int) -> RunConfig:
    """The recipe: ``base``'s data, model, loss and optimiser settings on top of ``profile``
    (:func:`on_profile.config_on_profile`), with the raw samples (the floor holds the device bias)."""
    cfg = on_profile.config_on_profile(base, profile, base.optim.epochs, seed)
    return build_config(cfg.to_dict(), {"data.train_bias": "keep"})


def run_fold(base: RunConfig, fold: Fold, seed: int, out: Path, device: str) -> Dict[str, Any]:
    """One (fold, seed): the profile, the run, its held-out cells (``heldout.json``)."""
    seed_dir = out / fold.held_out / f"seed{seed}"
    done = seed_dir / "heldout.json"
    if done.exists():
        return complete_aoe(json.loads(done.read_text()), base, fold, seed_dir, out / fold.held_out / "profile.json")
    t0 = time.time()
    profile_path = fold_profile(fold, base, out / fold.held_out / "profile.json", device)
    cfg = fold_config(base, profile_path, seed)
    if seed_dir.exists():
        shutil.rmtree(seed_dir)  # an interrupted fold restarts
    res = on_profile.train_on_profile(cfg, fold.train, fold.val, seed_dir, bar=False)
    scored = replace(cfg, optim=replace(cfg.optim, select_horizons=list(cfg.data.eval_horizons)))
    profile = Profile.load(profile_path)
    model = load_model(res.run_dir / "best.pt")
    model_cells = on_profile.versus_floor(model, profile, fold.test, scored)
    model_cells.append(aoe_cell(model, profile, fold.test, scored))
    row = {"held_out": fold.held_out, "seed": seed, "trained_on": fold.trained_on,
           "best_epoch": res.best_epoch, "beats_floor_on_validation": res.beats_floor,
           "cells": recipe_cells(model_cells, res.beats_floor), "model_cells": model_cells,
           "seconds": round(time.time() - t0, 1)}
    atomic_write_text(done, json.dumps(row, indent=2) + "\n")
    return row


def has_aoe(cells: Sequence[Dict[str, Any]]) -> bool:
    return any(c.get("protocol") == AOE_PROTOCOL for c in cells)


def complete_aoe(row: Dict[str, Any], base: RunConfig, fold: Fold, seed_dir: Path, profile_path: Path) -> Dict[str, Any]:
    """A ``heldout.json`` scored before the AOE was a cell, completed from the fold's own run
    (``fit/best.pt``) and profile, no retraining; unchanged where those files are gone (the verdict
    then says incomplete)."""
    if has_aoe(row.get("model_cells", row["cells"])):
        return row
    best = seed_dir / "fit" / "best.pt"
    if not (best.exists() and profile_path.exists()):
        return row
    t0 = time.time()
    cfg = fold_config(base, profile_path, row["seed"])
    cell = aoe_cell(load_model(best), Profile.load(profile_path), fold.test, cfg)
    model_cells = list(row.get("model_cells", row["cells"])) + [cell]
    row = {**row, "cells": recipe_cells(model_cells, bool(row["beats_floor_on_validation"])), "model_cells": model_cells,
           "aoe_scored_later_s": round(time.time() - t0, 1)}
    atomic_write_text(seed_dir / "heldout.json", json.dumps(row, indent=2) + "\n")
    return row


def whole_stretches(segs: Sequence[Segment]) -> List[Segment]:
    """``segs`` with the parts of one gap-free stretch joined again (a recording cut at the config's
    fraction into two adjacent parts is one stretch: the next part starts within 1.5 sample periods of
    the previous one's end)."""
    out: List[Segment] = []
    for s in sorted(segs, key=lambda x: (recording_name(x.name), int(x.t_ns[0]))):
        if out and recording_name(out[-1].name) == recording_name(s.name) and len(out[-1]) > 1:
            prev = out[-1]
            period = float(np.median(np.diff(prev.t_ns)))
            gap = int(s.t_ns[0]) - int(prev.t_ns[-1])
            if 0 < gap <= 1.5 * period:
                out[-1] = Segment(prev.name, *(np.concatenate([getattr(prev, k), getattr(s, k)])
                                               for k in ("t_ns", "gyro", "acc", "p", "v", "q_wxyz")))
                continue
        out.append(s)
    return out


def aoe_cell(model: Any, profile: Profile, test: Sequence[Segment], cfg: RunConfig) -> Dict[str, Any]:
    """The open-loop AOE of the model and of the floor on the held-out recording (``test``): the
    gyro integrated over each whole gap-free stretch (:func:`whole_stretches`) from the ground-truth
    attitude at its first sample, the RMSE of the angle error over all samples of all stretches
    (:func:`imu_learn.score.peers.attitude_errors`; Brossard's AOE, as ``imu-learn evaluate`` reports it)."""
    floor_e, model_e = peers.PeerErrors(rot_rad=None, trans_m=None), peers.PeerErrors(rot_rad=None, trans_m=None)
    stretches = whole_stretches(test)
    for s in stretches:
        g_floor, _ = profile.apply(s.t_ns, s.gyro, s.acc)
        g_model = trainer.refine_sequence(model, s, cfg).gyro
        for acc, g in ((floor_e, g_floor), (model_e, g_model)):
            e = peers.attitude_errors(s, np.asarray(g, dtype=np.float64))
            peers.add_segment(acc, {"angle_rad": e["angle_rad"], "yaw_rad": e["yaw_rad"], "rot_rad": None,
                                    "trans_m": None, "window": 0})
    f, m = peers.summarise(floor_e), peers.summarise(model_e)
    return {"n": AOE_N, "protocol": AOE_PROTOCOL, "stretches": len(stretches), "samples": f["samples"],
            "floor": {"aoe_deg": f["aoe_deg"], "yaw_aoe_deg": f["yaw_aoe_deg"]},
            "model": {"aoe_deg": m["aoe_deg"], "yaw_aoe_deg": m["yaw_aoe_deg"]},
            "aoe_ratio": m["aoe_deg"] / max(f["aoe_deg"], 1e-15)}


def cell_terms(c: Dict[str, Any]) -> List[Tuple[str, str]]:
    """The (term, figure key) pairs ``c`` scores (:data:`TERMS`)."""
    return [(t, k) for t, k in TERMS if f"{t}_ratio" in c or f"{t}_ratio_mean" in c]


def recipe_cells(model_cells: List[Dict[str, Any]], shipped: bool) -> List[Dict[str, Any]]:
    """What the recipe gives on the held-out recording: the model where the fold's validation
    shipped it (``calibrate --learned``'s rule), else the profile, whose ratio to itself is 1."""
    if shipped:
        return model_cells
    return [{**c, "model": dict(c["floor"]), **{f"{t}_ratio": 1.0 for t, _ in cell_terms(c)}, "profile_alone": True}
            for c in model_cells]


def _run_fold_job(args: Tuple[Dict[str, Any], Fold, int, str, str]) -> Dict[str, Any]:
    cfg_dict, fold, seed, out, device = args
    return run_fold(build_config(cfg_dict, {}), fold, seed, Path(out), device)


def summarise(rows: Sequence[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """Per held-out recording and cell: the floor, what the recipe gives over seeds (ratios' mean
    and worst) and the model's own ratios, shipped or not (their mean). Each cell has the terms it
    scores (:data:`TERMS`: rotation and translation, or the AOE)."""
    by: Dict[Tuple[str, Any, str], List[Tuple[Dict[str, Any], Dict[str, Any]]]] = {}
    for r in rows:
        for c, m in zip(r["cells"], r.get("model_cells", r["cells"])):
            by.setdefault((r["held_out"], c["n"], c["protocol"]), []).append((c, m))
    out = []
    for (rec, n, protocol), cs in by.items():
        cell: Dict[str, Any] = {"held_out": rec, "n": n, "protocol": protocol, "seeds": len(cs),
                                "floor": cs[0][0]["floor"]}
        for term, key in cell_terms(cs[0][0]):
            ratios = [c[f"{term}_ratio"] for c, _ in cs]
            cell[f"{term}_ratio_mean"] = sum(ratios) / len(ratios)
            cell[f"{term}_ratio_worst"] = max(ratios)
            cell[f"model_{key}_mean"] = sum(c["model"][key] for c, _ in cs) / len(cs)
            cell[f"{term}_model_alone_mean"] = sum(m[f"{term}_ratio"] for _, m in cs) / len(cs)
        out.append(cell)
    return out


def losing_terms(c: Dict[str, Any]) -> List[str]:
    """The terms of summary cell ``c`` in which the recipe does not beat the floor."""
    return [t for t, _ in cell_terms(c)
            if c[f"{t}_ratio_worst"] > 1.0 or c[f"{t}_ratio_mean"] >= on_profile.BEAT]


def verdict(cells: Sequence[Dict[str, Any]]) -> Dict[str, Any]:
    """Ships only when every cell's seed mean is below BEAT and no seed is above 1, the open-loop AOE
    included; a held-out recording without its AOE cell makes the verdict incomplete (module doc)."""
    losing = [c for c in cells if losing_terms(c)]
    beaten = sorted({c["held_out"] for c in losing})
    recordings = list(dict.fromkeys(c["held_out"] for c in cells))
    no_aoe = [r for r in recordings if not any(c["held_out"] == r and c["protocol"] == AOE_PROTOCOL for c in cells)]
    v: Dict[str, Any] = {
        "ships": not losing and bool(cells) and not no_aoe, "recordings_not_beaten": beaten,
        "cells_lost": [f"{c['held_out']} n={c['n']} {c['protocol']}: {', '.join(losing_terms(c))}" for c in losing],
        "rule": f"ships when, on every held-out recording and in every cell (rotation and translation, each horizon, "
                f"open loop and start-up bias removed, and the open-loop AOE), the seeds' mean model/floor is below "
                f"{on_profile.BEAT} and no seed is above 1"}
    if no_aoe:
        v["incomplete"] = (f"no open-loop AOE cell for {', '.join(no_aoe)} (scored before the AOE was a cell: rerun "
                           "the same fit --loro to score it from the saved runs)")
    return v


def read_loro(path: Path) -> Dict[str, Any]:
    """``loro.json`` (any version) with its cells and verdict recomputed from its runs by the rules
    here: a file written before the AOE was a cell reads as incomplete (no model ships on it)."""
    res = json.loads(Path(path).read_text())
    cells = summarise(res.get("runs", []))
    v = verdict(cells)
    done, total = len(res.get("runs", [])), res.get("runs_total", len(res.get("runs", [])))
    if done != total:
        v = {**v, "ships": False, "incomplete": "; ".join(x for x in (f"{done} of {total} runs", v.get("incomplete")) if x)}
    return {**res, "cells": cells, "verdict": v}


def _r(c: Dict[str, Any], term: str) -> str:
    return f"{c[f'{term}_ratio_mean']:.3f} ({c[f'{term}_ratio_worst']:.3f})"


def _row(c: Dict[str, Any]) -> str:
    if c["protocol"] == AOE_PROTOCOL:  # an angle: in the rotation columns
        return (f"| {c['held_out']} | {c['n']} | {c['protocol']} | {c['floor']['aoe_deg']:.4g} | {_r(c, 'aoe')} | "
                f"{c['aoe_model_alone_mean']:.3f} | - | - | - |")
    return (f"| {c['held_out']} | {c['n']} | {c['protocol']} | {c['floor']['rot_deg']:.4g} | {_r(c, 'rot')} | "
            f"{c['rot_model_alone_mean']:.3f} | {c['floor']['trans_m']:.4g} | {_r(c, 'trans')} | "
            f"{c['trans_model_alone_mean']:.3f} |")


def markdown(cells: Sequence[Dict[str, Any]], v: Dict[str, Any], seeds: Sequence[int]) -> str:
    lines = [f"Leave-one-recording-out, seeds {', '.join(map(str, seeds))}: on each held-out recording, what the recipe "
             "gives (the model where its fold's validation shipped it, else the profile) over the floor: mean over seeds, "
             "worst seed in brackets; below 1 is better than the floor. \"alone\": the trained model's own ratio, "
             "shipped or not (mean over seeds). n = whole, open-loop AOE: the gyro integrated over each whole gap-free "
             "stretch of the recording from its ground-truth attitude, RMSE of the angle error [deg] (rotation columns).",
             "",
             "| held out | n | protocol | floor rot [deg] | rot: recipe | rot: alone | floor trans [m] | trans: recipe | trans: alone |",
             "|---|---|---|---|---|---|---|---|---|"]
    order = {p: i for i, p in enumerate(on_profile.PROTOCOLS + (AOE_PROTOCOL,))}
    recs = list(dict.fromkeys(c["held_out"] for c in cells))
    for c in sorted(cells, key=lambda c: (recs.index(c["held_out"]), c["protocol"] == AOE_PROTOCOL,
                                          c["n"] if isinstance(c["n"], int) else 0, order.get(c["protocol"], 9))):
        lines.append(_row(c))
    if v.get("incomplete"):
        said = f"Verdict: incomplete ({v['incomplete']}): no model ships on a partial validation; the profile alone ships."
    elif v["ships"]:
        said = "Verdict: the learned model beats the floor on every held-out recording, in every cell: it ships."
    else:
        said = ("Verdict: the learned model does not beat the floor on every held-out recording (not on "
                f"{', '.join(v['recordings_not_beaten'])}; cells lost: {'; '.join(v.get('cells_lost', []))}): "
                "the profile alone ships.")
    lines += ["", said, ""]
    return "\n".join(lines)


def run_loro(base: RunConfig, out: Path, settings: LoroSettings, device: str,
             progress: Progress = lambda s: None) -> Dict[str, Any]:
    """Every (fold, seed) of ``base`` (module doc); returns what ``loro.json`` holds."""
    t0 = time.time()
    names = loro_recordings(base, settings.recordings)
    folds = load_folds(base, names)
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(f, s) for f in folds for s in settings.seeds]
    progress(f"leave-one-recording-out: {len(folds)} recordings x {len(settings.seeds)} seeds = {len(jobs)} runs "
             f"of {base.optim.epochs} x {base.optim.steps_per_epoch} steps, {settings.jobs} at once ({out})")
    rows: List[Dict[str, Any]] = []
    head = {"config": base.name, "device": device, "recordings": names, "seeds": list(settings.seeds),
            "epochs": base.optim.epochs, "steps_per_epoch": base.optim.steps_per_epoch, "runs_total": len(jobs)}

    def done(row: Dict[str, Any]) -> None:
        rows.append(row)
        rows.sort(key=lambda r: (names.index(r["held_out"]), r["seed"]))
        worst = max(c[f"{t}_ratio"] for c in row["cells"] for t, _ in cell_terms(c))
        progress(f"[{len(rows)}/{len(jobs)}] held out {row['held_out']}, seed {row['seed']}: best epoch "
                 f"{row['best_epoch']}, worst model/floor {worst:.3f} ({row['seconds']:.0f} s)")
        write_summary(out, head, rows, time.time() - t0)

    if settings.jobs <= 1:
        for f, s in jobs:
            done(run_fold(base, f, s, out, device))
    else:
        # profiles first (one per fold), so that the seeds of a fold never fit it twice at once
        args = [(base.to_dict(), f, s, str(out), device) for f, s in jobs]
        with ProcessPoolExecutor(settings.jobs, mp_context=get_context("spawn")) as pool:
            list(pool.map(_profile_job, [(base.to_dict(), f, str(out), device) for f in folds]))
            for fut in as_completed([pool.submit(_run_fold_job, a) for a in args]):
                done(fut.result())
    return write_summary(out, head, rows, time.time() - t0)


def write_summary(out: Path, head: Dict[str, Any], rows: List[Dict[str, Any]], seconds: float) -> Dict[str, Any]:
    """``loro.json`` and ``loro.md`` from the runs so far (rewritten after each run; a verdict on
    fewer runs than planned says so and never ships)."""
    cells = summarise(rows)
    v = verdict(cells)
    complete = len(rows) == head["runs_total"]
    if not complete:
        v = {**v, "ships": False,
             "incomplete": "; ".join(x for x in (f"{len(rows)} of {head['runs_total']} runs", v.get("incomplete")) if x)}
    result = {**head, "runs_done": len(rows), "verdict": v, "cells": cells, "runs": rows, "seconds": round(seconds, 1)}
    atomic_write_text(out / "loro.json", json.dumps(result, indent=2) + "\n")
    atomic_write_text(out / "loro.md", markdown(cells, v, head["seeds"]))
    return result


def _profile_job(args: Tuple[Dict[str, Any], Fold, str, str]) -> str:
    cfg_dict, fold, out, device = args
    return str(fold_profile(fold, build_config(cfg_dict, {}), Path(out) / fold.held_out / "profile.json", device))
