"""The fusion run online: a recording treated as a stream, one IMU sample at a time.

Each raw sample goes through the whole per-sample path a navigation system would run live:

1. the input's refiner: ``raw`` passes the sample through; ``proposed`` steps the causal model
   (:meth:`~imu_learn.nn.model.ImuRefiner.step`, :class:`CausalStepper`) with the LSTM state carried
   from the previous sample; ``learned`` (:class:`WindowedStepper`) buffers it for the bidirectional
   covariance model, which runs once per completed window of the one windowing rule
   (:mod:`imu_learn.infer.windowing`) and releases that window's settled (centre-crop) samples, refined
   and with the covariance head's variances;
2. :meth:`IncrementalFusion.add_sample <imu_learn.fuse.graph.IncrementalFusion.add_sample>`, for
   every sample the refiner released (with its variances for ``learned``), advances the
   preintegration and, at a keyframe, adds the IMU and aiding factors and updates the causal solver
   (the fixed-lag smoother of ``lag_s``, the config's) where aiding arrived; it returns the causal
   state as of that sample's stamp.

The wall time of that whole path (``time.perf_counter_ns`` around refiner and fusion; a window's
model call is in the latency of the sample that completed the window) is the per-sample latency; the
real-time factor is the recording's duration over the loop's wall time (> 1: it keeps up). A sample
released later than it arrived (``learned``: it waits for its window) has an algorithmic delay,
:meth:`OnlineResult.algorithmic_delay_ns`: the stamps between its arrival and the arrival that
released it (inside the recording at most 3/4 of a window: 150 samples, 0.75 s for a 200-sample
window at 200 Hz; up to a whole window for the first window's first samples and the tail flushed at
the end). The causal trajectory is what :func:`imu_learn.fuse.graph.fuse` gives as its causal output
on the same input: bit for bit for ``raw`` (the batch run streams through the same class);
with the model, up to the float32 rounding by which its step-by-step forward differs from the
whole-sequence causal forward :func:`imu_learn.refine.refine_arrays` runs (about 1e-6 in the refined
IMU; tests/test_fuse_online.py). For ``learned`` it is what ``fuse()`` gives on the offline
:func:`imu_learn.infer.windowing.apply` of the same model (refined samples and variances; the streamed
ones equal them up to float32 rounding of the batched forward, tests/test_fuse_online.py), plus, where
the device has a tlio-style model, the same displacement factors (``extra_factors``; they read only
raw samples before the current keyframe, which have arrived). No smoothing runs online.

``imu-learn fuse --config configs/fuse_euroc.toml --online --checkpoint CAUSAL.pt`` runs
a config's recordings x scenarios this way (:func:`run_online`) and writes ``<out>/online.json``;
``--inputs raw,learned`` streams the config's covariance_checkpoint as ``learned``.
"""
from __future__ import annotations

import logging
import os
import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.core.quat import wxyz_to_xyzw
from imu_learn.errors import ConfigError, InvalidInputError
from imu_learn.infer.streaming import WindowedStepper, load_causal_model, load_learned_model, make_stepper
from imu_learn.util.machine import cpu_name

from ..aiding import OutageWindow
from ..graph import FusionResult, IncrementalFusion, feed
from ..inputs import TLIO_INPUT, displacement_hook, load
from ..output import read_runs, write_json
from ..score import score_online
from ..settings import FusionSettings
from . import batch as runmod

log = logging.getLogger(__name__)


ONLINE_INPUTS = ("raw", "proposed")  # streamed by default (--online without --inputs)
# every input that streams: "learned" on request (it needs the config's covariance_checkpoint)
STREAMABLE = ONLINE_INPUTS + ("learned",)



def latency_stats(ns: np.ndarray) -> Dict[str, float]:
    """count, median, p99, max and mean of latencies given in ns, in microseconds."""
    us = np.asarray(ns, dtype=np.float64) * 1e-3
    if not len(us):
        return {"count": 0, "median_us": float("nan"), "p99_us": float("nan"), "max_us": float("nan"),
                "mean_us": float("nan")}
    return {"count": int(len(us)), "median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
            "max_us": float(us.max()), "mean_us": float(us.mean())}


