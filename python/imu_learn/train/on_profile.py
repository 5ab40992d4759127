"""A refiner trained on top of a device profile (``imu-learn calibrate --learned``): the run, and
whether it beat the profile's floor on validation.

The run is ``imu-learn fit`` with ``model.start`` = the profile's file (:func:`trainer.profile_start`:
the floor is the model's fixed calibration and FIR shift, the learned part starts at zero, so the
untrained model is the floor), on the segments calibrate fitted the profile on (its train and
validation split), selected on the validation pose error against that start
(``optim.select = "val_pose"``, ``validate_start``, ``select_reference = "start"``: epoch 0, the
floor itself, is kept when no epoch beats it). The run folder (config.toml, split.json, metrics.csv,
best.pt, last.pt) is ``OUT/fit``.

The verdict (:func:`versus_floor`) compares the selected model with the profile's own floor
(:meth:`Profile.apply`, low-pass included) on the validation segments: relative pose RMSE over the
selection horizons (default one training window), rotation and translation, open loop and with each
segment's start-up bias removed. The model *beats the floor* only when an epoch beat the start in
the selection (epoch 0, the floor itself, is not a model) and it is at least 1 % below the floor in
every one of those cells (:data:`BEAT`). Then it is written as ``OUT/model.pt`` (a stripped
checkpoint carrying the profile); otherwise as ``OUT/model.not_shipped.pt`` and the profile stays the
result. The figures go to ``OUT/learned.json``.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Sequence

from imu_learn.calib.correction import NOT_SHIPPED_SUFFIX
from imu_learn.calib.profile import Profile
from imu_learn.data.splits import Split, write_split
from imu_learn.data.types import Segment
from imu_learn.errors import ConfigError
from imu_learn.infer.checkpoint import load_checkpoint, load_model, strip_checkpoint
from imu_learn.score.metrics import index_at, relative_pose_rmse_many
from imu_learn.train import trainer
from imu_learn.train.config import RunConfig, build_config, to_toml
from imu_learn.util.atomic import atomic_write_text

Progress = Callable[[str], None]
SHIPPED, NOT_SHIPPED = "model.pt", "model" + NOT_SHIPPED_SUFFIX  # refine --checkpoint warns on the second
PROTOCOLS = ("open loop", "start-up bias removed")
# Below the floor means below this ratio in every cell: the untrained model (epoch 0, the floor in
# float32 with its low-pass as a FIR) scores within 2e-4 of 1, which is no gain.
BEAT = 0.99


@dataclass
class LearnedResult:
    beats_floor: bool
    model_file: Path
    run_dir: Path
    best_epoch: Any
    cells: List[Dict[str, Any]] = field(default_factory=list)  # one per (horizon, protocol)
    validation: List[str] = field(default_factory=list)  # the validation segments' names
    seconds: float = 0.0

    def line(self) -> str:
        """The one line calibrate prints."""
        figs = "; ".join(f"n={c['n']} {c['protocol']}: rot {c['rot_ratio']:.3f}, trans {c['trans_ratio']:.3f}"
                         for c in self.cells)
        where = f"{len(self.validation)} validation segment{'s' * (len(self.validation) != 1)}"
        if self.beats_floor:
            return f"learned refiner: beats the profile's floor on {where} (model/floor {figs}): {self.model_file}"
        return (f"learned refiner: does NOT beat the profile's floor on {where} (model/floor {figs}; best epoch "
                f"{self.best_epoch}): the profile stays the result; the model is kept as {self.model_file}, not shipped")

    def to_dict(self) -> Dict[str, Any]:
        return {"beats_floor": self.beats_floor, "model": str(self.model_file), "run": str(self.run_dir),
                "best_epoch": self.best_epoch, "validation": self.validation, "cells": self.cells,
                "rule": f"beats the floor: a trained epoch selected, and model/floor below {BEAT} in every cell "
                        "(rotation and translation, open loop and start-up bias removed, each horizon) on the "
                        "validation segments",
                "seconds": round(self.seconds, 1)}


def config_on_profile(base: RunConfig, profile: Path, epochs: int, seed: int) -> RunConfig:
    """``base`` (a fit config, or the defaults) set to train on top of ``profile`` for ``epochs``
    epochs from ``seed``, selected against its floor on validation (module doc)."""
    over = {"model.start": str(profile), "optim.epochs": epochs, "seed": seed, "optim.select": "val_pose",
            "optim.validate_start": True, "optim.select_reference": "start"}
    return build_config(base.to_dict(), over)


def split_record(train: Sequence[Segment], val: Sequence[Segment]) -> Dict[str, object]:
    """split.json of segments handed over directly (no recording is read by the run)."""
    def rows(segs: Sequence[Segment]) -> List[Dict[str, Any]]:
        return [{"entry": s.name, "recording": s.name, "segments": [
            {"name": s.name, "samples": len(s), "t0_ns": int(s.t_ns[0]), "t1_ns": int(s.t_ns[-1]),
             "duration_s": round(s.duration_s, 3), "used": True}]} for s in segs]
    return {"rule": "the segments imu-learn calibrate fitted the profile on", "data_root": None, "cache": None,
            "train": rows(train), "val": rows(val), "test": []}


def usable(segs: Sequence[Segment], cfg: RunConfig) -> List[Segment]:
    return [s for s in segs if len(s) > cfg.data.window]


def train_on_profile(cfg: RunConfig, train: Sequence[Segment], val: Sequence[Segment], out_dir: Path,
                     progress: Progress = lambda s: None, bar: bool = True) -> LearnedResult:
    """Train ``cfg`` (:func:`config_on_profile`) on ``train`` (``val`` selects), judge it against the
    profile's floor, write the model file and ``learned.json`` into ``out_dir`` (module doc)."""
    t0 = time.time()
    tr, va = usable(train, cfg), usable(val, cfg)
    if not tr or not va:
        raise ConfigError(f"--learned: needs training and validation segments longer than one window "
                          f"({cfg.data.window} samples); got {len(tr)} and {len(va)} (--val-fraction > 0, or a "
                          "config with a val split)")
    run_dir = Path(out_dir) / "fit"
    if (run_dir / "last.pt").exists():
        raise ConfigError(f"{run_dir}: already holds a run; choose another --out or remove it")
    run_dir.mkdir(parents=True, exist_ok=True)
    split = Split(tr, va, [], split_record(tr, va))
    atomic_write_text(run_dir / "config.toml", to_toml(cfg))
    write_split(split, run_dir / "split.json")
    progress(f"training the refiner on top of the profile: {cfg.optim.epochs} epochs of {cfg.optim.steps_per_epoch} "
             f"steps, {len(tr)} training and {len(va)} validation segments ({run_dir})")
    trainer.train(cfg, run_dir, split=split, progress=bar)
    state_best = load_checkpoint(run_dir / "best.pt")
    best_epoch = (state_best.get("extra") or {}).get("best_epoch")
    profile = Profile.from_dict(state_best["profile"], f"{run_dir / 'best.pt'} (its profile)")
    progress("judging the refiner against the profile's floor on validation")
    cells = versus_floor(load_model(run_dir / "best.pt"), profile, va, cfg)
    beats = bool(best_epoch) and all(c["rot_ratio"] < BEAT and c["trans_ratio"] < BEAT for c in cells)
    model_file = Path(out_dir) / (SHIPPED if beats else NOT_SHIPPED)
    for stale in (Path(out_dir) / SHIPPED, Path(out_dir) / NOT_SHIPPED):
        if stale != model_file and stale.exists():
            stale.unlink()  # an earlier calibrate's verdict in the same folder
    strip_checkpoint(run_dir / "best.pt", model_file)
    res = LearnedResult(beats, model_file, run_dir, best_epoch, cells, [s.name for s in va], time.time() - t0)
    atomic_write_text(Path(out_dir) / "learned.json", json.dumps(res.to_dict(), indent=2) + "\n")
    return res


