"""Relative poses, and poses in the aiding's own world, that keep a SLAM trajectory's global
consistency. :func:`relative_poses` ties each row to the row before it (:data:`SPANS_S`, the
navigator's default) and, over longer spans (:data:`LONG_SPANS_S`), each anchor row (one per
``ANCHOR_S``) to the anchors further back, inside one run of rows (never across a gap longer than
``max_gap_s``: a visual system that lost track may restart in a new map). :func:`world_poses` ties
each row's pose to the aiding's own world, one free state of the graph (its pose in the navigation
frame, estimated online: :class:`.types.WorldPoses`); the navigator does so on aiding without breaks
(:func:`unbroken`) and on aiding whose breaks keep one map (:mod:`.maps`). Chaining consecutive rows
only turns a loop-closed trajectory into an odometry whose drift the graph cannot see; the world
carries its global shape to the causal estimate as well
(the long spans reached the smoothing pass only, those longer than the fixed-lag window never the
causal one: docs/experiments/navigate-vo.md), the chain its detail, and between them the IMU.

Each pair's sigmas come from each pose's own noise (:class:`.noise.PoseNoise`, per body axis, as
white noise per pose): rotation ``sqrt(2) σ_θ``; translation in frame i ``sqrt(2 σ_p² + (σ_θ × t_ij)²)``
(frame i's rotation error swings the far end). Over long spans every pose takes part in up to twice
as many pairs as there are spans, so its noise would be counted that many times: each long span's
sigma is inflated by the square root of the number of long spans (``inflate``).

A world pose's error is not white: a SLAM map's error varies slowly over the recording (ORB-SLAM2 on
EuRoC: 2-8 cm against the motion capture; 1700 poses at their estimated 2-3 cm each, weighed as
independent, would pin the world to about a millimetre). Where the aiding
has breaks in one map the causal estimate coasts through each break from the state the world leaves
it in, and with each world pose weighed as an independent measurement at the per-pose noise the
world's pull on that state (its velocity, its biases) doubled the coasting error (EuRoC V1_03, two
10 s gaps). So across breaks the causal solver gives each world pose the per-pose noise times
sqrt(rate x :data:`WORLD_CORRELATION_S`) (:func:`world_inflation`): the world's poses together weigh as
one pose per 500 s (x100 at 20 Hz). Weighed so, the world pulls a coast's end back onto the map over
seconds (each pose at 20 cm where the coast ended a metre or two off: EuRoC V1_03 with the raw IMU 22-28 cm
RMS over the first half second, against the VO's 2 cm). So the rows of the first :data:`REJOIN_S` after each
break (:func:`rejoining`) take their translation noise times :data:`REJOIN_INFLATE` only (x10, 2 cm) in the
causal solver: the map's error across a break changes little, the state's after a coast a lot. At their own
noise (x1) they pinned the state to the map's local error and pulled the biases after it (ORB-SLAM2 trial 0
with the profile: the causal track above the VO by up to 5.4 %, against 2.0 % without and 1.1 % at x10).
Their rotation stays inflated (at their own rotation noise ten of them outweigh the world's attitude and
turned it toward the coast's). Without breaks nothing coasts and the per-pose noise keeps the
causal track on the VO (at or below it on 19 of 24 ORB-SLAM2 runs; inflated, 14); the batch smoothing
pass always takes the per-pose noise (docs/experiments/navigate-vo.md)."""
from __future__ import annotations

from typing import Optional, Sequence, Tuple

import numpy as np

from .noise import PoseNoise
from .pairs import run_numbers
from .types import RelativePoses, WorldPoses

SPANS_S = (0.0,)  # 0: the next row (the navigator's relative poses, beside the world's)
LONG_SPANS_S = (0.0, 1.0, 4.0, 16.0, 64.0)  # and the anchors 1-64 s back (the navigator's before the world)
# across breaks, a world pose's error is the map's, correlated over the recording: in the causal solver the
# world's poses weigh together as one pose per WORLD_CORRELATION_S (each sigma x sqrt(rate x it))
WORLD_CORRELATION_S = 500.0
# the world's poses in the first REJOIN_S after each break: in the causal solver their translation sigmas
# x REJOIN_INFLATE only (chosen on ORB-SLAM2 trial 0 among 1, 10 and the full inflation)
REJOIN_S = 0.5
REJOIN_INFLATE = 10.0
ANCHOR_S = 1.0  # the spans longer than 0 join anchor rows, the first row of each ANCHOR_S