@dataclass
class OnlineResult:
    t_ns: np.ndarray  # (N,) the samples' stamps
    kf_idx: np.ndarray  # (K,) keyframe sample indices
    causal_p: np.ndarray  # (K, 3) each keyframe's causal position (as fuse()'s causal_p)
    causal_R: np.ndarray  # (K, 3, 3)
    p: np.ndarray  # (N, 3) the causal position as of every sample (IMU prediction between keyframes)
    latency_ns: np.ndarray  # (N,) wall time of each arrival's path: refiner + fusion of what it released
    keyframe: np.ndarray  # (N,) bool: the arrival's path reached a keyframe (raw, proposed: it is one)
    updated: np.ndarray  # (N,) bool: iSAM2 was updated in the arrival's path
    duration_s: float  # the recording's span
    wall_s: float  # the streaming loop's wall time
    setup_s: float  # building the graph's priors and the keyframe plan (before the first sample)
    counts: Dict[str, int]
    # (N,) the arrival at which each sample was released to the fusion (None: its own, no delay)
    released_at: Optional[np.ndarray] = None
    # (N,) bool: the refiner ran its model for a window in the arrival's path (learned); None: none do
    model_ran: Optional[np.ndarray] = None

    @property
    def rtf(self) -> float:
        """Real-time factor: recording duration / wall time (> 1 keeps up with the sensor)."""
        return self.duration_s / self.wall_s if self.wall_s > 0 else float("inf")

    def delay_ns(self) -> np.ndarray:
        """Each sample's delay from its stamp to its output if samples queue while the loop is busy
        (a sample is taken at its stamp or when the previous one is done, whichever is later):
        finish_s = max(stamp_s, finish_s-1) + latency_s, delay_s = finish_s - stamp_s."""
        arr = self.t_ns - self.t_ns[0]
        done = np.cumsum(self.latency_ns)
        finish = done + np.maximum.accumulate(arr - (done - self.latency_ns))
        return finish - arr

    def released_index(self) -> np.ndarray:
        """(N,) the arrival whose path released each sample to the fusion."""
        return np.arange(len(self.t_ns)) if self.released_at is None else self.released_at

    def algorithmic_delay_ns(self) -> np.ndarray:
        """(N,) each sample's wait for its refiner, in stamps [ns]: from its own stamp to the stamp of the
        arrival that released it (0 for raw and proposed; learned: the rest of its window)."""
        return self.t_ns[self.released_index()] - self.t_ns

    def output_delay_ns(self) -> np.ndarray:
        """(N,) each sample's delay from its stamp to its causal state: the algorithmic delay plus the
        queued delay (:meth:`delay_ns`) of the arrival that released it."""
        return self.algorithmic_delay_ns() + self.delay_ns()[self.released_index()]

    def stats(self) -> Dict[str, object]:
        period_ns = float(np.median(np.diff(self.t_ns)))
        return {
            "samples": int(len(self.latency_ns)),
            "duration_s": self.duration_s,
            "wall_s": self.wall_s,
            "setup_s": self.setup_s,
            "real_time_factor": self.rtf,
            "per_sample": latency_stats(self.latency_ns),
            "keyframe": latency_stats(self.latency_ns[self.keyframe]),
            "update": latency_stats(self.latency_ns[self.updated]),
            "between_keyframes": latency_stats(self.latency_ns[~self.keyframe]),
            "sample_period_us": period_ns * 1e-3,
            "over_period": int(np.sum(self.latency_ns > period_ns)),
            "delay": latency_stats(self.delay_ns()),
            "algorithmic_delay": {**latency_stats(self.algorithmic_delay_ns()),
                                  "max_samples": int((self.released_index() - np.arange(len(self.t_ns))).max()),
                                  "median_samples": float(np.median(self.released_index() - np.arange(len(self.t_ns))))},
            "output_delay": latency_stats(self.output_delay_ns()),
            "model_run": latency_stats(self.latency_ns[self.model_ran] if self.model_ran is not None else []),
            "counts": dict(self.counts),
        }

    def as_fusion_result(self) -> FusionResult:
        """The causal estimates in a :class:`FusionResult` for :func:`imu_learn.fuse.score.score`;
        there is no smoothing online, so its smoothed fields repeat the causal ones."""
        K = len(self.kf_idx)
        return FusionResult(self.kf_idx, self.causal_p, self.causal_R, self.causal_p, self.causal_R,
                            np.full((K, 3), np.nan), np.full((K, 6), np.nan), self.wall_s, dict(self.counts))


