"""The aiding measurements the factor graph takes, each tied to IMU sample indices: position fixes
(:class:`PositionFixes`, and :class:`GnssFixes` with per-fix sigmas), relative poses
(:class:`RelativePoses`), absolute poses (:class:`AbsolutePoses`) and poses in the aiding's own
world, a free state of the graph (:class:`WorldPoses`, held by :class:`RelativePoses`). Each subsets with
:meth:`select` (every per-measurement array together, dropped measurements counted) and is
re-indexed from a run's first fused sample with :meth:`since`; :meth:`tied_samples` names the IMU
samples its measurements are tied to and :meth:`factors_by_sample` hands the factor graph
(:mod:`imu_learn.fuse.graph`) their factors' ingredients: a new aiding type is one class here."""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Dict, List, Optional, Union

import numpy as np

from imu_learn.errors import AidingError, InvalidInputError


@dataclass(frozen=True)
class PositionFixes:
    """Positions of a point ``lever`` [m] (body frame) in the world frame at IMU samples ``idx``.
    ``source``: the file they were read from ("" when simulated). ``dropped_outside`` /
    ``dropped_unmatched``: real fixes left out because they lie outside the IMU's time span / have
    no IMU sample of their own (see the module's time rules); ``dropped_outage``: fixes removed by
    :func:`apply_outages`."""

    idx: np.ndarray
    p: np.ndarray
    sigma_m: float
    lever: np.ndarray
    label: str
    source: str = ""
    dropped_outside: int = 0
    dropped_unmatched: int = 0
    dropped_outage: int = 0

    def __len__(self) -> int:
        return len(self.idx)

    def select(self, keep: np.ndarray, dropped_outage: int = 0) -> PositionFixes:
        """The fixes where ``keep`` (M,) is True; ``dropped_outage`` is added to the count."""
        keep = np.asarray(keep, dtype=bool)
        return replace(self, idx=self.idx[keep], p=self.p[keep], dropped_outage=self.dropped_outage + int(dropped_outage))

    def since(self, s0: int) -> PositionFixes:
        """The fixes from sample ``s0`` on, their indices counted from it (a run's first fused sample)."""
        if s0 == 0:
            return self
        kept = self.select(self.idx >= s0)
        return replace(kept, idx=kept.idx - s0)

    def tied_samples(self) -> List[np.ndarray]:
        """The IMU samples the fixes are tied to (the graph makes each a keyframe)."""
        return [self.idx]

    def factors_by_sample(self, fixes_at: Dict[int, List], between_at: Dict[int, List]) -> None:
        """Each fix into ``fixes_at`` as ``{s: [(p, lever, model)]}`` (the graph's position factors)."""
        import gtsam

        model = gtsam.noiseModel.Isotropic.Sigma(3, self.sigma_m)
        # Per-fix sigmas (M, 3) where the aiding has them (GnssFixes), else sigma_m.
        sig = getattr(self, "sigmas", None)
        if sig is not None and np.shape(sig) != (len(self.idx), 3):
            raise InvalidInputError(f"{self.label}: per-fix sigmas {np.shape(sig)}, expected ({len(self.idx)}, 3)")
        for n, (s, p) in enumerate(zip(self.idx, self.p)):
            m = model if sig is None else gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sig[n], dtype=np.float64))
            fixes_at.setdefault(int(s), []).append((p, self.lever, m))


