"""The fusion experiment: every recording x IMU input x aiding scenario of a :class:`FuseConfig`,
fused by :func:`imu_learn.fuse.graph.fuse` and scored against ground truth.

Every input of a recording and scenario sees the same aiding (for simulated aiding one draw per
noise seed of the config, seeded by it and the recording's and scenario's names), so rows differ
only in the IMU; the tables give mean +- std over the seeds. Results go to
``<out>/results.json`` after each run (atomically), each with a hash of everything it depends on, so
an interrupted or extended experiment reruns only what is missing or changed; a run whose graph GTSAM
cannot solve is recorded as failed with its error and the experiment goes on. ``table.md`` and the
trajectories (TUM files, causal and smoothed, at keyframes) are written beside it.
"""
from __future__ import annotations

import functools
import hashlib
import json
import multiprocessing
import os
import sys
import zlib
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.baselines.registry import method_file
from imu_learn.core.quat import wxyz_to_xyzw
from imu_learn.data.formats import rosbag
from imu_learn.data.formats.asl import imu_sensor_yaml, leica_file, read_leica
from imu_learn.data.loading import AlignOptions, load_recording
from imu_learn.data.types import Segment
from imu_learn.errors import ConfigError, InvalidInputError
from imu_learn.score.metrics import fit_startup_bias
from imu_learn.util.atomic import atomic_write_text
from imu_learn.util.digest import file_sha256

from ..aiding import (
    aiding_gaps,
    apply_outages,
    bag_position_source,
    check_aiding,
    clip_outages,
    leica_fixes,
    simulate_position,
    simulate_relative_pose,
)
from ..factors import chain
from ..factors.nhc import NhcSettings, nhc_callback
from ..graph import fuse
from ..inputs import FACTOR_INPUTS, LEARNED_COV_INPUTS, LEARNED_INPUT, TLIO_INPUT, displacement_hook, imu_input, load
from ..noise import ImuNoise
from ..output import plot_setting, read_runs, runs_of, write_json, write_trajectory, write_trajectory_bag
from ..score import crop, score
from ..settings import SETTLE_S, FusionSettings
from ..start import Start, groundtruth_start
from ..start.data import AlignSettings, data_start
from .config import FuseConfig, RecordingSpec, ScenarioSpec

# Changes with the estimator in graph.py, so results of an older estimator are not resumed.
ESTIMATOR = "isam2-gn-at-aiding-resolve-after-2s-qr+lm-qr"


def estimator(cfg: FuseConfig) -> str:
    """The estimator's name in the runs' hashes: the whole-graph one (lag inf) keeps its old name, so
    its results are resumed; a fixed-lag window names its length."""
    if not np.isfinite(cfg.lag_s):
        return ESTIMATOR
    return f"{ESTIMATOR}+fixed-lag-{cfg.lag_s:g}s-settle-{SETTLE_S:g}s-window-resolve-held"