def versus_floor(model: Any, profile: Profile, val: Sequence[Segment], cfg: RunConfig) -> List[Dict[str, Any]]:
    """The model's and the floor's relative pose RMSE on ``val`` and their ratios, per selection
    horizon and protocol (module doc); windows every ``data.val_stride`` samples, from
    ``data.startup_bias_s`` on where every segment is long enough, else from the start."""
    d = cfg.data
    floor = [Segment(s.name, s.t_ns, *profile.apply(s.t_ns, s.gyro, s.acc), s.p, s.v, s.q_wxyz) for s in val]
    learned = [trainer.refine_sequence(model, s, cfg) for s in val]
    out = []
    for n in list(cfg.optim.select_horizons) or [d.window]:
        first = d.startup_bias_s if all(len(s) - index_at(s, d.startup_bias_s) > n for s in val) else 0.0
        for protocol in PROTOCOLS:
            if protocol == "open loop":
                f, m = (relative_pose_rmse_many(x, n, d.val_stride, d.gravity, first_s=first) for x in (floor, learned))
            else:
                f, m = (trainer.bias_removed_pose(x, n, cfg) for x in (floor, learned))
            out.append({"n": n, "protocol": protocol, "from_s": first,
                        "floor": {"rot_deg": f["rot_deg"], "trans_m": f["trans_m"]},
                        "model": {"rot_deg": m["rot_deg"], "trans_m": m["trans_m"]},
                        "rot_ratio": m["rot_rad"] / max(f["rot_rad"], 1e-15),
                        "trans_ratio": m["trans_m"] / max(f["trans_m"], 1e-15)})
    return out
