"""The fusion run online: a recording treated as a stream, one IMU sample at a time.

Each raw sample goes through the whole per-sample path a navigation system would run live:

1. the causal model's :meth:`~imu_learn.nn.model.ImuRefiner.step` (input ``proposed``; ``raw`` passes
   the sample through) refines it with the LSTM state carried from the previous sample;
2. :meth:`IncrementalFusion.add_sample <imu_learn.fuse.graph.IncrementalFusion.add_sample>`
   advances the preintegration and, at a keyframe, adds the IMU and aiding factors and updates
   the causal solver (the fixed-lag smoother of ``lag_s``, the config's) where aiding arrived; it
   returns the causal state as of the sample's stamp.

The wall time of that whole path (``time.perf_counter_ns`` around model step and fusion) is the
per-sample latency; the real-time factor is the recording's duration over the loop's wall time (> 1:
it keeps up). The causal trajectory is what :func:`imu_learn.fuse.graph.fuse` gives as its causal
output on the same input: bit for bit for ``raw`` (the batch run streams through the same class);
with the model, up to the float32 rounding by which its step-by-step forward differs from the
whole-sequence causal forward :func:`imu_learn.refine.refine_arrays` runs (about 1e-6 in the refined
IMU; tests/test_fuse_online.py). No smoothing runs online.

``python -m imu_learn.fuse --config configs/fuse_euroc.toml --online --checkpoint CAUSAL.pt`` runs
a config's recordings x scenarios this way (:func:`run_online`) and writes ``<out>/online.json``.
"""
from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.errors import ConfigError, InvalidInputError

from .graph import DEFAULT_LAG_S, FusionResult, IncrementalFusion, PriorSigmas
from .noise import ImuNoise

ONLINE_INPUTS = ("raw", "proposed")


class CausalStepper:
    """The causal model applied one sample at a time with its LSTM state carried over. As in
    :func:`imu_learn.refine.refine_arrays`, the network runs in float32 and its correction is added
    to the float64 raw sample.

    The step runs with oneDNN (mkldnn) off: its LSTM primitive costs about 200 us per call whatever
    the length, which for one time step is most of the step (measured on 2 cores: 580-940 us per
    step with it, 370-390 us without); torch's native LSTM kernel then runs instead. Both are float32;
    they differ from the whole-sequence forward by float32 rounding (tests/test_fuse_online.py)."""

    def __init__(self, model, native_lstm: bool = True) -> None:
        import torch

        if not getattr(model, "cfg", None) or not model.cfg.causal:
            raise ConfigError("the model is bidirectional (it needs future samples); online refinement needs a "
                              "causal checkpoint (trained with --model.causal true)")
        self._torch = torch
        self._mkldnn = torch.backends.mkldnn
        self.native_lstm = native_lstm
        self.model = model.eval()
        self.state = None

    def warm_up(self) -> None:
        """One step on a zero sample with a throwaway state (torch's first call allocates)."""
        state = self.state
        self.step(np.zeros(3), np.zeros(3))
        self.state = state

    def step(self, gyro: np.ndarray, acc: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        raw = np.concatenate((gyro, acc)).astype(np.float64, copy=False)
        x = self._torch.from_numpy(raw.astype(np.float32))[None]
        was = self._mkldnn.enabled
        self._mkldnn.enabled = was and not self.native_lstm
        try:
            y, self.state = self.model.step(x, self.state)
        finally:
            self._mkldnn.enabled = was
        refined = raw + (y - x)[0].numpy().astype(np.float64)
        return refined[:3], refined[3:]


def load_causal_model(path: Path, hint: str = ""):
    """A causal checkpoint's model; a bidirectional one is a :class:`ConfigError` (``hint`` is
    appended to its message)."""
    from imu_learn.train.checkpoint import load_model

    model = load_model(Path(path))
    if not model.cfg.causal:
        raise ConfigError(f"{path}: a bidirectional checkpoint (it needs future samples); online refinement needs a "
                          f"causal one (trained with --model.causal true){hint}")
    return model


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
    latency_ns: np.ndarray  # (N,) wall time of each sample's path: model step + fusion
    keyframe: np.ndarray  # (N,) bool: the sample is a keyframe
    updated: np.ndarray  # (N,) bool: iSAM2 was updated at the sample
    duration_s: float  # the recording's span
    wall_s: float  # the streaming loop's wall time
    setup_s: float  # building the graph's priors and the keyframe plan (before the first sample)
    counts: Dict[str, int]

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
            "counts": dict(self.counts),
        }

    def as_fusion_result(self) -> FusionResult:
        """The causal estimates in a :class:`FusionResult` for :func:`imu_learn.fuse.score.score`;
        there is no smoothing online, so its smoothed fields repeat the causal ones."""
        K = len(self.kf_idx)
        return FusionResult(self.kf_idx, self.causal_p, self.causal_R, self.causal_p, self.causal_R,
                            np.full((K, 3), np.nan), np.full((K, 6), np.nan), self.wall_s, dict(self.counts))