def file_digest(path: str) -> str:
    p = Path(path)
    if not p.is_file():
        return ""
    st = p.stat()
    return _digest(str(p.resolve()), st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _digest(path: str, _size: int, _mtime_ns: int) -> str:
    """Keyed by size and mtime too, so a rewritten file is hashed again; read once per run_experiment
    otherwise (run_hash asks for every recording x scenario)."""
    return file_sha256(Path(path))


def artefact_of(cfg: FuseConfig, spec: RecordingSpec, name: str) -> str:
    """The file behind an input for this recording ("" for raw): its own model where it names one."""
    if name == "proposed":
        return spec.checkpoint or cfg.checkpoint
    if name in LEARNED_COV_INPUTS:
        return spec.covariance_checkpoint or cfg.covariance_checkpoint
    if name == "traditional":
        return spec.traditional or cfg.traditional
    if name == "raw":
        return ""
    return str(method_file(Path(spec.methods_dir or cfg.methods_dir), name))


def displacement_artefact(cfg: FuseConfig, spec: RecordingSpec) -> str:
    """The tlio-style model the ``learned`` input adds displacement factors from ("" when there is none)."""
    path = artefact_of(cfg, spec, TLIO_INPUT)
    return path if Path(path).is_file() else ""


def displacement_of(cfg: FuseConfig, spec: RecordingSpec, name: str, processors: Dict[Tuple[str, str], object]):
    """The fitted displacement model an input adds factors from, or None."""
    if name in FACTOR_INPUTS:
        return processors.get((name, artefact_of(cfg, spec, name)))
    if name == LEARNED_INPUT and displacement_artefact(cfg, spec):
        return load(TLIO_INPUT, displacement_artefact(cfg, spec), processors)
    return None


def seeds_of(cfg: FuseConfig, scn: ScenarioSpec) -> List[Optional[int]]:
    """The noise seeds a scenario runs with: every seed for simulated aiding, none for real."""
    return [None] if scn.kind == "leica" else list(cfg.seeds)


def align_settings(cfg: FuseConfig) -> AlignSettings:
    """The data start's settings this config asks for (its runs' hash and their first state)."""
    return AlignSettings(min_travel_m=cfg.align_travel_m)


def run_hash(cfg: FuseConfig, spec: RecordingSpec, scn: ScenarioSpec, name: str, seed: Optional[int]) -> str:
    """Everything one run's result depends on (not the other recordings, scenarios or inputs)."""
    artefact = artefact_of(cfg, spec, name)
    recording = {k: v for k, v in asdict(spec).items()
                 if k not in ("checkpoint", "traditional", "methods_dir", "covariance_checkpoint")}
    d = {"estimator": estimator(cfg), "seed": seed, "gravity": cfg.gravity, "keyframe_hz": cfg.keyframe_hz,
         "noise": asdict(cfg.noise), "recording": recording, "scenario": scenario_of(scn), "input": name,
         "artefact": file_digest(artefact) if artefact else ""}
    if name in FACTOR_INPUTS:  # learned displacement factors: their update grid too
        d["displacement_update_s"] = cfg.displacement_update_s
    if name == LEARNED_INPUT:  # its displacement model, when the device has one
        d["displacement"] = file_digest(displacement_artefact(cfg, spec))
        d["displacement_update_s"] = cfg.displacement_update_s
    if cfg.init != "groundtruth":  # (results from before the option existed started from ground truth)
        d["init"] = align_settings(cfg).tag()
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]


def scenario_of(scn: ScenarioSpec) -> dict:
    """The scenario's settings as a run depends on them (an option left off is left out, so results
    written before the option existed still resume)."""
    return {k: v for k, v in asdict(scn).items() if not (k == "nhc_sigma_mps" and v == 0)}


def run_key(spec: RecordingSpec, scn: ScenarioSpec, name: str, seed: Optional[int]) -> str:
    return f"{Path(spec.path).name}|{scn.name}|{name}" + ("" if seed is None else f"|s{seed}")


def aiding_rng(seed: Optional[int], rname: str, scn: ScenarioSpec) -> np.random.Generator:
    return np.random.default_rng([seed or 0, zlib.crc32(rname.encode()), zlib.crc32(scn.name.encode())])


def load_recording_for_fusion(cfg: FuseConfig, spec: RecordingSpec):
    """The recording's longest gap-free segment, its noise model, and its Leica fixes (or None)."""
    root = cfg.root()
    path = root / spec.path
    gt = root / spec.groundtruth if spec.groundtruth else None
    rec = load_recording(path, spec.format, groundtruth=gt, options=AlignOptions(max_gap_s=spec.max_gap_s),
                         imu_topic=spec.imu_topic or None, groundtruth_topic=spec.groundtruth_topic or None)
    seq = max(rec.segments, key=len)
    yaml = imu_sensor_yaml(path)
    n = cfg.noise
    if n.source == "sensor.yaml" and yaml is not None:
        noise = ImuNoise.from_sensor_yaml(yaml)
    else:
        noise = ImuNoise(n.gyro_noise_density, n.acc_noise_density, n.gyro_random_walk, n.acc_random_walk,
                         source="config [noise]")
    leica_csv = leica_file(path)
    leica = (*read_leica(leica_csv), str(leica_csv)) if leica_csv is not None else None
    if spec.aiding_topic:  # a bag's position / pose topic in the Leica's place
        leica = bag_position_source(path, spec.aiding_topic, spec.aiding_lever)
    return seq, noise, leica