def stream(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, start_pose: tuple, aiding: Sequence = (),
           model=None, settings: FusionSettings = FusionSettings(), bias0: Optional[np.ndarray] = None,
           extra_factors: Optional[Callable] = None) -> OnlineResult:
    """Stream raw samples ``gyro``, ``acc`` (N, 3) with stamps ``t_ns`` through a refiner and
    :class:`IncrementalFusion` (under ``settings``), timing each arrival's whole path. ``model``: None
    (raw), a causal model (stepped: :class:`~imu_learn.infer.streaming.CausalStepper`), or a
    bidirectional model with a covariance head (``learned``:
    :class:`~imu_learn.infer.streaming.WindowedStepper`; its variances weight the IMU factors).
    ``extra_factors``: the graph's hook (e.g. learned displacement factors, :mod:`imu_learn.fuse.factors`)."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    gyro = np.asarray(gyro, dtype=np.float64)
    acc = np.asarray(acc, dtype=np.float64)
    n = len(t_ns)
    if n < 2 or gyro.shape != (n, 3) or acc.shape != gyro.shape:
        raise InvalidInputError(f"stream needs N >= 2 samples with gyro and acc (N, 3); got {gyro.shape}, {acc.shape}")
    stepper = make_stepper(model)
    if stepper is not None:
        stepper.warm_up()
    t0 = time.perf_counter()
    fusion = IncrementalFusion(t_ns, start_pose, aiding, settings, bias0, extra_factors=extra_factors)
    setup_s = time.perf_counter() - t0
    lat = np.zeros(n, dtype=np.int64)
    is_kf = np.zeros(n, dtype=bool)
    upd = np.zeros(n, dtype=bool)
    p = np.zeros((n, 3))
    at = np.full(n, -1, dtype=np.int64)
    ran = np.zeros(n, dtype=bool)

    def observe(item, state) -> None:
        i, s = item[0], item[4]  # the sample, and the arrival that released it
        is_kf[s] |= state.keyframe
        upd[s] |= state.updated
        p[i] = state.p
        at[i] = s

    wall0 = time.perf_counter()
    feed(fusion, _arrivals(stepper, gyro, acc, lat, ran), observe)
    wall_s = time.perf_counter() - wall0
    if (at < 0).any():
        raise RuntimeError(f"stream: {int((at < 0).sum())} samples were never released to the fusion")
    windowed = isinstance(stepper, WindowedStepper)
    return OnlineResult(t_ns, fusion.kf_idx, fusion.causal_p, fusion.causal_R, p, lat, is_kf, upd,
                        float(t_ns[-1] - t_ns[0]) * 1e-9, wall_s, setup_s, dict(fusion.counts),
                        at if windowed else None, ran if windowed else None)


def _arrivals(stepper, gyro: np.ndarray, acc: np.ndarray, lat: np.ndarray, ran: np.ndarray):
    """The samples the refiner releases at each arrival, as (index, gyro, acc, var, arrival); each
    arrival's wall time, from before the refiner to after the fusion of the last sample it released
    (the generator resumes once the consumer is done with it), goes to ``lat``; ``ran``: whether the
    refiner ran its model in that arrival's path."""
    clock = time.perf_counter_ns
    n = len(gyro)
    calls = getattr(stepper, "model_calls", 0)
    for s in range(n):
        g, a = gyro[s], acc[s]  # the sample as it arrives (a view: no work)
        c0 = clock()
        if stepper is None:
            yield s, g, a, None, s
        else:
            out = stepper.push(g, a)
            if s == n - 1:
                out = out + stepper.finish()
            for i, gi, ai, vi in out:
                yield i, gi, ai, vi, s
        lat[s] = clock() - c0
        if calls != getattr(stepper, "model_calls", 0):
            ran[s], calls = True, stepper.model_calls


