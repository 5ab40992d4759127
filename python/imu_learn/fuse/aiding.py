"""Aiding measurements for the factor graph, each tied to IMU sample indices.

Real: EuRoC's Leica MS50 laser tracker (a prism's position, 20 Hz; lever arm from its
``sensor.yaml``; read strictly by :func:`imu_learn.data.formats.asl.read_leica`), snapped to the nearest
IMU sample. Simulated from ground truth (seeded, and labelled as simulated in every table): a
GNSS-like position fix and a VO-like relative pose. Outages drop every measurement inside
configured time windows.

Time rules (tested in tests/test_fuse_aiding.py):

* A real fix stamped exactly at an IMU sample is tied to that sample; otherwise to the nearest one,
  and exactly halfway between two samples to the earlier. It is dropped (and counted in
  ``dropped_outside``) when stamped before the first or after the last IMU sample, never moved
  onto the end samples; and dropped (``dropped_unmatched``) inside the span when no IMU sample is
  within half the median sample period (an IMU gap), or when an earlier fix already took its sample.
  No fix inside the IMU's span at all is an :class:`AidingOverlapError`.
* Simulated epochs (and the graph's keyframe grid) take the first IMU sample at or after each
  grid time ``t_0 + k / rate_hz``: a grid time exactly at a sample is that sample, one exactly
  halfway between two samples the later. The grid starts at the first sample, so no simulated
  epoch lies outside the IMU's span.
* An outage window is clipped to the recording (:func:`clip_outages`); :func:`check_aiding` raises
  :class:`AidingError` when outages leave a scenario without any measurement, and
  :func:`aiding_gaps` gives the longest stretch without aiding for the runner to record.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Dict, List, Optional, Tuple, Union
from typing import Sequence as Seq

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.core.quat import wxyz_to_xyzw
from imu_learn.errors import AidingError, AidingOverlapError, InvalidInputError


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


@dataclass(frozen=True)
class RelativePoses:
    """Body pose at sample ``j`` relative to sample ``i``: rotation ``R_ij`` and translation
    ``t_ij`` (in frame i), with isotropic rotation [rad] and translation [m] sigmas."""

    i: np.ndarray
    j: np.ndarray
    R_ij: np.ndarray
    t_ij: np.ndarray
    sigma_rot_rad: float
    sigma_trans_m: float
    label: str
    dropped_outage: int = 0  # relative poses removed by apply_outages

    def __len__(self) -> int:
        return len(self.i)


Aiding = Union[PositionFixes, RelativePoses]


def epochs(t_ns: np.ndarray, rate_hz: float) -> np.ndarray:
    """Sample indices of a ``rate_hz`` grid starting at the first sample: for each grid time the
    first sample at or after it (a grid time exactly at a sample is that sample; one halfway
    between two samples is the later), each index once."""
    if not rate_hz > 0:
        raise InvalidInputError(f"aiding rate must be > 0 Hz, got {rate_hz!r}")
    period_ns = int(round(1e9 / rate_hz))
    grid = np.arange(int(t_ns[0]), int(t_ns[-1]) + 1, period_ns, dtype=np.int64)
    idx = np.clip(np.searchsorted(t_ns, grid), 0, len(t_ns) - 1)
    return np.unique(idx)


def simulate_position(t_ns, p_gt, rate_hz: float, sigma_m: float, rng: np.random.Generator) -> PositionFixes:
    """GNSS-like fixes: ground-truth position plus white Gaussian noise, every ``1/rate_hz`` s."""
    idx = epochs(t_ns, rate_hz)
    p = p_gt[idx] + rng.normal(0.0, sigma_m, size=(len(idx), 3))
    return PositionFixes(idx, p, float(sigma_m), np.zeros(3),
                         f"simulated position {rate_hz:g} Hz, sigma {sigma_m:g} m")


def simulate_relative_pose(t_ns, p_gt, q_wxyz_gt, rate_hz: float, sigma_rot_deg: float, sigma_trans_m: float,
                           rng: np.random.Generator) -> RelativePoses:
    """VO-like relative poses between consecutive ``rate_hz`` epochs: ground truth perturbed by a
    random rotation (axis-angle, sigma per axis) and a translation error (sigma per axis)."""
    idx = epochs(t_ns, rate_hz)
    i, j = idx[:-1], idx[1:]
    R = Rotation.from_quat(wxyz_to_xyzw(q_wxyz_gt))
    Ri, Rj = R[i], R[j]
    R_ij = (Ri.inv() * Rj)
    t_ij = Ri.inv().apply(p_gt[j] - p_gt[i])
    sig_r = np.deg2rad(sigma_rot_deg)
    R_noisy = R_ij * Rotation.from_rotvec(rng.normal(0.0, sig_r, size=(len(i), 3)))
    t_noisy = t_ij + rng.normal(0.0, sigma_trans_m, size=(len(i), 3))
    return RelativePoses(i, j, R_noisy.as_matrix(), t_noisy, float(sig_r), float(sigma_trans_m),
                         f"simulated relative pose {rate_hz:g} Hz, sigma {sigma_rot_deg:g} deg / {sigma_trans_m:g} m")


def snap_to_samples(imu_t_ns: np.ndarray, t_ns: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For stamps ``t_ns`` on the IMU's clock: the nearest IMU sample of each (a stamp exactly at a
    sample is that sample; exactly halfway between two, the earlier), whether the stamp lies inside
    the IMU's span [first, last sample], and whether it is within half the median sample period of
    its sample."""
    imu = np.asarray(imu_t_ns, dtype=np.int64)
    t = np.asarray(t_ns, dtype=np.int64)
    if len(imu) < 2:
        raise InvalidInputError(f"snapping needs at least 2 IMU samples, got {len(imu)}")
    half = int(np.median(np.diff(imu))) // 2
    k = np.clip(np.searchsorted(imu, t), 1, len(imu) - 1)
    nearest = np.where(np.abs(t - imu[k - 1]) <= np.abs(imu[k] - t), k - 1, k)
    inside = (t >= imu[0]) & (t <= imu[-1])
    close = np.abs(imu[nearest] - t) <= half
    return nearest, inside, close