@dataclass(frozen=True)
class RelativePoses:
    """Body pose at sample ``j`` relative to sample ``i``: rotation ``R_ij`` and translation
    ``t_ij`` (in frame i), with isotropic rotation [rad] and translation [m] sigmas, or per pair and
    axis ``sigmas`` (M, 6): rotation [rad] then translation [m], in frame i (the graph then builds a
    diagonal noise model per pair; ``sigma_rot_rad`` and ``sigma_trans_m`` are then only a label)."""

    i: np.ndarray
    j: np.ndarray
    R_ij: np.ndarray
    t_ij: np.ndarray
    sigma_rot_rad: float
    sigma_trans_m: float
    label: str
    dropped_outage: int = 0  # relative poses removed by apply_outages
    sigmas: Optional[np.ndarray] = None
    # the same rows' poses tied to the aiding's own world, a free state of the graph (:class:`WorldPoses`)
    world: Optional[WorldPoses] = None

    def __len__(self) -> int:
        return len(self.i) + (0 if self.world is None else len(self.world))

    def select(self, keep: np.ndarray, dropped_outage: int = 0) -> RelativePoses:
        """The relative poses where ``keep`` (M,) is True; ``dropped_outage`` is added to the count; of
        :attr:`world`, the poses at a dropped pair's end and no kept pair's are dropped too."""
        keep = np.asarray(keep, dtype=bool)
        i, j = self.i[keep], self.j[keep]
        world = self.world
        if world is not None:
            w = world.idx
            world = world.select(~(np.isin(w, np.r_[self.i[~keep], self.j[~keep]]) & ~np.isin(w, np.r_[i, j])))
        return replace(self, i=i, j=j, R_ij=self.R_ij[keep], t_ij=self.t_ij[keep],
                       dropped_outage=self.dropped_outage + int(dropped_outage),
                       sigmas=None if self.sigmas is None else self.sigmas[keep], world=world)

    def since(self, s0: int) -> RelativePoses:
        """The relative poses starting from sample ``s0`` on, their indices counted from it."""
        if s0 == 0:
            return self
        kept = self.select(self.i >= s0)
        return replace(kept, i=kept.i - s0, j=kept.j - s0, world=None if kept.world is None else kept.world.since(s0))

    def tied_samples(self) -> List[np.ndarray]:
        """The IMU samples the relative poses are tied to: both ends (and :attr:`world`'s)."""
        return [self.i, self.j] + ([] if self.world is None else self.world.tied_samples())

    def factors_by_sample(self, fixes_at: Dict[int, List], between_at: Dict[int, List]) -> None:
        """Each relative pose into ``between_at`` at its later end as ``{j: [(i, Pose3, model)]}``
        (and :attr:`world`'s poses)."""
        import gtsam

        model = gtsam.noiseModel.Diagonal.Sigmas(np.r_[[self.sigma_rot_rad] * 3, [self.sigma_trans_m] * 3])
        sig = self.sigmas  # per pair and axis (M, 6), where the aiding has them
        for n, (i, j, R, t) in enumerate(zip(self.i, self.j, self.R_ij, self.t_ij)):
            m = model if sig is None else gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sig[n], dtype=np.float64))
            between_at.setdefault(int(j), []).append((int(i), gtsam.Pose3(gtsam.Rot3(R), t), m))
        if self.world is not None:
            self.world.factors_by_sample(fixes_at, between_at)


# between_at's first element for a pose tied to the aiding's own world (:class:`WorldPoses`)
WORLD = "world"


class _PosesAtSamples:
    """What poses tied to one IMU sample each (``idx``) share: ``i`` and ``j`` are both ``idx``,
    their count, and :meth:`since` (the subclass's :meth:`select`, re-indexed from ``s0``)."""

    idx: np.ndarray

    @property
    def i(self) -> np.ndarray:
        return self.idx

    @property
    def j(self) -> np.ndarray:
        return self.idx

    def __len__(self) -> int:
        return len(self.idx)

    def since(self, s0: int):
        """The poses from sample ``s0`` on, their indices counted from it."""
        if s0 == 0:
            return self
        kept = self.select(self.idx >= s0)
        return replace(kept, idx=kept.idx - s0)