def bias_prior_mean(scn: ScenarioSpec, seq, gyro: np.ndarray, acc: np.ndarray, gravity: float):
    if scn.bias_prior == "zero":
        return None
    bg, ba = fit_startup_bias(Segment(seq.name, seq.t_ns, gyro, acc, seq.p, seq.v, seq.q_wxyz),
                              scn.startup_bias_s, gravity=gravity)
    return np.r_[bg, ba]


def make_aiding(scn: ScenarioSpec, seq, leica, rng: np.random.Generator):
    if scn.kind == "position":
        a = simulate_position(seq.t_ns, seq.p, scn.rate_hz, scn.sigma_m, rng)
    elif scn.kind == "relative_pose":
        a = simulate_relative_pose(seq.t_ns, seq.p, seq.q_wxyz, scn.rate_hz, scn.sigma_rot_deg, scn.sigma_trans_m, rng)
    else:
        if leica is None:
            return None
        t, p, lever, source = leica
        t = t + int(round(scn.time_offset_s * 1e9))
        a = leica_fixes(t, p, lever, seq.t_ns, scn.rate_hz or None, scn.sigma_m, source=source)
    # AidingOverlapError (Leica outside the IMU segment) above; AidingError when outages leave nothing
    return check_aiding(apply_outages(a, seq.t_ns, scn.outage_windows()), f"{seq.name}|{scn.name}")


def bag_of(cfg: FuseConfig, spec: RecordingSpec) -> Optional[Path]:
    """The recording's bag (its trajectories are written as bags of the same kind), or None."""
    path = cfg.root() / spec.path
    return path if spec.format == rosbag.NAME or (spec.format == "auto" and rosbag.detect(path)) else None


def run_experiment(cfg: FuseConfig, out: Path, log: Callable[[str], None] = print,
                   only_inputs: Optional[List[str]] = None, jobs: int = 1) -> Dict[str, dict]:
    """Every run of ``cfg`` not yet in ``<out>/results.json`` with the same settings; ``jobs`` > 1 fuses
    that many runs at a time in worker processes (each single-threaded); this process alone writes
    results.json, after each run, in the runs' fixed order, so ``--jobs`` changes no output but
    the runs' ``seconds``."""
    # only_inputs: run only these of the config's inputs; the other inputs' results are left as they are
    run_inputs = [i for i in cfg.inputs if not only_inputs or i in only_inputs]
    if only_inputs and set(only_inputs) - set(cfg.inputs):
        raise ConfigError(f"--inputs: {sorted(set(only_inputs) - set(cfg.inputs))} not among the config's inputs {cfg.inputs}")
    if int(jobs) < 1:
        raise ConfigError(f"--jobs: must be >= 1, got {jobs}")
    processors: Dict[Tuple[str, str], object] = {}
    for spec in cfg.recordings:  # a missing model or fit fails here, before any run and before OUT exists
        for name in run_inputs:
            if name != "raw":
                load(name, artefact_of(cfg, spec, name), processors)
    out.mkdir(parents=True, exist_ok=True)
    res_path = out / "results.json"
    results = read_runs(res_path, log)
    wanted = {run_key(spec, scn, name, seed): run_hash(cfg, spec, scn, name, seed)
              for spec in cfg.recordings for scn in cfg.scenarios for seed in seeds_of(cfg, scn) for name in cfg.inputs}
    kept = {k: r for k, r in results.items()
            if wanted.get(k) == r.get("hash") or (only_inputs and r.get("input") not in run_inputs)}
    todo = [k for k in wanted if k.split("|")[2] in run_inputs]  # the runs of the inputs asked for (--inputs)
    done = sum(k in kept for k in todo)
    if done:
        log(f"imu_learn.fuse: {done} of {len(todo)} runs already in {res_path} with these settings")
    runs = RunQueue(int(jobs), res_path, cfg, kept, wanted, log, total=len(todo))
    plots: List[Callable[[], None]] = []
    with runs:
        for spec in cfg.recordings:
            plots += _submit_recording(cfg, out, spec, run_inputs, processors, runs)
    for plot in plots:  # after every run: they draw the trajectories on disk
        plot()
    atomic_write_text(out / "table.md", format_table(cfg, runs.results))
    return runs.results