def machine() -> Dict[str, object]:
    """What the latencies were measured on."""
    import torch

    cpu = cpu_name()
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count() or 0
    return {"cpu": cpu, "cores_available": cores, "torch_threads": torch.get_num_threads(),
            "RAYON_NUM_THREADS": os.environ.get("RAYON_NUM_THREADS", ""),
            "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", ""), "python": platform.python_version()}


def _select(names: Optional[Sequence[str]], available: List[str], what: str) -> List[str]:
    if not names:
        return available
    unknown = [n for n in names if n not in available]
    if unknown:
        raise ConfigError(f"--{what}: {', '.join(unknown)} not in the config (it has {', '.join(available)})")
    return [n for n in available if n in names]


def _causal_models(cfg, specs: list, checkpoint: Optional[str]) -> Tuple[Dict[str, object], Dict[str, str]]:
    """Every recording's causal model for ``proposed``, loaded (and checked causal) before any run:
    the models by checkpoint path, and each recording's checkpoint path."""
    models: Dict[str, object] = {}
    ckpt_of: Dict[str, str] = {}
    for spec in specs:
        path = checkpoint or runmod.artefact_of(cfg, spec, "proposed")
        if not Path(path).is_file():
            raise FileNotFoundError(2, "No such file or directory (the causal checkpoint for 'proposed')", path)
        if path not in models:
            hint = "" if checkpoint else "; pass --checkpoint CAUSAL.pt, or --inputs raw"
            models[path] = load_causal_model(Path(path), hint)
        ckpt_of[spec.path] = path
    return models, ckpt_of


def _learned_models(cfg, specs: list) -> Tuple[Dict[str, object], Dict[str, str]]:
    """Every recording's ``learned`` model (the config's covariance_checkpoint: bidirectional, with a
    covariance head), loaded and checked before any run: the models by path, and each recording's path."""
    models: Dict[str, object] = {}
    ckpt_of: Dict[str, str] = {}
    for spec in specs:
        path = runmod.artefact_of(cfg, spec, "learned")
        if not path or not Path(path).is_file():
            raise FileNotFoundError(2, "No such file or directory (the covariance_checkpoint for 'learned')", path)
        if path not in models:
            models[path] = load_learned_model(Path(path))
        ckpt_of[spec.path] = path
    return models, ckpt_of


def _displacement_hook(cfg, spec, seq, s0: int = 0) -> Optional[Callable]:
    """The ``learned`` input's displacement factors where the device has a tlio-style model (as the
    batch run adds them, on the raw IMU; the hook reads only samples before the current keyframe),
    else None."""
    path = runmod.displacement_artefact(cfg, spec)
    if not path:
        return None
    proc = load(TLIO_INPUT, path)
    log.info("learned: displacement factors from %s", path)
    return displacement_hook(proc, seq.t_ns[s0:], seq.gyro[s0:], seq.acc[s0:], cfg.displacement_update_s)


