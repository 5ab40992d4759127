"""What the navigator estimates about pose aiding from the data before it fuses: the aiding–IMU time
offset (:mod:`.offset`, applied to the aiding's stamps) and each pose's noise (:mod:`.noise`, the
relative poses' sigmas where none are given), and the summary's entry for both."""
from __future__ import annotations

import logging
from dataclasses import replace
from typing import Dict, Optional, Tuple

import numpy as np

from imu_learn.errors import AidingError

from .maps import one_map
from .noise import PoseNoise, pose_noise
from .offset import AidingOffset, estimate_offset
from .pairs import gyro_orientation
from .tum import Trajectory
from .types import AidingRows

log = logging.getLogger(__name__)
LARGE_LAG_S = 0.05  # an aiding this far off the IMU's clock is moved onto it with a warning (a camera's: a few ms)


def shift_trajectory(traj: Trajectory, imu_t_ns: np.ndarray, gyro: np.ndarray) -> Tuple[Trajectory, AidingOffset]:
    """(the trajectory on the IMU's clock, the offset): its stamps moved by the estimated lag where
    it was applied (:func:`.offset.estimate_offset`: at least one IMU sample), as read otherwise."""
    period_s = float(np.median(np.diff(np.asarray(imu_t_ns, dtype=np.int64)))) * 1e-9
    off = estimate_offset(imu_t_ns, gyro, traj.t_ns, traj.q_xyzw, min_shift_s=period_s)
    if off.why.startswith("at the search's edge"):  # a lag the search cannot place: refused, not fused unmoved
        raise AidingError(f"the aiding's rotations match the IMU's best at a lag of {1e3 * off.lag_s:+.0f} ms or more "
                          f"(|w| correlation {off.correlation:.2f}, {off.why}): a clock far off the IMU's, or "
                          "another recording's aiding; put both on one clock", None)
    if not off.applied:
        return traj, off
    if abs(off.lag_s) > LARGE_LAG_S:
        log.warning(f"the aiding's stamps are {1e3 * off.lag_s:+.0f} ms off the IMU's (|w| correlation "
                    f"{off.correlation:.2f}): moved onto the IMU's clock; check the clocks")
    return replace(traj, t_ns=traj.t_ns - int(round(off.lag_s * 1e9))), off


def with_noise(rows: AidingRows, imu_t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
               max_gap_s: float) -> AidingRows:
    """``rows`` with each pose's noise estimated against the IMU (None with too few increments) and,
    where they have breaks, whether they stay in one map (:mod:`.maps`)."""
    C = gyro_orientation(imu_t_ns, gyro)  # the gyro's chain, once for both
    rows.noise = pose_noise(imu_t_ns, gyro, acc, (rows.sample, rows.R, rows.p), 1, max_gap_s, C=C)
    rows.maps = one_map(imu_t_ns, gyro, acc, rows.sample, rows.t_ns, rows.p, rows.R, max_gap_s, C=C)
    if rows.maps is not None and not rows.maps.verdict:
        log.info("aiding with breaks, not tied to one world: %s", rows.maps.why)
    return rows


def summary_entry(rows: AidingRows, used: Optional[PoseNoise], source: str) -> Dict[str, object]:
    """The summary's ``aiding_estimates``: the offset, the noise estimated and the noise used (and
    where it came from)."""
    est = rows.noise
    return {"frame_check": None if rows.frame is None else rows.frame.to_dict(),
            "offset": None if rows.offset is None else rows.offset.to_dict(),
            "scale": None if rows.scale is None else rows.scale.to_dict(),
            "breaks": None if rows.maps is None else rows.maps.to_dict(),
            "noise_estimated": None if est is None else est.to_dict(),
            "noise_used": None if used is None else {
                "rot_deg_per_axis": [round(float(np.rad2deg(x)), 5) for x in used.rot_rad],
                "trans_m_per_axis": [round(float(x), 5) for x in used.trans_m], "source": source}}


def one_line_text(entry: Optional[Dict[str, object]]) -> str:
    """``aiding noise 0.03 deg / 2.1 mm per pose (estimated), offset -2.5 ms`` for the CLI's line ("" without)."""
    if not entry:
        return ""
    parts = []
    used = entry.get("noise_used")
    if used:
        rot = float(np.sqrt(np.mean(np.square(used["rot_deg_per_axis"]))))
        trans = 1e3 * float(np.sqrt(np.mean(np.square(used["trans_m_per_axis"]))))
        parts.append(f"aiding noise {rot:.3f} deg / {trans:.1f} mm per pose ({used['source']})")
    br = entry.get("breaks")
    if br:
        parts.append(f"{len(br['breaks'])} break(s), " + ("one map: its world tied across them" if br["one_map"] else
                                                          "not one map: each run chained alone"))
    sc = entry.get("scale")
    if sc and sc.get("observed"):
        parts.append(f"scale x{sc['scale']:.3f} (+-{sc['std']:.3f}) of metric")
    off = entry.get("offset")
    if off and off.get("lag_s") is not None:
        parts.append(f"offset {1e3 * off['lag_s']:+.1f} ms{'' if off['applied'] else ' (not applied)'}")
    return ", ".join(parts)