def _submit_recording(cfg: FuseConfig, out: Path, spec: RecordingSpec, run_inputs: List[str],
                      processors: Dict[Tuple[str, str], object], runs: RunQueue) -> List[Callable[[], None]]:
    """Hand every missing run of one recording to ``runs``; returns its scenarios' plots, to draw once
    the runs are done."""
    rname = Path(spec.path).name
    seq, noise, leica = load_recording_for_fusion(cfg, spec)  # also for the plots of finished runs
    pending = any(k.split("|")[0] == rname and k.split("|")[2] in run_inputs and k not in runs.results
                  for k in runs.wanted)
    inputs = ({name: imu_input(name, seq, artefact_of(cfg, spec, name), processors) for name in run_inputs}
              if pending else {})
    # the ground-truth first attitude, for init = "groundtruth" only (run_one starts from the data otherwise)
    R0 = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix()
    plots: List[Callable[[], None]] = []
    for scn in cfg.scenarios:
        label = None
        for seed in seeds_of(cfg, scn):
            aiding = make_aiding(scn, seq, leica, aiding_rng(seed, rname, scn))
            if aiding is not None and seed == seeds_of(cfg, scn)[0] and (
                    getattr(aiding, "dropped_outside", 0) or getattr(aiding, "dropped_unmatched", 0)):
                runs.log(f"{rname}|{scn.name}: {aiding.label}: {aiding.dropped_outside} fixes outside the IMU segment "
                         f"and {aiding.dropped_unmatched} without an IMU sample of their own left out")
            for name in cfg.inputs:
                if name not in run_inputs:
                    continue
                key = run_key(spec, scn, name, seed)
                runs.count += 1
                if aiding is None or key in runs.results:
                    continue
                gyro, acc, var = inputs[name]
                displacement = displacement_of(cfg, spec, name, processors)
                runs.submit(key, seed, (cfg, out, Run(key, seq, noise, R0, scn, aiding, (gyro, acc, var), displacement,
                                                      bag_of(cfg, spec))), {})
            label = label or (aiding.label if aiding is not None else None)
        if label is not None:  # drawn from the first seed's trajectories
            stem = run_key(spec, scn, "{input}", seeds_of(cfg, scn)[0]).replace("|", "_")
            plots.append(functools.partial(_plot, out, rname, scn, label, seq.t_ns, seq.p, stem, list(cfg.inputs)))
    return plots


def _plot(out: Path, rname: str, scn: ScenarioSpec, label: str, t_ns: np.ndarray, p: np.ndarray, stem: str,
          inputs: List[str]) -> None:
    plot_setting(out / "plots" / f"{rname}_{scn.name}.png", f"{rname}, {label}", t_ns, p,
                 runs_of(out / "trajectories", stem, inputs), scn.outage_windows())


# Thread pools of the numeric libraries a worker may load, held to one thread each (set before the
# workers start: they read these at import).
SINGLE_THREAD_ENV = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "RAYON_NUM_THREADS")


def _single_threaded_worker() -> None:
    """A worker's initialiser: torch (when a run brings a model) on one thread too."""
    os.environ.update({k: "1" for k in SINGLE_THREAD_ENV})
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