def _bias_prior(cfg, scn, seq, name: str, model, refined: Dict[str, tuple]) -> Optional[np.ndarray]:
    """The bias prior's mean for input ``name`` (None for a zero prior). The start-up prior (an
    initialisation from ground truth, as in the batch experiment) is fitted on the input the stream
    will see: the causal refinement of the first seconds, which refine_arrays gives (up to float32
    rounding), or for ``learned`` the windowed one, which ``apply`` gives (idem); ``refined`` caches
    them per recording."""
    if scn.bias_prior == "zero":
        return None
    if name == "proposed" and "proposed" not in refined:
        from imu_learn.infer.refiner import refine_arrays

        refined["proposed"] = refine_arrays(model, seq.gyro, seq.acc)
    if name == "learned" and "learned" not in refined:
        from imu_learn.infer.windowing import apply

        refined["learned"] = apply(model, seq.gyro, seq.acc)[:2]
    g, a = refined[name] if name in refined else (seq.gyro, seq.acc)
    return runmod.bias_prior_mean(scn, seq, g, a, cfg.gravity)


def _run_line(key: str, sc: dict, st: dict) -> str:
    """One finished online run, on one line."""
    ps, up = st["per_sample"], st["update"]
    return (f"{key}: causal position RMSE {sc['pos_rmse_m']:.3f} m; per-sample latency median "
            f"{ps['median_us']:.0f} us, p99 {ps['p99_us']:.0f} us, max {ps['max_us'] / 1e3:.1f} ms; "
            f"update p99 {up['p99_us'] / 1e3:.1f} ms ({up['count']}); max delay queued "
            f"{st['delay']['max_us'] / 1e3:.1f} ms; {_algorithmic(st)}real-time factor {st['real_time_factor']:.1f} "
            f"({st['samples']} samples, {st['duration_s']:.0f} s in {st['wall_s']:.1f} s)")


def _algorithmic(st: dict) -> str:
    """The algorithmic delay's part of a run's line ("" where samples do not wait for a window)."""
    ad = st["algorithmic_delay"]
    if not ad["max_samples"]:
        return ""
    return (f"algorithmic delay median {ad['median_samples']:.0f} samples ({ad['median_us'] / 1e3:.0f} ms), "
            f"max {ad['max_samples']} ({ad['max_us'] / 1e3:.0f} ms); ")


def _stream_recording(cfg, spec, scns: list, inputs: Sequence[str], models: Dict[str, object],
                      ckpt_of: Dict[Tuple[str, str], str], runs: Dict[str, dict], save: Callable[[], None],
                      log: Callable[[str], None]) -> None:
    """Every scenario x input of one recording, each run stored in ``runs`` and saved as it ends."""
    import torch
    from scipy.spatial.transform import Rotation

    rname = Path(spec.path).name
    seq, noise, leica = runmod.load_recording_for_fusion(cfg, spec)
    R0 = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix()
    refined: Dict[str, tuple] = {}
    with_displacement = "learned" in inputs and bool(runmod.displacement_artefact(cfg, spec))
    for scn in scns:
        scn_seed = runmod.seeds_of(cfg, scn)[0]  # None for real aiding
        aiding = runmod.make_aiding(scn, seq, leica, runmod.aiding_rng(scn_seed, rname, scn))
        if aiding is None:
            log(f"{rname}|{scn.name}: no {scn.kind} aiding in this recording; skipped")
            continue
        starts: Dict[Optional[bytes], object] = {}  # bias prior -> the scenario's first state
        for name in inputs:
            model = models[ckpt_of[(name, spec.path)]] if name != "raw" else None
            bias0 = _bias_prior(cfg, scn, seq, name, model, refined)
            key = runmod.run_key(spec, scn, name, scn_seed)
            try:
                # the batch runner's first state (cfg.init), found from the raw samples (the input's own
                # refinement is not streamed yet at the start): the same for every input with the same bias prior
                b_key = None if bias0 is None else np.asarray(bias0).tobytes()
                if b_key not in starts:
                    starts[b_key] = runmod.first_state(cfg, seq, noise, R0, aiding, seq.gyro, seq.acc, bias0, None)
                start = starts[b_key]
                s0 = start.start
                # a fresh hook per run: it holds the run's orientation estimates
                hook = _displacement_hook(cfg, spec, seq, s0) if name == "learned" and with_displacement else None
                res = stream(seq.t_ns[s0:], seq.gyro[s0:], seq.acc[s0:], (start.R, start.p, start.v),
                             [aiding.since(s0)], model,
                             FusionSettings(noise, cfg.gravity, cfg.keyframe_hz, start.prior, lag_s=cfg.lag_s),
                             bias0=start.bias, extra_factors=hook)
            except (RuntimeError, InvalidInputError) as e:  # GTSAM's exceptions; no heading could be aligned
                runs[key] = {"recording": rname, "scenario": scn.name, "input": name,
                             "failed": " ".join(str(e).split())[:300]}
                save()
                log(f"{key}: failed: {runs[key]['failed'][:120]}")
                continue
            st = res.stats()
            shift = (seq.t_ns[s0] - seq.t_ns[0]) * 1e-9  # outages count from the recording's first sample
            sc = score_online(res, seq.t_ns[s0:], seq.p[s0:], seq.q_wxyz[s0:],
                              [OutageWindow(a - shift, d) for a, d in scn.outage_windows()], start.score_from - s0, start.align)
            for o in sc["outages"]:
                o["start_s"] += shift
            runs[key] = {"recording": rname, "scenario": scn.name, "input": name, "seed": scn_seed,
                         "aiding": aiding.label, "aiding_count": len(aiding),
                         "checkpoint": ckpt_of.get((name, spec.path), ""),
                         "displacement": runmod.displacement_artefact(cfg, spec) if hook is not None else "",
                         "torch_threads": torch.get_num_threads(), "causal": sc, **st, "init": start.info}
            save()
            log(_run_line(key, sc, st))