def _span(t0: int, t1: int) -> str:
    return f"[{t0}, {t1}] ns ({(t1 - t0) * 1e-9:.3f} s)"


def leica_fixes(leica_t_ns, leica_p, lever, imu_t_ns, rate_hz: Optional[float], sigma_m: float,
                source: str = "") -> PositionFixes:
    """Real laser-tracker fixes on the IMU's clock: each tied to the nearest IMU sample (module
    docstring: fixes outside the IMU's span or without a sample within half a period are dropped
    and counted on the result), then thinned to at most one per ``1/rate_hz`` s (all when
    ``rate_hz`` is None). ``source``: the file the fixes were read from, for messages (row i of the
    arrays is line i + 2 of an ASL file). Raises :class:`AidingError` when there are no fixes and
    :class:`AidingOverlapError` when none lies inside the IMU's time span."""
    imu_t_ns = np.asarray(imu_t_ns, dtype=np.int64)
    leica_t_ns = np.asarray(leica_t_ns, dtype=np.int64)
    leica_p = np.asarray(leica_p, dtype=np.float64)
    rate = "20 Hz" if rate_hz is None else f"{rate_hz:g} Hz"
    label = f"Leica MS50 (real) {rate}, sigma {sigma_m:g} m"
    where = f"{source}: " if source else ""
    if leica_t_ns.ndim != 1 or leica_p.shape != (len(leica_t_ns), 3):
        raise InvalidInputError(f"{where}Leica stamps (N,) and positions (N, 3) expected, got "
                                f"{leica_t_ns.shape} and {leica_p.shape}")
    if rate_hz is not None and not rate_hz > 0:
        raise InvalidInputError(f"{where}Leica rate must be > 0 Hz or None (every fix), got {rate_hz!r}")
    if len(leica_t_ns) == 0:
        raise AidingError(f"{where}no Leica fixes (only a header?)", source or None, label)
    nearest, inside, close = snap_to_samples(imu_t_ns, leica_t_ns)
    if not inside.any():
        lines = f"lines 2-{len(leica_t_ns) + 1}: " if source else ""
        raise AidingOverlapError(
            f"{where}{lines}Leica fixes and IMU do not overlap in time: the fixes span "
            f"{_span(int(leica_t_ns[0]), int(leica_t_ns[-1]))}, the IMU {_span(int(imu_t_ns[0]), int(imu_t_ns[-1]))} "
            "(are both on the same clock and in ns? is the scenario's time_offset_s right?)",
            source or None, label)
    keep = inside & close
    if not keep.any():
        raise AidingError(f"{where}none of the {int(inside.sum())} Leica fixes inside the IMU's span "
                          "has an IMU sample within half a sample period", source or None, label)
    idx, p = nearest[keep], leica_p[keep]
    shared = 0
    if rate_hz is None:  # every fix; a second fix on one sample is dropped (not thinning)
        idx, first = np.unique(idx, return_index=True)
        shared = int(keep.sum()) - len(idx)
    else:  # the first fix of each 1/rate_hz bin (fixes sharing a sample share its bin)
        bins = (imu_t_ns[idx] - imu_t_ns[0]) // int(round(1e9 / rate_hz))
        _bins, first = np.unique(bins, return_index=True)
        idx = idx[first]
    return PositionFixes(idx, p[first], float(sigma_m), np.asarray(lever, dtype=np.float64), label, source,
                         dropped_outside=int((~inside).sum()),
                         dropped_unmatched=int((inside & ~close).sum()) + shared)