class RunQueue:
    """The runs of an experiment: fused here one after the other (``jobs`` 1), or ``jobs`` at a time in
    worker processes (spawned, single-threaded). Either way this process records each result as
    it ends and rewrites results.json (atomically, the runs in ``wanted``'s order), so an
    interrupted experiment resumes from the runs that ended."""

    def __init__(self, jobs: int, res_path: Path, cfg: FuseConfig, results: Dict[str, dict], wanted: Dict[str, str],
                 log: Callable[[str], None], total: Optional[int] = None) -> None:
        self.jobs, self.res_path, self.cfg, self.log = jobs, res_path, cfg, log
        self.results, self.wanted = dict(results), wanted
        self.count = 0  # runs looked at so far, for the progress lines
        self.total = len(wanted) if total is None else int(total)  # the runs asked for (--inputs), of the lines
        self._pool = None
        self._futures: Dict[object, Tuple[str, Optional[int], int]] = {}
        self._env: Dict[str, Optional[str]] = {}

    def __enter__(self) -> RunQueue:
        if self.jobs > 1:
            self._env = {k: os.environ.get(k) for k in SINGLE_THREAD_ENV}
            os.environ.update({k: "1" for k in SINGLE_THREAD_ENV})
            self._pool = ProcessPoolExecutor(self.jobs, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_single_threaded_worker)
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._pool is None:
            return
        try:
            if exc_type is None:
                self._collect()
        finally:
            self._pool.shutdown(wait=True, cancel_futures=True)
            # whatever ended is kept (an error in one run stops the rest), so a rerun resumes after it
            for fut, (key, seed, n) in self._futures.items():
                if fut.done() and not fut.cancelled() and fut.exception() is None and key not in self.results:
                    self._record(key, seed, n, fut.result())
            for k, v in self._env.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v

    def submit(self, key: str, seed: Optional[int], args: tuple, kwargs: dict) -> None:
        if self._pool is None:
            self._record(key, seed, self.count, run_one(*args, **kwargs))
        else:
            self._futures[self._pool.submit(run_one, *args, **kwargs)] = (key, seed, self.count)

    def _collect(self) -> None:
        for fut in as_completed(self._futures):
            key, seed, n = self._futures[fut]
            self._record(key, seed, n, fut.result())

    def _record(self, key: str, seed: Optional[int], n: int, r: dict) -> None:
        r = self.results[key] = r | {"seed": seed, "hash": self.wanted[key]}
        order = {k: i for i, k in enumerate(self.wanted)}
        self.results = dict(sorted(self.results.items(), key=lambda kv: order.get(kv[0], len(order))))
        save_results(self.res_path, self.cfg, self.results)
        self.log(f"[{n}/{self.total}] {key}: " + (f"failed: {r['failed'][:120]}" if "failed" in r else
                 f"position RMSE causal {r['causal']['pos_rmse_m']:.3f} m, smoothed "
                 f"{r['smoothed']['pos_rmse_m']:.3f} m ({r['seconds']:.0f} s)"))


@dataclass
class Run:
    """One run of the experiment: its ``key`` (recording|scenario|input[|seed]), the recording's segment
    ``seq`` and noise model, ground truth's first attitude ``R0`` (the first state with
    ``cfg.init = "groundtruth"``; else the run starts from the data:
    :func:`imu_learn.fuse.start.data.data_start`), the scenario and its aiding, the input's samples
    ``imu`` (gyro, acc, per-sample variances or None), a fitted displacement model whose displacements
    join the graph as factors (or None), and the recording's bag when it is one (the trajectories are
    then written as its kind of bag too)."""

    key: str
    seq: object
    noise: ImuNoise
    R0: np.ndarray
    scn: ScenarioSpec
    aiding: object
    imu: tuple
    displacement: object = None
    bag: Optional[Path] = None


