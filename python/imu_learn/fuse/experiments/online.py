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

``python -m imu_learn.fuse --config configs/fuse_euroc.toml --online --checkpoint CAUSAL.pt`` runs
a config's recordings x scenarios this way (:func:`run_online`) and writes ``<out>/online.json``;
``--inputs raw,learned`` streams the config's covariance_checkpoint as ``learned``.
"""
from __future__ import annotations

import json
import logging
import os
import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.errors import ConfigError, InvalidInputError

from ..graph import DEFAULT_LAG_S, FusionResult, IncrementalFusion, PriorSigmas
from ..noise import ImuNoise

log = logging.getLogger(__name__)

# One refined sample as a refiner releases it to the fusion: (sample index, gyro [rad/s] (3,),
# acc [m/s^2] (3,), its noise variances (6,) [gyro (rad/s)^2, acc (m/s^2)^2] or None for the datasheet's).
Released = Tuple[int, np.ndarray, np.ndarray, Optional[np.ndarray]]

ONLINE_INPUTS = ("raw", "proposed")  # streamed by default (--online without --inputs)
# every input that streams: "learned" on request (it needs the config's covariance_checkpoint)
STREAMABLE = ONLINE_INPUTS + ("learned",)


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
        self._n = 0  # samples pushed

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

    def push(self, gyro: np.ndarray, acc: np.ndarray) -> List[Released]:
        """The stepper as a refiner of the stream: the sample, refined at once (no variances)."""
        i = self._n
        self._n = i + 1
        g, a = self.step(gyro, acc)
        return [(i, g, a, None)]

    def finish(self) -> List[Released]:
        """Nothing is held back."""
        return []


def load_causal_model(path: Path, hint: str = ""):
    """A causal checkpoint's model; a bidirectional one is a :class:`ConfigError` (``hint`` is
    appended to its message)."""
    from imu_learn.infer.checkpoint import load_model

    model = load_model(Path(path))
    if not model.cfg.causal:
        raise ConfigError(f"{path}: a bidirectional checkpoint (it needs future samples); online refinement needs a "
                          f"causal one (trained with --model.causal true){hint}")
    return model


class WindowedStepper:
    """A bidirectional refiner with a covariance head (the ``learned`` input) applied to a stream by
    the one windowing rule of :mod:`imu_learn.infer.windowing`: sample by sample, with the same output
    as the offline ``apply(model, gyro, acc, variance=True)`` on the whole recording, without knowing
    where the recording ends.

    :meth:`push` buffers a raw sample and returns the samples it settled; :meth:`finish` (the stream
    has ended) returns the rest. A sample is released once its source window (the window of
    :func:`~imu_learn.infer.windowing.window_plan` it is kept from) has completed and is the same
    whatever the recording's length N turns out to be: with m samples in, those are the samples on
    which the plans for N = m and N = m + 1 agree (for N > m + 1 the kept ranges only grow;
    :meth:`_settled`), so a window's centre samples wait for the window's end and the end of its
    successor's overlap: an algorithmic delay of up to 3/4 of a window inside the recording (the
    first window's first samples and the tail released by :meth:`finish` wait up to a whole window:
    the plan's outer windows keep their outer edges). Each window runs
    through :func:`~imu_learn.infer.windowing.corrections` alone (a batch of one window; the offline
    pass stacks 16, hence float32 rounding differences), when its first samples are released: at the
    sample that completes it, or at :meth:`finish` for the plan's last window (moved back to end at
    N) or a recording shorter than a window. Refined = raw (float64) + the model's float32
    correction; variances (6,) [(rad/s)^2, (m/s^2)^2] as float64, as ``apply`` gives them.

    Memory is bounded: the raw samples and window outputs still needed (about two windows)."""

    def __init__(self, model, windowing=None) -> None:
        from imu_learn.infer.windowing import Windowing, windowing_of

        if getattr(getattr(model, "cfg", None), "causal", False):
            raise ConfigError("the model is causal; the windowed refiner is for a bidirectional model with a "
                              "covariance head (step a causal one with CausalStepper)")
        if getattr(model, "cov_head", None) is None:
            raise ConfigError("the model has no covariance head (a refiner fitted with model.covariance = true); "
                              "the 'learned' input fuses its per-sample variances")
        self.model = model.eval()
        self.windowing = windowing if windowing is not None else windowing_of(model)
        self._one = Windowing(self.windowing.window, self.windowing.overlap, 1)  # one window per forward
        self.W, self.S = self.windowing.window, self.windowing.window - self.windowing.overlap
        self.n = 0  # samples pushed
        self.released = 0  # samples released
        self.model_calls = 0
        self._buf = np.zeros((4 * self.W + 2 * self.S, 6))  # raw samples [_off, n)
        self._off = 0
        self._out: Dict[int, Tuple[np.ndarray, np.ndarray]] = {}  # window start -> (corrections, variances)

    def warm_up(self) -> None:
        """One forward on a zero window (torch's first call allocates); no state changes."""
        from imu_learn.infer.windowing import corrections

        corrections(self.model, np.zeros((self.W, 6), dtype=np.float32), self._one, variance=True)

    def _tail(self, n: int) -> List[Tuple[int, int, int, int]]:
        """The last windows of ``window_plan(n)`` (start, end, keep_from, keep_to): the plan of the
        samples from a window start b at least two strides before the last full window ending by n - 1,
        shifted by b (the plan's starts are multiples of the stride, so its windows from b on are these),
        without the window at b whose keep_from the shift loses (its samples are released already)."""
        from imu_learn.infer.windowing import window_plan

        W, S = self.W, self.S
        b = max(0, ((n - 1 - W) // S) * S - 2 * S) if n > W else 0
        plan = window_plan(n - b, W, self.windowing.overlap)
        return [(s + b, e + b, kf + b, kt + b) for s, e, kf, kt in (plan[1:] if b else plan)]

    def _settled(self, m: int) -> Tuple[int, List[Tuple[int, int, int, int]]]:
        """(bound, windows): with m samples in and more possibly to come, samples [0, bound) have the
        same source window in ``window_plan(N)`` for every N >= m, and that window has ended; windows:
        the plan's complete windows near the bound (for N = m + 1)."""
        nxt = [w for w in self._tail(m + 1) if w[1] <= m]  # every window but the last (it ends at m + 1)
        if not nxt:
            return 0, []
        s_last, kt_next = nxt[-1][0], nxt[-1][3]
        kt_now = next(kt for s, _e, _kf, kt in self._tail(m) if s == s_last)
        return min(kt_now, kt_next), nxt

    def _window(self, s: int, e: int) -> Tuple[np.ndarray, np.ndarray]:
        """Window [s, e)'s float32 corrections and variances (L, 6), computed once."""
        if s not in self._out:
            from imu_learn.infer.windowing import corrections

            raw32 = self._buf[s - self._off : e - self._off].astype(np.float32)
            self._out[s] = corrections(self.model, raw32, self._one, variance=True)
            self.model_calls += 1
        return self._out[s]

    def _release(self, bound: int, windows: Sequence[Tuple[int, int, int, int]]) -> List[Released]:
        """Samples [released, bound), each from its plan window, refined, with its variances."""
        out: List[Released] = []
        for s, e, kf, kt in windows:
            lo, hi = max(self.released, kf), min(bound, kt)
            if lo >= hi:
                continue
            if lo != self.released:
                raise RuntimeError(f"windowed refiner: sample {self.released} has no window (next kept from {lo})")
            corr, var = self._window(s, e)
            refined = self._buf[lo - self._off : hi - self._off] + corr[lo - s : hi - s].astype(np.float64)
            var64 = var[lo - s : hi - s].astype(np.float64)
            out += [(lo + j, refined[j, :3], refined[j, 3:], var64[j]) for j in range(hi - lo)]
            self.released = hi
        if self.released != bound:
            raise RuntimeError(f"windowed refiner: released {self.released} of {bound} settled samples")
        for s in [s for s in self._out if s + self.W <= self.released]:  # used up
            del self._out[s]
        return out

    def _append(self, row: np.ndarray) -> None:
        """Store a raw sample; when the buffer is full drop what no window or release needs any more."""
        if self.n - self._off == len(self._buf):
            keep = min(self.released, max(0, self.n - self.W - self.S))
            self._buf[: self.n - keep] = self._buf[keep - self._off : self.n - self._off]
            self._off = keep
        self._buf[self.n - self._off] = row
        self.n += 1

    def push(self, gyro: np.ndarray, acc: np.ndarray) -> List[Released]:
        """Take raw sample number :attr:`n` (gyro [rad/s], acc [m/s^2] (3,)); returns the samples it
        settles, in order (often none; about half a window's worth when it completes a window)."""
        self._append(np.concatenate((gyro, acc)))
        bound, windows = self._settled(self.n)
        return self._release(bound, windows) if bound > self.released else []

    def finish(self) -> List[Released]:
        """The stream has ended at N = :attr:`n` samples: the rest by ``window_plan(N)`` itself."""
        if self.n == 0:
            return []
        return self._release(self.n, self._tail(self.n))


def load_learned_model(path: Path):
    """The ``learned`` input's model: a bidirectional refiner with a covariance head; anything else is a
    :class:`ConfigError`."""
    from imu_learn.infer.checkpoint import load_model

    model = load_model(Path(path))
    if model.cfg.causal or getattr(model, "cov_head", None) is None:
        raise ConfigError(f"{path}: the 'learned' input needs a bidirectional refiner with a covariance head "
                          f"(model.covariance = true, e.g. models/euroc_adis16448_cov.pt); this one is "
                          f"{'causal' if model.cfg.causal else 'without a covariance head'}")
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
    extra_factors: Optional[Callable] = None,
) -> OnlineResult:
    """Stream raw samples ``gyro``, ``acc`` (N, 3) with stamps ``t_ns`` through a refiner and
    :class:`IncrementalFusion`, timing each arrival's whole path. ``model``: None (raw), a causal
    model (stepped: :class:`CausalStepper`), or a bidirectional model with a covariance head
    (``learned``: :class:`WindowedStepper`; its variances weight the IMU factors). ``extra_factors``:
    the graph's hook (e.g. learned displacement factors, :mod:`.displacement`)."""
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
    fusion = IncrementalFusion(t_ns, start_pose, aiding, noise, gravity, keyframe_hz, prior, bias0, iterations,
                               resolve_after_s=resolve_after_s, lag_s=lag_s, extra_factors=extra_factors)
    setup_s = time.perf_counter() - t0
    lat = np.zeros(n, dtype=np.int64)
    is_kf = np.zeros(n, dtype=bool)
    upd = np.zeros(n, dtype=bool)
    p = np.zeros((n, 3))
    at = np.full(n, -1, dtype=np.int64)
    ran = np.zeros(n, dtype=bool)
    stamps = t_ns.tolist()
    clock = time.perf_counter_ns
    calls = getattr(stepper, "model_calls", 0)
    wall0 = time.perf_counter()
    for s in range(n):
        g, a = gyro[s], acc[s]  # the sample as it arrives (a view: no work)
        c0 = clock()
        if stepper is None:
            out: Sequence[Released] = ((s, g, a, None),)
        else:
            out = stepper.push(g, a)
            if s == n - 1:
                out = out + stepper.finish()
        for i, gi, ai, vi in out:
            state = fusion.add_sample(stamps[i], gi, ai, vi)
            is_kf[s] |= state.keyframe
            upd[s] |= state.updated
            p[i] = state.p
            at[i] = s
        c1 = clock()
        lat[s] = c1 - c0
        if calls != getattr(stepper, "model_calls", 0):
            ran[s], calls = True, stepper.model_calls
    wall_s = time.perf_counter() - wall0
    if (at < 0).any():
        raise RuntimeError(f"stream: {int((at < 0).sum())} samples were never released to the fusion")
    windowed = isinstance(stepper, WindowedStepper)
    return OnlineResult(t_ns, fusion.kf_idx, fusion.causal_p, fusion.causal_R, p, lat, is_kf, upd,
                        float(t_ns[-1] - t_ns[0]) * 1e-9, wall_s, setup_s, dict(fusion.counts),
                        at if windowed else None, ran if windowed else None)


def make_stepper(model):
    """The refiner a model is streamed with: None (raw) for None, :class:`CausalStepper` for a causal
    model, :class:`WindowedStepper` for a bidirectional one (it needs a covariance head)."""
    if model is None:
        return None
    if getattr(getattr(model, "cfg", None), "causal", False):
        return CausalStepper(model)
    return WindowedStepper(model)


def score_online(res: OnlineResult, t_ns: np.ndarray, p_gt: np.ndarray, q_wxyz_gt: np.ndarray,
                 outages: Sequence[Tuple[float, float]] = (), first: int = 0, align: bool = False) -> Dict[str, object]:
    """The causal scores of :func:`imu_learn.fuse.score.score` (position and rotation RMSE at the
    keyframes, drift in each outage), plus the position RMSE of the causal state at every sample;
    from sample ``first`` on (a data start's alignment window is not scored), SE(3)-aligned first
    with ``align`` (relative aiding started from the data; the per-sample RMSE is then left out)."""
    from ..inmotion import crop
    from ..score import score

    s = dict(score(crop(res.as_fusion_result(), 0, first), t_ns, p_gt, q_wxyz_gt, outages, align=align)["causal"])
    if not align:
        s["pos_rmse_every_sample_m"] = float(np.sqrt(np.mean(np.sum((res.p[first:] - p_gt[first:]) ** 2, axis=1))))
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
    from . import batch as runmod

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
    from . import batch as runmod

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
    from . import batch as runmod
    from ..displacement import TLIO_INPUT, displacement_factors_for

    path = runmod.displacement_artefact(cfg, spec)
    if not path:
        return None
    proc = runmod.load_processor(TLIO_INPUT, path, {})
    log.info("learned: displacement factors from %s", path)
    return displacement_factors_for(proc, seq.t_ns[s0:], seq.gyro[s0:], seq.acc[s0:], cfg.displacement_update_s)


def _bias_prior(cfg, scn, seq, name: str, model, refined: Dict[str, tuple]) -> Optional[np.ndarray]:
    """The bias prior's mean for input ``name`` (None for a zero prior). The start-up prior (an
    initialisation from ground truth, as in the batch experiment) is fitted on the input the stream
    will see: the causal refinement of the first seconds, which refine_arrays gives (up to float32
    rounding), or for ``learned`` the windowed one, which ``apply`` gives (idem); ``refined`` caches
    them per recording."""
    from . import batch as runmod

    if scn.bias_prior == "zero":
        return None
    if name == "proposed" and "proposed" not in refined:
        from imu_learn.infer.refine import refine_arrays

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

    from imu_learn.core.quat import wxyz_to_xyzw

    from . import batch as runmod
    from ..inmotion import from_sample

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
                             [from_sample(aiding, s0)], model, noise, cfg.gravity, cfg.keyframe_hz, prior=start.prior,
                             bias0=start.bias, lag_s=cfg.lag_s, extra_factors=hook)
            except (RuntimeError, InvalidInputError) as e:  # GTSAM's exceptions; no heading could be aligned
                runs[key] = {"recording": rname, "scenario": scn.name, "input": name,
                             "failed": " ".join(str(e).split())[:300]}
                save()
                log(f"{key}: failed: {runs[key]['failed'][:120]}")
                continue
            st = res.stats()
            shift = (seq.t_ns[s0] - seq.t_ns[0]) * 1e-9  # outages count from the recording's first sample
            sc = score_online(res, seq.t_ns[s0:], seq.p[s0:], seq.q_wxyz[s0:],
                              [(a - shift, d) for a, d in scn.outage_windows()], start.score_from - s0, start.align)
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
    :class:`~imu_learn.fuse.config.FuseConfig`) and write ``<out>/online.json``, atomically after
    every run, merged with the runs already there (a run named again is measured again).
    ``checkpoint`` (a causal one) beats the config's models for ``proposed``; ``learned`` streams the
    config's covariance_checkpoint (:class:`WindowedStepper`) with, where the device has a tlio-style
    model, its displacement factors. Simulated aiding uses the config's first noise seed (the same
    draw as the batch experiment's runs of that seed)."""
    from imu_learn.util.atomic import atomic_write_text

    from . import batch as runmod

    bad = [i for i in inputs if i not in STREAMABLE]
    if bad or not inputs:
        raise ConfigError(f"--inputs: online runs take {', '.join(STREAMABLE)}, got {', '.join(inputs) or 'none'}")
    rec_names = _select(recordings, [Path(r.path).name for r in cfg.recordings], "recordings")
    scn_names = _select(scenarios, [s.name for s in cfg.scenarios], "scenarios")
    specs = [r for r in cfg.recordings if Path(r.path).name in rec_names]
    scns = [s for s in cfg.scenarios if s.name in scn_names]
    models: Dict[str, object] = {}
    ckpt_of: Dict[Tuple[str, str], str] = {}  # (input, recording) -> checkpoint path
    for name, load in (("proposed", lambda: _causal_models(cfg, specs, checkpoint)),
                       ("learned", lambda: _learned_models(cfg, specs))):
        if name in inputs:
            loaded, paths = load()
            models.update(loaded)
            ckpt_of.update({(name, rec): path for rec, path in paths.items()})
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
