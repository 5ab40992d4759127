"""The navigator's aiding kinds (``--aiding-kind``), one class each behind :data:`KINDS`: what its
rows carry, how the run starts from them, its default sigmas (the options that set them) and the
graph's aiding object it builds from them. A new kind is one class here.

* ``position`` (:class:`PositionKind`): position fixes (or geodetic fixes, with their own sigmas);
  the start is levelled then headed along the track (:func:`..start.aiding.position_start`),
  moving; an extrinsic's translation is the antenna's lever arm.
* ``pose`` (:class:`PoseKind`): absolute body poses, rotated into the navigation frame.
* ``relative-pose`` (:class:`RelativePoseKind`): the motion between consecutive poses and, where
  the aiding has no breaks or its breaks keep one map (:mod:`.maps`), each pose in the aiding's own
  world, one free state (:mod:`.spans`).

Both pose kinds start from the first pose row (:func:`..start.aiding.pose_start`), at rest when the
IMU was still there."""
from __future__ import annotations

from dataclasses import replace
from typing import Dict, Optional, Tuple

import numpy as np

from ..start.aiding import pose_start, position_start
from ..start.types import Start
from .estimate import summary_entry
from .spans import given_noise, rejoining, relative_poses, unbroken, world_inflation, world_poses
from .types import AbsolutePoses, AidingRows, PositionFixes


class AidingKind:
    """One ``--aiding-kind``. ``poses``: its rows are body poses (orientation read, time offset and
    noise estimated), else positions; ``moving_start``: the run starts moving (no at-rest velocity
    prior); ``aligned``: scored after a rigid alignment (its world is not the ground truth's);
    ``lever``: an extrinsic's translation is the antenna's lever arm; ``geodetic``: takes geodetic
    fixes. ``sigma_rot_option`` / ``sigma_m_option``: the options ``--sigma-rot-deg`` /
    ``--sigma-m`` set."""

    name = ""
    poses = True
    moving_start = False
    aligned = True
    lever = False
    geodetic = False
    sigma_rot_option = "pose_sigma_rot_deg"
    sigma_m_option = "pose_sigma_m"

    def start(self, imu: tuple, rows: AidingRows, lever: np.ndarray, bias0: np.ndarray, opts) -> Start:
        """The first state from the IMU ``imu`` (t_ns, gyro, acc as fused) and the rows."""
        t_ns, gyro, acc = imu
        return pose_start(t_ns, gyro, acc, rows, int(rows.sample[0]), bias0, opts.gravity, opts.level_s)

    def build(self, rows: AidingRows, s0: int, R_WA: np.ndarray, lever: np.ndarray, opts, label: str,
              source: str, gnss=None) -> Tuple[object, Dict[str, object]]:
        """(the graph's aiding object for the rows, sample indices counted from ``s0`` (the first
        fused sample), the summary's counts)."""
        raise NotImplementedError


class PositionKind(AidingKind):
    name = "position"
    poses = False
    moving_start = True
    aligned = False
    lever = True
    geodetic = True
    sigma_m_option = "position_sigma_m"

    def start(self, imu: tuple, rows: AidingRows, lever: np.ndarray, bias0: np.ndarray, opts) -> Start:
        t_ns, gyro, acc = imu
        return position_start(t_ns, gyro, acc, rows, lever, bias0, opts.gravity, opts.level_s, body_x_forward=opts.nhc)

    def build(self, rows, s0, R_WA, lever, opts, label, source, gnss=None):
        # fixes before the start (the track heading's first fast fix) are left out
        idx = rows.sample
        fixes = gnss if gnss is not None else PositionFixes(
            idx, rows.p @ R_WA.T, float(opts.position_sigma_m), np.asarray(lever, dtype=np.float64),
            f"{label}: positions, sigma {opts.position_sigma_m:g} m", source)
        return fixes.since(s0), {"position_fixes": int((idx >= s0).sum()), "fixes_before_start": int((idx < s0).sum())}


class PoseKind(AidingKind):
    name = "pose"

    def build(self, rows, s0, R_WA, lever, opts, label, source, gnss=None):
        idx = rows.sample
        R = np.einsum("ij,njk->nik", R_WA, rows.R)
        p = rows.p @ R_WA.T
        a = AbsolutePoses(idx, R, p, float(np.deg2rad(opts.pose_sigma_rot_deg)), float(opts.pose_sigma_m),
                          f"{label}: absolute poses, sigma {opts.pose_sigma_rot_deg:g} deg / {opts.pose_sigma_m:g} m",
                          source).since(s0)
        return a, {"absolute_poses": int(len(idx)), "aiding_estimates": summary_entry(rows, None, "")}


class RelativePoseKind(AidingKind):
    name = "relative-pose"
    sigma_rot_option = "rel_sigma_rot_deg"
    sigma_m_option = "rel_sigma_trans_m"

    def build(self, rows, s0, R_WA, lever, opts, label, source, gnss=None):
        whole = unbroken(rows.t_ns, opts.max_relative_gap_s)
        noise, source = relative_noise(rows, opts, whole)
        a, counts = relative_poses(rows.sample, rows.t_ns, rows.R, rows.p, noise,
                                   opts.relative_spans_s if whole else (0.0,), opts.max_relative_gap_s, label)
        # breaks in one map (.maps: each checked against the IMU's dead reckoning): every run tied to the one
        # world, with the noise estimated, in the causal solver weighed as the map's slow error (.spans)
        one_map = not whole and bool(getattr(rows.maps, "verdict", False))
        if (whole or one_map) and opts.relative_world:  # each pose also in the aiding's own world, a free state
            wn = noise if whole else relative_noise(rows, opts, True)[0]
            inflate = world_inflation(rows.t_ns) if one_map else 1.0
            rejoin = rejoining(rows.t_ns, opts.max_relative_gap_s) if one_map else None
            a = replace(a, world=world_poses(rows.sample, rows.R, rows.p, wn, label, inflate, rejoin))
            counts["world_poses"] = len(rows.sample)
        return a.since(s0), {**counts, "aiding_estimates": summary_entry(rows, noise, source)}


def relative_noise(rows: AidingRows, opts, whole: bool = True):
    """(each pose's noise, where it came from): ``--sigma-rot-deg`` / ``--sigma-m`` where given (a
    relative pose's sigmas, each pose's = over sqrt(2)), else for an unbroken aiding (``whole``, tied
    to its world) the noise estimated against the IMU (:mod:`.noise`), else the defaults (a
    relative pose's 0.003 m / 0.05 deg: consecutive poses alone fused better at them than at the
    estimate, docs/experiments/navigate-vo.md). ``opts``: the navigator's options (their class's
    defaults tell what was given)."""
    d = type(opts)()
    given = (opts.rel_sigma_rot_deg != d.rel_sigma_rot_deg) or (opts.rel_sigma_trans_m != d.rel_sigma_trans_m)
    if rows.noise is not None and not given and whole:
        return rows.noise, "estimated"
    return (given_noise(float(np.deg2rad(opts.rel_sigma_rot_deg)), float(opts.rel_sigma_trans_m)),
            "given" if given else "default")


# every kind by its name, in the order the CLI lists them
KINDS: Dict[str, AidingKind] = {k.name: k for k in (PositionKind(), PoseKind(), RelativePoseKind())}
GEODETIC_KIND = next(k.name for k in KINDS.values() if k.geodetic)  # what geodetic fixes are


def kind_of(name: Optional[str]) -> Optional[AidingKind]:
    """The kind named ``name``; None for no or an unknown name (:meth:`NavigateOptions.check` refuses it)."""
    return KINDS.get(name) if name is not None else None