def stream(
    t_ns: np.ndarray,
    gyro: np.ndarray,
    acc: np.ndarray,
    start_pose: tuple,
    aiding: Sequence = (),
    model=None,
    noise: ImuNoise = ImuNoise(),
    gravity: float = 9.81,
    keyframe_hz: float = 10.0,
    prior: PriorSigmas = PriorSigmas(),
    bias0: Optional[np.ndarray] = None,
    iterations: int = 1,
    resolve_after_s: float = 2.0,
    lag_s: float = DEFAULT_LAG_S,
) -> OnlineResult:
    """Stream raw samples ``gyro``, ``acc`` (N, 3) with stamps ``t_ns`` through ``model``'s causal
    step (None: raw) and :class:`IncrementalFusion`, timing each sample's whole path."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    gyro = np.asarray(gyro, dtype=np.float64)
    acc = np.asarray(acc, dtype=np.float64)
    n = len(t_ns)
    if n < 2 or gyro.shape != (n, 3) or acc.shape != gyro.shape:
        raise InvalidInputError(f"stream needs N >= 2 samples with gyro and acc (N, 3); got {gyro.shape}, {acc.shape}")
    stepper = None if model is None else CausalStepper(model)
    if stepper is not None:
        stepper.warm_up()
    t0 = time.perf_counter()
    fusion = IncrementalFusion(t_ns, start_pose, aiding, noise, gravity, keyframe_hz, prior, bias0, iterations,
                               resolve_after_s=resolve_after_s, lag_s=lag_s)
    setup_s = time.perf_counter() - t0
    lat = np.zeros(n, dtype=np.int64)
    is_kf = np.zeros(n, dtype=bool)
    upd = np.zeros(n, dtype=bool)
    p = np.zeros((n, 3))
    stamps = t_ns.tolist()
    clock = time.perf_counter_ns
    wall0 = time.perf_counter()
    for s in range(n):
        g, a = gyro[s], acc[s]  # the sample as it arrives (a view: no work)
        c0 = clock()
        if stepper is not None:
            g, a = stepper.step(g, a)
        state = fusion.add_sample(stamps[s], g, a)
        c1 = clock()
        lat[s] = c1 - c0
        is_kf[s], upd[s] = state.keyframe, state.updated
        p[s] = state.p
    wall_s = time.perf_counter() - wall0
    return OnlineResult(t_ns, fusion.kf_idx, fusion.causal_p, fusion.causal_R, p, lat, is_kf, upd,
                        float(t_ns[-1] - t_ns[0]) * 1e-9, wall_s, setup_s, dict(fusion.counts))


def score_online(res: OnlineResult, t_ns: np.ndarray, p_gt: np.ndarray, q_wxyz_gt: np.ndarray,
                 outages: Sequence[Tuple[float, float]] = ()) -> Dict[str, object]:
    """The causal scores of :func:`imu_learn.fuse.score.score` (position and rotation RMSE at the
    keyframes, drift in each outage), plus the position RMSE of the causal state at every sample."""
    from .score import score

    s = dict(score(res.as_fusion_result(), t_ns, p_gt, q_wxyz_gt, outages)["causal"])
    s["pos_rmse_every_sample_m"] = float(np.sqrt(np.mean(np.sum((res.p - p_gt) ** 2, axis=1))))
    return s


def machine() -> Dict[str, object]:
    """What the latencies were measured on."""
    import torch

    from imu_learn.util.machine import cpu_name

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
    from . import run as runmod

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


def _bias_prior(cfg, scn, seq, name: str, model, refined: Dict[str, tuple]) -> Optional[np.ndarray]:
    """The bias prior's mean for input ``name`` (None for a zero prior). The start-up prior (an
    initialisation from ground truth, as in the batch experiment) is fitted on the input the stream
    will see: the causal refinement of the first seconds, which refine_arrays gives (up to float32
    rounding); ``refined`` caches it per recording."""
    from . import run as runmod

    if scn.bias_prior == "zero":
        return None
    if name == "proposed" and "proposed" not in refined:
        from imu_learn.infer.refine import refine_arrays

        refined["proposed"] = refine_arrays(model, seq.gyro, seq.acc)
    g, a = refined["proposed"] if name == "proposed" else (seq.gyro, seq.acc)
    return runmod.bias_prior_mean(scn, seq, g, a, cfg.gravity)


def _run_line(key: str, sc: dict, st: dict) -> str:
    """One finished online run, on one line."""
    ps, up = st["per_sample"], st["update"]
    return (f"{key}: causal position RMSE {sc['pos_rmse_m']:.3f} m; per-sample latency median "
            f"{ps['median_us']:.0f} us, p99 {ps['p99_us']:.0f} us, max {ps['max_us'] / 1e3:.1f} ms; "
            f"update p99 {up['p99_us'] / 1e3:.1f} ms ({up['count']}); max delay queued "
            f"{st['delay']['max_us'] / 1e3:.1f} ms; real-time factor {st['real_time_factor']:.1f} "
            f"({st['samples']} samples, {st['duration_s']:.0f} s in {st['wall_s']:.1f} s)")


def _stream_recording(cfg, spec, scns: list, inputs: Sequence[str], models: Dict[str, object],
                      ckpt_of: Dict[str, str], runs: Dict[str, dict], save: Callable[[], None],
                      log: Callable[[str], None]) -> None:
    """Every scenario x input of one recording, each run stored in ``runs`` and saved as it ends."""
    import torch
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw

    from . import run as runmod

    rname = Path(spec.path).name
    seq, noise, leica = runmod.load_recording_for_fusion(cfg, spec)
    R0 = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix()
    refined: Dict[str, tuple] = {}
    for scn in scns:
        scn_seed = runmod.seeds_of(cfg, scn)[0]  # None for real aiding
        aiding = runmod.make_aiding(scn, seq, leica, runmod.aiding_rng(scn_seed, rname, scn))
        if aiding is None:
            log(f"{rname}|{scn.name}: no {scn.kind} aiding in this recording; skipped")
            continue
        for name in inputs:
            model = models[ckpt_of[spec.path]] if name == "proposed" else None
            bias0 = _bias_prior(cfg, scn, seq, name, model, refined)
            key = runmod.run_key(spec, scn, name, scn_seed)
            try:
                res = stream(seq.t_ns, seq.gyro, seq.acc, (R0, seq.p[0], seq.v[0]), [aiding], model, noise,
                             cfg.gravity, cfg.keyframe_hz, bias0=bias0, lag_s=cfg.lag_s)
            except RuntimeError as e:  # GTSAM's IndeterminateLinearSystemException and kin
                runs[key] = {"recording": rname, "scenario": scn.name, "input": name,
                             "failed": " ".join(str(e).split())[:300]}
                save()
                log(f"{key}: failed: {runs[key]['failed'][:120]}")
                continue
            st = res.stats()
            sc = score_online(res, seq.t_ns, seq.p, seq.q_wxyz, scn.outage_windows())
            runs[key] = {"recording": rname, "scenario": scn.name, "input": name, "seed": scn_seed,
                         "aiding": aiding.label, "aiding_count": len(aiding),
                         "checkpoint": ckpt_of.get(spec.path, "") if name == "proposed" else "",
                         "torch_threads": torch.get_num_threads(), "causal": sc, **st}
            save()
            log(_run_line(key, sc, st))


def run_online(cfg, out: Path, checkpoint: Optional[str] = None, recordings: Optional[Sequence[str]] = None,
               scenarios: Optional[Sequence[str]] = None, inputs: Sequence[str] = ONLINE_INPUTS,
               log: Callable[[str], None] = print) -> Dict[str, dict]:
    """Stream each selected recording x scenario x input of ``cfg`` (a
    :class:`~imu_learn.fuse.config.FuseConfig`) and write ``<out>/online.json``, atomically after
    every run, merged with the runs already there (a run named again is measured again).
    ``checkpoint`` (a causal one) beats the config's models for ``proposed``. Simulated aiding uses
    the config's first noise seed (the same draw as the batch experiment's runs of that seed)."""
    from imu_learn.util.atomic import atomic_write_text

    from . import run as runmod

    bad = [i for i in inputs if i not in ONLINE_INPUTS]
    if bad or not inputs:
        raise ConfigError(f"--inputs: online runs take {', '.join(ONLINE_INPUTS)}, got {', '.join(inputs) or 'none'}")
    rec_names = _select(recordings, [Path(r.path).name for r in cfg.recordings], "recordings")
    scn_names = _select(scenarios, [s.name for s in cfg.scenarios], "scenarios")
    specs = [r for r in cfg.recordings if Path(r.path).name in rec_names]
    scns = [s for s in cfg.scenarios if s.name in scn_names]
    models, ckpt_of = _causal_models(cfg, specs, checkpoint) if "proposed" in inputs else ({}, {})
    res_path = Path(out) / "online.json"
    runs = runmod.read_runs(res_path, log)
    info = machine()

    def save() -> None:
        atomic_write_text(res_path, json.dumps({"machine": info, "config": asdict(cfg), "runs": runs}, indent=1))

    for spec in specs:
        _stream_recording(cfg, spec, scns, inputs, models, ckpt_of, runs, save, log)
    if not res_path.exists():
        save()
    return runs