@dataclass(frozen=True)
class WorldPoses(_PosesAtSamples):
    """Body poses ``R`` (M, 3, 3), ``p`` (M, 3) at IMU samples ``idx`` in the aiding's own world A,
    tied to the navigation frame through one more state of the graph, A's pose in it (``X_k = T_WA
    Z_k``; no prior on it: a free world frame, estimated online with the rest, the first pose's
    prior and gravity fixing it). Per pose and body axis ``sigmas`` (M, 6): rotation [rad] then
    translation [m]. A SLAM trajectory's global consistency thereby reaches the causal estimate,
    as it is, where relative poses carry it over long spans only (docs/experiments/navigate-vo.md)."""

    idx: np.ndarray
    R: np.ndarray
    p: np.ndarray
    sigmas: np.ndarray
    label: str
    dropped_outage: int = 0
    # (M, 6) or None: the causal solver's sigmas (None: ``sigmas``); the batch smoothing pass takes ``sigmas``.
    # :func:`.spans.world_poses` sets them to ``sigmas`` times the map's slow error, less on the rows that rejoin
    # the map after a break (:mod:`.spans`)
    causal_sigmas: Optional[np.ndarray] = None

    def select(self, keep: np.ndarray, dropped_outage: int = 0) -> WorldPoses:
        """The poses where ``keep`` (M,) is True; ``dropped_outage`` is added to the count."""
        keep = np.asarray(keep, dtype=bool)
        return replace(self, idx=self.idx[keep], R=self.R[keep], p=self.p[keep], sigmas=self.sigmas[keep],
                       dropped_outage=self.dropped_outage + int(dropped_outage),
                       causal_sigmas=None if self.causal_sigmas is None else self.causal_sigmas[keep])

    def tied_samples(self) -> List[np.ndarray]:
        """The IMU samples the poses are tied to."""
        return [self.idx]

    def factors_by_sample(self, fixes_at: Dict[int, List], between_at: Dict[int, List]) -> None:
        """Each pose into ``between_at`` at its sample as ``{s: [(WORLD, Pose3, (causal model, smoothing
        model))]}``."""
        import gtsam

        causal_sigmas = self.sigmas if self.causal_sigmas is None else self.causal_sigmas
        for name, sig in (("sigmas", self.sigmas), ("causal sigmas", causal_sigmas)):
            if np.shape(sig) != (len(self.idx), 6):
                raise InvalidInputError(f"{self.label}: per-pose {name} {np.shape(sig)}, expected ({len(self.idx)}, 6)")
        for s, R, t, sig, causal_sig in zip(self.idx, self.R, self.p, self.sigmas, causal_sigmas):
            smoothed = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sig, dtype=np.float64))
            causal = (smoothed if np.array_equal(causal_sig, sig)
                      else gtsam.noiseModel.Diagonal.Sigmas(np.asarray(causal_sig, dtype=np.float64)))
            between_at.setdefault(int(s), []).append((WORLD, gtsam.Pose3(gtsam.Rot3(R), t), (causal, smoothed)))


@dataclass(frozen=True)
class AbsolutePoses(_PosesAtSamples):
    """Body poses in the navigation frame at IMU samples ``idx``: rotations ``R`` (M, 3, 3) and
    positions ``p`` (M, 3), e.g. a camera trajectory moved into the IMU frame and its world rotated
    into the navigation frame (:mod:`imu_learn.fuse.navigate`); isotropic rotation [rad] and
    translation [m] sigmas. Each becomes a prior factor on its keyframe's pose. ``i`` and ``j`` are
    both ``idx`` (the keyframe rule reads every non-position aiding's samples from them).
    The navigator drops the rows inside its gaps before it builds them."""

    idx: np.ndarray
    R: np.ndarray
    p: np.ndarray
    sigma_rot_rad: float
    sigma_trans_m: float
    label: str
    source: str = ""
    dropped_outage: int = 0

    def select(self, keep: np.ndarray, dropped_outage: int = 0) -> AbsolutePoses:
        """The poses where ``keep`` (M,) is True; ``dropped_outage`` is added to the count."""
        keep = np.asarray(keep, dtype=bool)
        return replace(self, idx=self.idx[keep], R=self.R[keep], p=self.p[keep],
                       dropped_outage=self.dropped_outage + int(dropped_outage))

    def tied_samples(self) -> List[np.ndarray]:
        """The IMU samples the poses are tied to (``i`` and ``j``, both ``idx``)."""
        return [self.i, self.j]

    def factors_by_sample(self, fixes_at: Dict[int, List], between_at: Dict[int, List]) -> None:
        """Each pose into ``between_at`` as a pose prior at its sample: ``{s: [(None, Pose3, model)]}``."""
        import gtsam

        model = gtsam.noiseModel.Diagonal.Sigmas(np.r_[[self.sigma_rot_rad] * 3, [self.sigma_trans_m] * 3])
        for s, R, t in zip(self.idx, self.R, self.p):
            between_at.setdefault(int(s), []).append((None, gtsam.Pose3(gtsam.Rot3(R), t), model))


