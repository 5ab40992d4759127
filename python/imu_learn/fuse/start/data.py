"""The experiment runner's first state from the data (``init = "data"``, the default): no ground truth
at run time, as the navigator (:mod:`imu_learn.fuse.navigate`) starts a user's recording.

* **Roll and pitch** are levelled from the accelerometer. Where the recording comes to rest within its
  first 30 s (:func:`.level.first_rest`: EuRoC's machine-hall flights sit on the ground after a hand-held
  excitation), the run starts there: levelled over the rest, the gyro's mean there is the gyro bias
  prior's mean, velocity zero (a static alignment). Otherwise it starts at the first sample, levelled
  over the first seconds (:func:`.level.attitude_from_accelerometer`; the motion tilts it).
* **Position fixes** (simulated GNSS, a laser tracker) fix position but not heading, and a drone or a
  hand-held rig does not move along its x-axis, so the car's "heading from the track" does not apply.
  The heading comes from **competing yaw hypotheses** (in-motion alignment): the alignment window,
  from the first sample to the first fix at least ``min_travel_m`` (horizontally) from the first fix
  and no earlier than the ``min_fixes``-th fix, is fused once per yaw of ``n_yaw`` evenly spaced over
  the circle (batch: a heading prior loose enough, ``1.5 pi / n_yaw``, for each to settle inside its
  own basin; roll and pitch held to the levelling's :data:`LEVEL_SIGMA_DEG`); the hypothesis whose
  smoothed trajectory lies closest to the fixes (RMS of the fix residuals) wins. Its smoothed first
  state (pose, velocity) starts the run, whose estimates **are scored only from the window's last fix
  on**: every scored estimate uses no fix later than its own time (inside the window the heading
  came from fixes still to come, so it is not scored).
* **Relative poses** (simulated odometry) leave heading and position unobservable (a gauge): the run
  starts at the first sample with zero yaw at the origin, and is scored after a rigid SE(3)
  alignment to ground truth (Umeyama, no scale: ``evo_ape -a``), as the navigator scores relative aiding.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Dict, Optional, Tuple

import numpy as np

from imu_learn.core.still import MIN_STILL_START_S
from imu_learn.errors import InvalidInputError

from ..aiding import PositionFixes, RelativePoses
from ..graph import fuse
from ..settings import FusionSettings, PriorSigmas
from . import level as initial
from .types import Start

# The first state's prior after the alignment: roll and pitch levelled (3 deg), position from the fixes;
# the heading as loose as a hypothesis' basin (1.5 pi / n_yaw, 34 deg with 8): a short window of fixes
# leaves it tens of degrees off where the gyro bias is unknown (measured on EuRoC, docs/fusion.md), and the
# later fixes must be free to move it.
ALIGNED_PRIOR = PriorSigmas(rot_rad=float(np.deg2rad(3.0)), pos_m=0.1, vel_mps=0.2)
# Relative aiding: the gauge (yaw, position) pinned where it was put; roll/pitch from levelling.
RELATIVE_PRIOR = PriorSigmas(rot_rad=float(np.deg2rad(2.0)), pos_m=1e-3, vel_mps=0.5)
STILL_VEL_MPS = 0.05
# Roll and pitch levelled from the accelerometer over the first seconds while moving are good to a few
# degrees (the vehicle's own accelerations tilt them): their prior in the alignment window.
LEVEL_SIGMA_DEG = 3.0


@dataclass(frozen=True)
class AlignSettings:
    n_yaw: int = 8
    min_travel_m: float = 2.0
    min_fixes: int = 3
    level_s: float = 2.0

    def tag(self) -> str:
        """What the runs' hashes carry of these settings."""
        return f"data-v2-yaw{self.n_yaw}-travel{self.min_travel_m:g}-fixes{self.min_fixes}-level{self.level_s:g}"


