"""Streaming inference: a refiner applied to an IMU stream one sample at a time, each sample released
to its consumer (e.g. the factor graph, :mod:`imu_learn.fuse.experiments.online`) as soon as the one
windowing rule (:mod:`imu_learn.infer.windowing`) settles it.

* :class:`CausalStepper`: a causal model stepped sample by sample, its LSTM state carried over;
* :class:`WindowedStepper`: a bidirectional model with a covariance head, run once per completed
  window, releasing that window's settled samples with their variances (the same output as the
  offline :func:`~imu_learn.infer.windowing.apply` on the whole recording).

:func:`make_stepper` picks the stepper a model streams with; :func:`load_causal_model` and
:func:`load_learned_model` load and check a checkpoint for each.
"""
from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.errors import ConfigError

# One refined sample as a refiner releases it to the fusion: (sample index, gyro [rad/s] (3,),
# acc [m/s^2] (3,), its noise variances (6,) [gyro (rad/s)^2, acc (m/s^2)^2] or None for the datasheet's).
Released = Tuple[int, np.ndarray, np.ndarray, Optional[np.ndarray]]


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


def make_stepper(model):
    """The refiner a model is streamed with: None (raw) for None, :class:`CausalStepper` for a causal
    model, :class:`WindowedStepper` for a bidirectional one (it needs a covariance head)."""
    if model is None:
        return None
    if getattr(getattr(model, "cfg", None), "causal", False):
        return CausalStepper(model)
    return WindowedStepper(model)