def anchors(t_s: np.ndarray, anchor_s: float = ANCHOR_S) -> np.ndarray:
    """Indices of the anchor rows: the first row of each ``anchor_s`` bin of times ``t_s``."""
    bins = np.floor((np.asarray(t_s, dtype=np.float64) - float(t_s[0])) / anchor_s).astype(np.int64)
    return np.unique(bins, return_index=True)[1]


def span_pairs(t_s: np.ndarray, spans_s: Sequence[float], max_gap_s: float,
               anchor_s: float = ANCHOR_S) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, j, which span) of rows at times ``t_s`` (sorted): span 0 ties each row to the row before;
    a longer span ties each anchor row (:func:`anchors`) to the last anchor at least that span before
    it. Only inside one run (:func:`.pairs.run_numbers`: consecutive rows more than zero and at most
    ``max_gap_s`` apart), each pair once (the shortest span's)."""
    t_s = np.asarray(t_s, dtype=np.float64)
    run = run_numbers(np.diff(t_s), max_gap_s)
    anc = anchors(t_s, anchor_s)
    pairs = {}
    for n, span in enumerate(spans_s):
        if span <= 0:
            j = np.arange(1, len(t_s))
            i = j - 1
        else:
            j = anc[1:]
            k = np.searchsorted(t_s[anc], t_s[j] - span, side="right") - 1
            ok = k >= 0
            i, j = anc[np.maximum(k, 0)][ok], j[ok]
        ok = (i < j) & (run[i] == run[j])
        for a, b in zip(i[ok], j[ok]):
            pairs.setdefault((int(a), int(b)), n)
    if not pairs:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    ij = np.array(sorted(pairs), dtype=np.int64)
    return ij[:, 0], ij[:, 1], np.array([pairs[tuple(x)] for x in ij], dtype=np.int64)


def pair_sigmas(t_ij: np.ndarray, noise: PoseNoise, inflate=1.0) -> np.ndarray:
    """(M, 6) sigmas of relative poses with translations ``t_ij`` (M, 3) in frame i (module docstring):
    rotation [rad] then translation [m], per axis."""
    th, sp = np.asarray(noise.rot_rad), np.asarray(noise.trans_m)
    rot = np.broadcast_to(np.sqrt(2) * th, (len(t_ij), 3))
    x, y, z = t_ij[:, 0], t_ij[:, 1], t_ij[:, 2]
    swing = np.stack([th[1] ** 2 * z ** 2 + th[2] ** 2 * y ** 2,
                      th[0] ** 2 * z ** 2 + th[2] ** 2 * x ** 2,
                      th[0] ** 2 * y ** 2 + th[1] ** 2 * x ** 2], axis=1)
    trans = np.sqrt(2 * sp ** 2 + swing)
    return inflate * np.c_[rot, trans]


def unbroken(t_ns: np.ndarray, max_gap_s: float) -> bool:
    """Whether the rows at ``t_ns`` are one run: no two consecutive further apart than ``max_gap_s``.
    Only such aiding is tied to its world (or over long spans): a visual system that lost track may
    restart in a new map, and with breaks (10 s camera gaps on EuRoC) the long spans made the coasting
    worse, the causal estimate diverging after a break (docs/experiments/navigate-vo.md)."""
    return len(run_starts(t_ns, max_gap_s)) == 0


def run_starts(t_ns: np.ndarray, max_gap_s: float) -> np.ndarray:
    """The rows (at stamps ``t_ns``) that start a run after a break: further than ``max_gap_s`` after the
    row before (the break rule of :func:`unbroken`, :func:`relative_poses`' count and :func:`rejoining`)."""
    return np.flatnonzero(np.diff(np.asarray(t_ns, dtype=np.int64)) * 1e-9 > max_gap_s) + 1


def given_noise(rel_rot_rad: float, rel_trans_m: float) -> PoseNoise:
    """Each pose's noise from sigmas given for a relative pose between two rows (each over sqrt(2))."""
    return PoseNoise(np.full(3, rel_rot_rad / np.sqrt(2)), np.full(3, rel_trans_m / np.sqrt(2)), 0, 0, 0.0)


def relative_poses(sample: np.ndarray, t_ns: np.ndarray, R: np.ndarray, p: np.ndarray, noise: PoseNoise,
                   spans_s: Sequence[float], max_gap_s: float, label: str):
    """(:class:`RelativePoses` over ``spans_s`` (:func:`span_pairs`) with per-pair sigmas
    (:func:`pair_sigmas`), the counts for the summary) of rows at IMU samples ``sample`` with body
    poses ``R``, ``p`` in the aiding's world."""
    i, j, which = span_pairs((np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9, spans_s, max_gap_s)
    R_ij = np.einsum("nki,nkj->nij", R[i], R[j])  # Ri^T Rj
    t_ij = np.einsum("nki,nk->ni", R[i], p[j] - p[i])
    spans = np.asarray(spans_s, dtype=np.float64)
    inflate = np.where(spans[which] > 0, np.sqrt(max(1, int(np.sum(spans > 0)))), 1.0)
    sig = pair_sigmas(t_ij, noise, inflate[:, None])
    rot, trans = float(np.median(sig[:, :3])), float(np.median(sig[:, 3:]))
    text = (f"{label}: relative poses over spans {', '.join(f'{s:g}' for s in spans_s)} s, median sigma "
            f"{np.rad2deg(rot):.3g} deg / {trans:.3g} m")
    a = RelativePoses(sample[i], sample[j], R_ij, t_ij, rot, trans, text, sigmas=sig)
    consecutive = len(run_starts(t_ns, max_gap_s))
    counts = {"relative_poses": int(len(i)), "relative_poses_per_span": np.bincount(which, minlength=len(spans_s)).tolist(),
              "not_chained_over_gaps": consecutive}
    return a, counts


def world_poses(sample: np.ndarray, R: np.ndarray, p: np.ndarray, noise: PoseNoise, label: str,
                causal_inflate: float = 1.0, rejoin: Optional[np.ndarray] = None) -> WorldPoses:
    """The rows' body poses ``R``, ``p`` in the aiding's world, tied to the graph through its free world
    frame (:class:`WorldPoses`), each with its per-pose noise, times ``causal_inflate`` in the causal
    solver (:func:`world_inflation`); on the rows where ``rejoin`` (:func:`rejoining`) their translation's
    times :data:`REJOIN_INFLATE` (at most ``causal_inflate``), their rotation's still times ``causal_inflate``:
    ten rows at their own rotation noise outweigh the world's attitude (its ~1700 inflated rows hold it to
    ~0.1 deg) and turned the world toward the coast's."""
    sig = np.tile(np.r_[np.asarray(noise.rot_rad, dtype=np.float64), np.asarray(noise.trans_m, dtype=np.float64)],
                  (len(sample), 1))
    causal = None
    if causal_inflate != 1.0 or (rejoin is not None and np.any(rejoin)):
        causal = causal_inflate * sig
        if rejoin is not None:
            rows = np.asarray(rejoin, dtype=bool)
            causal[rows, 3:] = min(REJOIN_INFLATE, float(causal_inflate)) * sig[rows, 3:]
    more = f", causal sigmas x{causal_inflate:.3g}" if causal_inflate != 1.0 else ""
    return WorldPoses(np.asarray(sample), np.asarray(R), np.asarray(p), sig,
                      f"{label}: poses in the aiding's world (a free frame{more})", causal_sigmas=causal)


def rejoining(t_ns: np.ndarray, max_gap_s: float, within_s: float = REJOIN_S) -> np.ndarray:
    """(M,) the rows at stamps ``t_ns`` less than ``within_s`` after the end of a break (consecutive rows
    more than ``max_gap_s`` apart): the causal solver weighs their world positions at :data:`REJOIN_INFLATE`
    times their own noise, so that the state a coast through the break left comes back onto the map
    (module docstring)."""
    t = np.asarray(t_ns, dtype=np.int64)
    starts = run_starts(t, max_gap_s)
    run = np.searchsorted(starts, np.arange(len(t)), side="right")  # 0 before the first break
    if not len(starts):
        return np.zeros(len(t), bool)
    return (run > 0) & ((t - t[starts[np.maximum(run - 1, 0)]]) * 1e-9 < within_s)


def world_inflation(t_ns: np.ndarray, correlation_s: float = WORLD_CORRELATION_S) -> float:
    """The factor on each world pose's sigmas: sqrt(rate x ``correlation_s``), the aiding's median rate from
    its stamps ``t_ns`` (module docstring; 1 for fewer than two rows)."""
    dt = np.diff(np.asarray(t_ns, dtype=np.int64)) * 1e-9
    dt = dt[dt > 0]
    return float(np.sqrt(max(1.0, correlation_s / float(np.median(dt))))) if len(dt) else 1.0
