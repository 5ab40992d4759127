"""calibrate's held-back block (calib.sources.held_back): the last part of each recording, unless it does
not move, when it could neither select the floor's filter and offset nor judge the profile (BROAD's trial
18 ends at rest: a 5 Hz filter and a y gyro bias of -0.09 rad/s chosen and judged on it, the profile then
worse than raw on another trial); then the latest block that moves, never one fitted."""
from __future__ import annotations

import logging

import numpy as np

from imu_learn.calib.sources import held_back, moves
from imu_learn.data.splits import cut
from imu_learn.data.types import Segment


def recording(still_from: float, seconds: float = 100.0, rate: float = 100.0) -> list:
    """One segment: turning and shaking until ``still_from`` (a fraction of its time), at rest after it."""
    n = int(seconds * rate)
    t = np.arange(n) / rate
    rng = np.random.default_rng(0)
    gyro = 1e-3 * rng.standard_normal((n, 3))
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + 1e-2 * rng.standard_normal((n, 3))
    moving = t < still_from * seconds
    gyro[moving] += 0.5 * np.sin(t[moving])[:, None]
    acc[moving, 0] += 2.0 * np.sin(3 * t[moving])
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return [Segment("rec", (t * 1e9).astype(np.int64), gyro, acc, np.zeros((n, 3)), np.zeros((n, 3)), q)]


def span(segs):
    return [(round(float(s.t_ns[0]) * 1e-9), round(float(s.t_ns[-1]) * 1e-9)) for s in segs]


def test_the_last_block_where_it_moves():
    tr, va = held_back(recording(1.0), 0.15)
    assert span(va) == [(85, 100)] and span(tr) == [(0, 85)]


def test_a_still_end_holds_back_the_latest_block_that_moves(caplog):
    segs = recording(0.8)
    with caplog.at_level(logging.INFO):
        tr, va = held_back(segs, 0.15)
    # stepping back half a block: 0.775-0.925 moves for its first 2.5 s only, 0.7-0.85 for two thirds
    assert moves(va) and span(va) == [(70, 85)]
    assert span(tr) == [(0, 70), (85, 100)]  # the rest fitted: before and after it, nothing of it twice
    assert sum(len(s) for s in tr + va) == len(segs[0])
    assert "does not move; held back 0.7-0.85" in caplog.text


def test_nothing_moving_keeps_the_last_and_says_it_cannot_judge(caplog):
    with caplog.at_level(logging.WARNING):
        tr, va = held_back(recording(0.0), 0.15)
    assert span(va) == [(85, 100)] and "--val-fraction 0" in caplog.text


def test_a_raw_gyro_bias_is_not_a_turn():
    """A raw gyro 0.08 rad/s off (EuRoC's ADIS16448 on z) at rest does not move: the recording's median
    gyro is taken off before the turn test, so its still end is stepped over as a calibrated one is."""
    segs = recording(0.8)
    biased = [s.__class__(s.name, s.t_ns, s.gyro + [0.0, 0.0, 0.08], s.acc, s.p, s.v, s.q_wxyz) for s in segs]
    tr, va = held_back(biased, 0.15)
    assert span(va) == [(70, 85)]
    tail = cut(biased, 0.85, 1.0, "rec")  # at rest: its gyro mean is the bias alone, above the cap
    assert moves(tail) and not moves(tail, np.median(biased[0].gyro, axis=0))