def outage_mask(t_ns: np.ndarray, outages: Seq[Tuple[float, float]]) -> np.ndarray:
    """True for samples inside an outage ``(start_s, duration_s)`` (seconds from the first sample;
    each window half-open, [start, start + duration)). A window running past either end of the
    recording covers only the samples it has (see :func:`clip_outages`)."""
    rel = (np.asarray(t_ns) - t_ns[0]) * 1e-9
    inside = np.zeros(len(t_ns), dtype=bool)
    for start, dur in outages:
        inside |= (rel >= start) & (rel < start + dur)
    return inside


def clip_outages(t_ns: np.ndarray, outages: Seq[Tuple[float, float]]) -> List[Tuple[float, float]]:
    """The outage windows ``(start_s, duration_s)`` as they act on this recording: each clipped to
    [0, the recording's duration] (seconds from the first sample), so a window running past the
    end ends at the last sample; a window that misses the recording entirely is left out."""
    span = (int(t_ns[-1]) - int(t_ns[0])) * 1e-9
    out = []
    for start, dur in outages:
        start, end = float(start), float(start) + float(dur)
        if start <= span and end > 0:  # [start, end) meets [0, span]
            out.append((max(start, 0.0), min(end, span) - max(start, 0.0)))
    return out


def apply_outages(aiding: Aiding, t_ns: np.ndarray, outages: Seq[Tuple[float, float]]) -> Aiding:
    """``aiding`` without the measurements inside any outage (a relative pose is dropped when
    either end is inside); how many it removed is added to ``dropped_outage``."""
    if not outages:
        return aiding
    inside = outage_mask(t_ns, outages)
    if isinstance(aiding, PositionFixes):
        keep = ~inside[aiding.idx]
        return replace(aiding, idx=aiding.idx[keep], p=aiding.p[keep],
                       dropped_outage=aiding.dropped_outage + int((~keep).sum()))
    keep = ~(inside[aiding.i] | inside[aiding.j])
    return replace(aiding, i=aiding.i[keep], j=aiding.j[keep], R_ij=aiding.R_ij[keep], t_ij=aiding.t_ij[keep],
                   dropped_outage=aiding.dropped_outage + int((~keep).sum()))


def aiding_samples(aiding: Aiding) -> np.ndarray:
    """The IMU samples the aiding constrains, sorted, each once (a relative pose: both ends)."""
    if isinstance(aiding, PositionFixes):
        return np.unique(np.asarray(aiding.idx, dtype=np.int64))
    return np.unique(np.concatenate([aiding.i, aiding.j]).astype(np.int64))


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


def bag_position_source(bag, topic: str, lever=(0.0, 0.0, 0.0)) -> Tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Real position fixes from a ROS bag topic (geometry_msgs/msg/PointStamped as EuRoC's Leica, or
    the position of a PoseStamped / TransformStamped / Odometry topic), in the form
    :func:`leica_fixes` takes: ``(t_ns, p, lever, source)``. ``lever``: the measured point in the
    body frame (a bag does not say it; the fuse config does). Header stamps; typed bag errors."""
    from imu_learn.data.formats.rosbag import read_positions

    t_ns, p = read_positions(bag, topic)
    lever_arm = np.asarray(lever, dtype=np.float64).reshape(3)
    return t_ns, p, lever_arm, f"{bag} topic {topic}"


@dataclass(frozen=True)
class AbsolutePoses:
    """Body poses in the navigation frame at IMU samples ``idx``: rotations ``R`` (M, 3, 3) and
    positions ``p`` (M, 3), e.g. a camera trajectory moved into the IMU frame and its world rotated
    into the navigation frame (:mod:`imu_learn.fuse.navigate`); isotropic rotation [rad] and
    translation [m] sigmas. Each becomes a prior factor on its keyframe's pose. ``i`` and ``j`` are
    both ``idx`` (the keyframe rule reads every non-position aiding's samples from them).
    :func:`apply_outages` does not take them: the navigator drops the rows inside its gaps first."""

    idx: np.ndarray
    R: np.ndarray
    p: np.ndarray
    sigma_rot_rad: float
    sigma_trans_m: float
    label: str
    source: str = ""
    dropped_outage: int = 0

    @property
    def i(self) -> np.ndarray:
        return self.idx

    @property
    def j(self) -> np.ndarray:
        return self.idx

    def __len__(self) -> int:
        return len(self.idx)