@dataclass(frozen=True)
class GnssFixes(PositionFixes):
    """:class:`PositionFixes` with per-fix sigmas: ``sigmas`` (M, 3) [m] along the world axes (the
    graph builds a diagonal noise model per fix from them; ``sigma_m`` is then only a label) and
    ``q`` (M,) the RTKLIB quality flag of each fix and ``epoch`` (M,) its row in the
    :class:`~imu_learn.fuse.aiding.rtklib.RtkSolution`. :meth:`select` subsets them with the fixes
    (dataclasses' ``replace`` alone would keep the per-fix arrays whole)."""

    sigmas: Optional[np.ndarray] = None
    q: Optional[np.ndarray] = None
    epoch: Optional[np.ndarray] = None

    def select(self, keep: np.ndarray, dropped_outage: int = 0) -> GnssFixes:
        keep = np.asarray(keep, dtype=bool)
        return GnssFixes(self.idx[keep], self.p[keep], self.sigma_m, self.lever, self.label, self.source,
                         self.dropped_outside, self.dropped_unmatched, self.dropped_outage + int(dropped_outage),
                         *(None if a is None else a[keep] for a in (self.sigmas, self.q, self.epoch)))


Aiding = Union[PositionFixes, RelativePoses, AbsolutePoses, WorldPoses]


def aiding_samples(aiding: Aiding) -> np.ndarray:
    """The IMU samples the aiding constrains, sorted, each once (a relative pose: both ends)."""
    return np.unique(np.concatenate(aiding.tied_samples()).astype(np.int64))


def aiding_gaps(aiding: Aiding, t_ns: np.ndarray) -> Dict[str, Optional[float]]:
    """Seconds without aiding, for the runner to record (JSON-ready): ``longest_s``, the longest
    time between consecutive aiding epochs, and ``longest_start_s`` where it starts (from the first
    sample; both None with fewer than two epochs); ``before_first_s`` from the first IMU sample to
    the first epoch and ``after_last_s`` from the last epoch to the last sample (each the whole
    span when there is no epoch)."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    span = (int(t_ns[-1]) - int(t_ns[0])) * 1e-9
    s = aiding_samples(aiding)
    out: Dict[str, Optional[float]] = {"longest_s": None, "longest_start_s": None, "before_first_s": span,
                                       "after_last_s": span}
    if len(s):
        t = t_ns[s]
        out["before_first_s"] = (int(t[0]) - int(t_ns[0])) * 1e-9
        out["after_last_s"] = (int(t_ns[-1]) - int(t[-1])) * 1e-9
    if len(s) >= 2:
        d = np.diff(t)
        k = int(np.argmax(d))
        out["longest_s"] = float(d[k]) * 1e-9
        out["longest_start_s"] = (int(t[k]) - int(t_ns[0])) * 1e-9
    return out


def check_aiding(aiding: Aiding, label: str) -> Aiding:
    """``aiding`` unchanged when it has at least one measurement; else :class:`AidingError` naming
    ``label`` (the recording and scenario), the aiding, and what removed its measurements."""
    if len(aiding) > 0:
        return aiding
    source = getattr(aiding, "source", "") or None
    dropped = [f"{n} {why}" for n, why in (
        (aiding.dropped_outage, "inside the outages"),
        (getattr(aiding, "dropped_outside", 0), "outside the IMU's time span"),
        (getattr(aiding, "dropped_unmatched", 0), "without an IMU sample of their own"),
    ) if n]
    why = f": dropped {', '.join(dropped)}" if dropped else ""
    raise AidingError(f"{label}: no aiding measurement left ({aiding.label}{', ' + source if source else ''}){why}",
                      source, label)


@dataclass
class AidingRows:
    """The aiding rows the run uses: their IMU sample (index into the full IMU), stamp, and body
    pose / position in the aiding's world A; ``dropped``: rows left out and why."""

    sample: np.ndarray
    t_ns: np.ndarray
    imu_t_ns: np.ndarray  # the stamp of each row's IMU sample (where the graph puts it)
    p: np.ndarray
    R: Optional[np.ndarray]
    dropped: Dict[str, int] = field(default_factory=dict)
    # estimated from the data (pose aiding): the time offset applied to the stamps
    # (:class:`.offset.AidingOffset`) and each pose's noise (:class:`.noise.PoseNoise`)
    offset: Optional[object] = None
    noise: Optional[object] = None
    frame: Optional[object] = None  # the frame check before the fusion (:class:`.frame.FrameCheck`)
    scale: Optional[object] = None  # the positions' metric scale (:class:`imu_learn.calib.metric_scale.ScaleFit`)
    maps: Optional[object] = None  # with breaks: whether they stay in one map (:class:`.maps.OneMap`)
    gravity: Optional[object] = None  # positions: their world's up (:class:`imu_learn.fuse.start.gravity.GravityCheck`)