def run_online(cfg, out: Path, checkpoint: Optional[str] = None, recordings: Optional[Sequence[str]] = None,
               scenarios: Optional[Sequence[str]] = None, inputs: Sequence[str] = ONLINE_INPUTS,
               log: Callable[[str], None] = print) -> Dict[str, dict]:
    """Stream each selected recording x scenario x input of ``cfg`` (a
    :class:`~imu_learn.fuse.experiments.config.FuseConfig`) and write ``<out>/online.json``, atomically after
    every run, merged with the runs already there (a run named again is measured again).
    ``checkpoint`` (a causal one) beats the config's models for ``proposed``; ``learned`` streams the
    config's covariance_checkpoint (:class:`WindowedStepper`) with, where the device has a tlio-style
    model, its displacement factors. Simulated aiding uses the config's first noise seed (the same
    draw as the batch experiment's runs of that seed)."""

    bad = [i for i in inputs if i not in STREAMABLE]
    if bad or not inputs:
        raise ConfigError(f"--inputs: online runs take {', '.join(STREAMABLE)}, got {', '.join(inputs) or 'none'}")
    rec_names = _select(recordings, [Path(r.path).name for r in cfg.recordings], "recordings")
    scn_names = _select(scenarios, [s.name for s in cfg.scenarios], "scenarios")
    specs = [r for r in cfg.recordings if Path(r.path).name in rec_names]
    scns = [s for s in cfg.scenarios if s.name in scn_names]
    models: Dict[str, object] = {}
    ckpt_of: Dict[Tuple[str, str], str] = {}  # (input, recording) -> checkpoint path
    for name, load_models in (("proposed", lambda: _causal_models(cfg, specs, checkpoint)),
                              ("learned", lambda: _learned_models(cfg, specs))):
        if name in inputs:
            loaded, paths = load_models()
            models.update(loaded)
            ckpt_of.update({(name, rec): path for rec, path in paths.items()})
    res_path = Path(out) / "online.json"
    runs = read_runs(res_path, log)
    info = machine()

    def save() -> None:
        write_json(res_path, {"machine": info, "config": asdict(cfg), "runs": runs})

    for spec in specs:
        _stream_recording(cfg, spec, scns, inputs, models, ckpt_of, runs, save, log)
    if not res_path.exists():
        save()
    return runs
