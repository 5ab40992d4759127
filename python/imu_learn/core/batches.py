"""Augmented training batches, built in Rust in parallel (GIL released) and deterministic per seed.

Build batches in the main process (or spawned workers): rayon's thread pool does not survive a
``fork``, so torch DataLoader workers started by fork must not call into the core.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Iterable, List, Tuple

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.core.integration import PAPER_FRACTIONS, SegmentArrays


@dataclass(frozen=True)
class AugmentConfig:
    """Augmentation per window. All zero means none.

    Noise densities are continuous-time (discrete std = density / sqrt(dt)); biases are drawn
    uniformly per axis in [-max, max] once per window; the walks add a random-walk bias on top.
    """

    gyro_noise_density: float = 0.0  # rad/s/sqrt(Hz)
    acc_noise_density: float = 0.0  # m/s^2/sqrt(Hz)
    gyro_bias_max: float = 0.0  # rad/s
    acc_bias_max: float = 0.0  # m/s^2
    gyro_bias_walk: float = 0.0  # rad/s^2/sqrt(Hz)
    acc_bias_walk: float = 0.0  # m/s^3/sqrt(Hz)


@dataclass(frozen=True)
class BatchConfig:
    window: int = 200
    batch_size: int = 32
    fractions: Tuple[float, ...] = PAPER_FRACTIONS
    gravity: float = 9.81
    augment: AugmentConfig = field(default_factory=AugmentConfig)


@dataclass(frozen=True)
class Batch:
    """``imu`` (B, W, 6) gyro then acc, augmented; ``dt`` (B, W) [s]; labels (B, H, ...);
    ``bias`` (B, W, 6) the bias that was added; ``seq_index``/``start`` where each window came from."""

    imu: np.ndarray
    dt: np.ndarray
    dq_wxyz: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    label_dt: np.ndarray
    bias: np.ndarray
    seq_index: np.ndarray
    start: np.ndarray
    horizons: np.ndarray


def _core_set(seqs: Iterable[SegmentArrays]):
    parts: List[tuple] = []
    for s in seqs:
        parts.append(
            (
                np.ascontiguousarray(s.t_ns, dtype=np.int64),
                np.ascontiguousarray(s.gyro, dtype=np.float64),
                np.ascontiguousarray(s.acc, dtype=np.float64),
                np.ascontiguousarray(s.p, dtype=np.float64),
                np.ascontiguousarray(s.v, dtype=np.float64),
                np.ascontiguousarray(s.q_wxyz, dtype=np.float64),
            )
        )
    return core.SequenceSet(parts)


def batch_seed(seed: int, rank: int, step: int) -> int:
    """The seed of batch ``step`` on ``rank`` (0 for a single process): a pure function of the
    triple, so a resumed run draws exactly the batches it would have drawn, and ranks or runs with
    neighbouring seeds draw unrelated streams. Every trainer (fit, the baselines) seeds batches so."""
    return int(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, int(rank), int(step)]).generate_state(1, np.uint64)[0] >> 1)


class BatchSampler:
    """Holds the sequences once in Rust; each call draws a fresh augmented batch."""

    def __init__(self, seqs: Iterable[SegmentArrays], config: BatchConfig = BatchConfig()) -> None:
        self.config = config
        self._set = _core_set(seqs)

    def sample(self, seed: int) -> Batch:
        c = self.config
        d = self._set.make_batch(c.window, c.batch_size, list(c.fractions), c.gravity, int(seed), **asdict(c.augment))
        return Batch(**d)

    def eval_windows(self, stride: int) -> Batch:
        """Every window at a fixed stride, without augmentation (for validation and tests)."""
        c = self.config
        return Batch(**self._set.eval_windows(c.window, int(stride), list(c.fractions), c.gravity))


def make_batch(seqs: Iterable[SegmentArrays], config: BatchConfig, seed: int) -> Batch:
    """One augmented batch; the same seed gives the same batch whatever the thread count."""
    return BatchSampler(seqs, config).sample(seed)