def alignment_window(fixes: PositionFixes, min_travel_m: float, min_fixes: int) -> int:
    """The number of the fix that ends the alignment window (module docstring)."""
    d = np.linalg.norm(fixes.p[:, :2] - fixes.p[0, :2], axis=1)
    ok = (d >= min_travel_m) & (np.arange(len(d)) >= min_fixes - 1)
    if not ok.any():
        raise InvalidInputError(f"{fixes.label}: the fixes never move {min_travel_m:g} m from the first one "
                                f"({len(d)} fixes, at most {d.max():.2f} m): the heading cannot be aligned")
    return int(np.flatnonzero(ok)[0])


def _fix_residual_rms(res, fixes: PositionFixes) -> float:
    """RMS [m] of the smoothed trajectory's lever-arm point against the fixes (every fix a keyframe)."""
    pos = {int(k): n for n, k in enumerate(res.kf_idx)}
    rows = [pos[int(i)] for i in fixes.idx]
    p = res.smoothed_p[rows] + np.einsum("nij,j->ni", res.smoothed_R[rows], fixes.lever)
    return float(np.sqrt(np.mean(np.sum((p - fixes.p) ** 2, axis=1))))


def yaw_hypotheses(imu: tuple, fixes: PositionFixes, R_level: np.ndarray, still: bool, bias0: np.ndarray,
                   fusion: FusionSettings, settings: AlignSettings) -> Tuple[int, object, Dict[str, object]]:
    """(window's last sample, the winning hypothesis' FusionResult over the window, info), from the
    IMU ``imu`` = (t_ns, gyro, acc, per-sample variances or None) fused under ``fusion`` (its noise,
    gravity and keyframes; each hypothesis its own prior, over the whole window). Each hypothesis
    starts at zero velocity, held to it at rest and loosely (2 m/s) otherwise."""
    t_ns, gyro, acc, var = imu
    e = alignment_window(fixes, settings.min_travel_m, settings.min_fixes)
    end = int(fixes.idx[e])
    win = fixes.select(np.arange(len(fixes)) <= e)
    sl = slice(0, end + 1)
    prior = PriorSigmas(rot_rad=float(np.deg2rad(LEVEL_SIGMA_DEG)), yaw_rad=1.5 * np.pi / settings.n_yaw,
                        pos_m=max(5 * fixes.sigma_m, 1.0), vel_mps=STILL_VEL_MPS if still else 2.0)
    fusion = replace(fusion, prior=prior, lag_s=np.inf)
    fits = []
    for yaw in np.arange(settings.n_yaw) * 2 * np.pi / settings.n_yaw:
        R0 = initial.rot_z(float(yaw)) @ R_level
        p0 = fixes.p[0] - R0 @ fixes.lever
        try:
            res = fuse(t_ns[sl], gyro[sl], acc[sl], (R0, p0, np.zeros(3)), [win], fusion, bias0=bias0,
                       var=None if var is None else var[sl])
        except RuntimeError:  # GTSAM could not solve this hypothesis: it does not win
            continue
        fits.append((_fix_residual_rms(res, win), float(yaw), res))
    if not fits:
        raise InvalidInputError(f"{fixes.label}: no yaw hypothesis could be fused over the alignment window")
    fits.sort(key=lambda f: f[0])
    best_rms, best_yaw, best = fits[0]
    info = {"heading_source": f"{settings.n_yaw} yaw hypotheses fused over the first {e + 1} fixes "
                              f"({(t_ns[end] - t_ns[0]) * 1e-9:.1f} s, {settings.min_travel_m:g} m of travel); "
                              f"the best fits them to {best_rms:.3f} m RMS (next {fits[1][0]:.3f} m)"
                              if len(fits) > 1 else "one yaw hypothesis solved",
            "alignment_window_s": round(float((t_ns[end] - t_ns[0]) * 1e-9), 3),
            "winning_start_yaw_deg": round(float(np.rad2deg(best_yaw)), 1)}
    return end, best, info