def run_one(cfg: FuseConfig, out: Path, run: Run) -> dict:
    """Fuse one input with one aiding; its scores (or ``failed``) and its trajectories on disk."""
    key, seq, noise, R0, scn, aiding, displacement, bag = (run.key, run.seq, run.noise, run.R0, run.scn, run.aiding,
                                                            run.displacement, run.bag)
    gyro, acc, var = run.imu
    rname, _, name = key.split("|")[:3]
    head = {"recording": rname, "scenario": scn.name, "input": name, "aiding": aiding.label,
            "aiding_count": len(aiding), "aiding_gaps": aiding_gaps(aiding, seq.t_ns),
            "aiding_dropped": {k: getattr(aiding, k) for k in ("dropped_outside", "dropped_unmatched", "dropped_outage")
                               if hasattr(aiding, k)},
            "outages_clipped": [list(w) for w in clip_outages(seq.t_ns, scn.outage_windows())],
            "duration_s": seq.duration_s, "noise": noise.source if var is None else "learned per-sample variances"}
    bias0 = bias_prior_mean(scn, seq, gyro, acc, cfg.gravity)
    if bias0 is not None:
        head["bias_prior"] = [round(float(b), 6) for b in bias0]
    try:
        start = first_state(cfg, seq, noise, R0, aiding, gyro, acc, bias0, var)
    except (RuntimeError, InvalidInputError) as e:  # no heading could be aligned
        return {**head, "failed": " ".join(str(e).split())[:300]}
    head["init"] = start.info
    s0 = start.start
    # The displacement network regresses from the raw samples it was trained on (tlio-style's input
    # is the raw IMU; "learned" fuses refined samples beside it).
    hook = (None if displacement is None else
            displacement_hook(displacement, seq.t_ns[s0:], seq.gyro[s0:], seq.acc[s0:],
                                     cfg.displacement_update_s))
    nhc = None
    if scn.nhc_sigma_mps > 0:  # wheeled platform: the non-holonomic constraint at every keyframe
        nhc = nhc_callback(NhcSettings(scn.nhc_sigma_mps, scn.nhc_sigma_mps), np.ascontiguousarray(gyro[s0:]))
    extra = chain(hook, nhc)
    try:
        res = fuse(seq.t_ns[s0:], gyro[s0:], acc[s0:], (start.R, start.p, start.v), [aiding.since(s0)],
                   FusionSettings(noise, cfg.gravity, cfg.keyframe_hz, start.prior, lag_s=cfg.lag_s), bias0=start.bias,
                   var=None if var is None else var[s0:], extra_factors=extra)
    except RuntimeError as e:  # GTSAM's IndeterminateLinearSystemException and kin
        return {**head, "failed": " ".join(str(e).split())[:300]}
    # keyframes in the recording's samples; a data start's alignment window is neither written nor scored
    res = crop(res, s0, start.score_from)
    if hook is not None:
        head["displacement_factors"] = {"count": hook.count, "skipped": hook.skipped,
                                        "update_s": cfg.displacement_update_s}
    stem = key.replace("|", "_")
    for kind, p, R in (("causal", res.causal_p, res.causal_R), ("smoothed", res.smoothed_p, res.smoothed_R)):
        write_trajectory(out / "trajectories" / f"{stem}_{kind}.tum", seq.t_ns[res.kf_idx], p, R)
        if bag is not None:  # a bag recording also gets its trajectory as a bag topic
            write_trajectory_bag(out / "trajectories" / f"{stem}_{kind}", seq.t_ns[res.kf_idx], p, R, like=bag)
    s = score(res, seq.t_ns, seq.p, seq.q_wxyz, scn.outage_windows(), align=start.align)
    return {**head, "seconds": round(res.seconds, 2), **s}


def first_state(cfg: FuseConfig, seq, noise: ImuNoise, R0: np.ndarray, aiding, gyro: np.ndarray, acc: np.ndarray,
                bias0: Optional[np.ndarray], var: Optional[np.ndarray]) -> Start:
    """The run's first fused sample and state: ground truth's (``cfg.init = "groundtruth"``, the
    graph's tight default prior) or the data's (:func:`imu_learn.fuse.start.data.data_start`)."""
    if cfg.init == "groundtruth":
        return groundtruth_start(R0, seq.p[0], seq.v[0], bias0)
    st = data_start(seq.t_ns, gyro, acc, aiding, FusionSettings(noise, cfg.gravity, cfg.keyframe_hz), bias0, var,
                    align_settings(cfg))
    return replace(st, info=json_ready(st.info))


def json_ready(info: Dict[str, object]) -> Dict[str, object]:
    return {k: (round(float(v), 4) if isinstance(v, (float, np.floating)) else v) for k, v in info.items()}


def save_results(path: Path, cfg: FuseConfig, results: Dict[str, dict]) -> None:
    write_json(path, {"config": asdict(cfg), "runs": results})


def runs_by_cell(results: Dict[str, dict]) -> Dict[Tuple[str, str, str], List[dict]]:
    """(recording, scenario, input) -> its runs over the noise seeds."""
    cells: Dict[Tuple[str, str, str], List[dict]] = {}
    for r in results.values():
        cells.setdefault((r["recording"], r["scenario"], r["input"]), []).append(r)
    return cells


def mean_std(values: List[float], digits: int = 3) -> str:
    """``mean ± std`` (sample std) over the seeds; the value alone for one run."""
    v = np.asarray(values, dtype=np.float64)
    if len(v) == 1:
        return f"{v[0]:.{digits}f}"
    return f"{v.mean():.{digits}f} ± {v.std(ddof=1):.{digits}f}"


# EuRoC MH_01 trained the shared models (its rows use models trained without it), so the averages
# over the test recordings that stand beside the paper's leave it out.
NOT_IN_AVERAGE = ("MH_01_easy",)


def complete_seeds(runs: List[dict], n_recordings: int) -> List[object]:
    """The noise seeds every one of the ``n_recordings`` has a run of (an average over a seed that
    some recordings lack would compare different recordings)."""
    count: Dict[object, int] = {}
    for r in runs:
        count[r.get("seed")] = count.get(r.get("seed"), 0) + 1
    return sorted((s for s, c in count.items() if c == n_recordings), key=lambda s: -1 if s is None else s)


def average(runs: List[dict], kind: str, seeds: List[object]) -> str:
    """Mean ± std over ``seeds`` of each seed's average over the recordings in ``runs``."""
    per_seed: Dict[object, List[float]] = {s: [] for s in seeds}
    for r in runs:
        if r.get("seed") in per_seed:
            per_seed[r.get("seed")].append(float("nan") if "failed" in r else r[kind]["pos_rmse_m"])
    return mean_std([sum(v) / len(v) for v in per_seed.values()])


def cell_text(runs: List[dict], kind: str) -> str:
    """A table cell: position RMSE mean ± std over the seeds (rotation RMSE mean in brackets);
    failed runs are counted, not averaged."""
    ok = [r for r in runs if "failed" not in r]
    if not ok:
        return "failed" if runs else "–"
    text = (f"{mean_std([r[kind]['pos_rmse_m'] for r in ok])} "
            f"({np.mean([r[kind]['rot_rmse_deg'] for r in ok]):.2f})")
    return text + (f" [{len(runs) - len(ok)} failed]" if len(ok) < len(runs) else "")


def first_state_label(cfg: FuseConfig) -> str:
    """What every table says of its runs' first state."""
    if cfg.init == "groundtruth":
        return ("First state: **a prior from ground truth** (pose and velocity at the first sample; the controlled "
                "setting, `init = \"groundtruth\"`; the default `init = \"data\"` and `imu-learn navigate` start from "
                "the data alone).")
    return ("First state: from the data alone (`init = \"data\"`, fuse/start/data.py): levelled from the accelerometer; "
            "position fixes: heading from yaw hypotheses fitted to the first fixes, the run scored from the end of that "
            "alignment window; relative poses: zero yaw at the origin, scores after a rigid SE(3) alignment.")


def format_table(cfg: FuseConfig, results: Dict[str, dict]) -> str:
    lines = [f"# {cfg.name}: position RMSE [m] (rotation RMSE [deg]) at keyframes, causal / smoothed",
             "", f"Simulated aiding: mean ± std over the noise seeds {cfg.seeds}; real aiding: one run.",
             first_state_label(cfg), ""]
    cells = runs_by_cell(results)
    for scn in cfg.scenarios:
        recs = list(dict.fromkeys(rec for rec, s, _ in cells if s == scn.name))
        if not recs:
            continue
        label = next(r["aiding"] for (_, s, _), rs in cells.items() if s == scn.name for r in rs)
        lines += [f"## {scn.name}: {label}" + (f", outages {scn.outages}" if scn.outages else ""), ""]
        head = "| recording | " + " | ".join(f"{i} causal | {i} smoothed" for i in cfg.inputs) + " |"
        lines += [head, "|" + "---|" * (1 + 2 * len(cfg.inputs))]
        for rec in recs:
            row = [cell_text(cells.get((rec, scn.name, i), []), k) for i in cfg.inputs for k in ("causal", "smoothed")]
            lines.append(f"| {rec} | " + " | ".join(row) + " |")
        if scn.outages:
            lines += ["", "Drift inside each outage (causal, max position error [m], mean ± std over the seeds):", ""]
            for rec in recs:
                for i in cfg.inputs:
                    ok = [r for r in cells.get((rec, scn.name, i), []) if "failed" not in r]
                    if ok:
                        o = "; ".join(f"{x['start_s']:g}+{x['duration_s']:g} s: "
                                      + mean_std([r["causal"]["outages"][j]["max_m"] for r in ok])
                                      for j, x in enumerate(ok[0]["causal"]["outages"]))
                        lines.append(f"- {rec}, {i}: {o}")
        lines.append("")
    return "\n".join(lines)