def data_start(t_ns, gyro, acc, aiding, fusion: FusionSettings, bias0: Optional[np.ndarray] = None,
               var: Optional[np.ndarray] = None, settings: AlignSettings = AlignSettings()) -> Start:
    """The first state of one run from its IMU samples and its aiding alone (module docstring); the
    yaw hypotheses are fused with ``fusion``'s noise, gravity and keyframes."""
    b0 = np.zeros(6) if bias0 is None else np.asarray(bias0, dtype=np.float64)
    s0, R_level, still, info = level_start(t_ns, gyro, acc, fusion.gravity, b0, bias0 is None, settings)
    if isinstance(aiding, RelativePoses):
        v = np.zeros(3)
        info["velocity_source"] = "zero (at rest)"
        first = np.flatnonzero(aiding.i >= s0)
        if not still and len(first):
            k = int(first[0])
            dt = (t_ns[aiding.j[k]] - t_ns[aiding.i[k]]) * 1e-9
            v = R_level @ aiding.t_ij[k] / max(dt, 1e-3)
            info["velocity_source"] = f"the first relative pose's translation over {dt:.2f} s"
        info["heading_source"] = "zero yaw at the origin (relative aiding: a gauge; scores SE(3)-aligned)"
        prior = replace(RELATIVE_PRIOR, vel_mps=STILL_VEL_MPS if still else RELATIVE_PRIOR.vel_mps)
        return Start(s0, s0, R_level, np.zeros(3), v, b0, prior, True, info)
    if not isinstance(aiding, PositionFixes):
        raise InvalidInputError(f"init = \"data\": no data start for {type(aiding).__name__} aiding")
    fixes = aiding.since(s0)
    sl = slice(s0, None)
    end, res, h_info = yaw_hypotheses((t_ns[sl], gyro[sl], acc[sl], None if var is None else var[sl]), fixes, R_level,
                                      still, b0, fusion, settings)
    info.update(h_info)
    info["position_source"] = info["velocity_source"] = "the winning hypothesis' smoothed first state"
    info["scored_from_s"] = round(float((t_ns[s0 + end] - t_ns[0]) * 1e-9), 3)
    prior = replace(ALIGNED_PRIOR, yaw_rad=1.5 * np.pi / settings.n_yaw,
                    vel_mps=STILL_VEL_MPS if still else ALIGNED_PRIOR.vel_mps)
    return Start(s0, s0 + end, res.smoothed_R[0], res.smoothed_p[0], res.smoothed_v[0], b0, prior, False, info)


def level_start(t_ns, gyro, acc, gravity: float, b0: np.ndarray, gyro_bias_from_rest: bool, settings: AlignSettings
                ) -> Tuple[int, np.ndarray, bool, Dict[str, object]]:
    """(first fused sample, levelled attitude there (zero yaw), at rest, info); ``b0`` takes the gyro's
    mean at rest as its gyro part when ``gyro_bias_from_rest``."""
    rest = initial.first_rest(t_ns, gyro, acc, gravity)
    if rest is None:
        R_level, info = initial.attitude_from_accelerometer(t_ns, gyro, acc, gravity, acc_bias=b0[3:],
                                                            level_s=settings.level_s)
        return 0, R_level, info["still_s"] >= MIN_STILL_START_S, info
    a, e = rest
    _, _, R_level = initial.level(acc[a:e].mean(axis=0) - b0[3:])
    if gyro_bias_from_rest:
        b0[:3] = gyro[a:e].mean(axis=0)
    info = {"attitude_source": f"at rest from {(t_ns[a] - t_ns[0]) * 1e-9:.2f} s for {(t_ns[e] - t_ns[a]) * 1e-9:.2f} s: "
                               "accelerometer averaged over it; the run starts there",
            "still_s": round(float((t_ns[e] - t_ns[a]) * 1e-9), 3),
            "gyro_bias_source": "the gyro's mean at rest" if gyro_bias_from_rest else "the scenario's bias prior"}
    return a, R_level, True, info
