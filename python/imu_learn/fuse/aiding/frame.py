"""Is the aiding's body frame the IMU's? Pose aiding (VO / SLAM output, a motion-capture track) is
fused as the poses of the IMU's body, after ``--extrinsics`` (the sensor's pose in the body frame)
where one is given. Poses of a camera given without it are rotated from the IMU by the camera's
mounting (EuRoC's cam0: about 90°), and the fusion then pulls the IMU's rotation toward another
axis's: it diverges while exiting 0 (an ORB-SLAM2 trajectory of V2_02 fused with no extrinsic gave an
aligned RMSE of 10^13 m against the VO's 6 cm). This check runs before any fusion.

The rotation between the two frames follows from rotation increments alone, as ``imu-learn calibrate``
resolves a reference's frame (:func:`imu_learn.calib.reference.resolve_frame`): between consecutive
aiding rows (paired as the noise estimate pairs them, :mod:`.pairs`), the aiding's body-frame rate
``log(R_iᵀ R_i+1) / dt`` against the gyro's ``log(C_iᵀ C_i+1) / dt`` over the same IMU samples (its
SO(3) chain), both centred (the gyro's bias, a constant rate, drops out), fitted by Kabsch
(:func:`imu_learn.calib.frames.kabsch`). A motion that turns about one axis only (a ground robot's
yaw) leaves the rotation about that axis unobservable; then only the axis is compared: the gyro's
rates that go with the aiding's main axis against that axis.

* rotation (or the axis's angle) above :data:`MAX_ROTATION_DEG`: refused (exit 2), naming
  ``--extrinsics``; a camera's mounting is tens of degrees, a well-mounted sensor's residual a few;
* above :data:`WARN_ROTATION_DEG`: one warning line (the fusion takes the poses as they are);
* rates that no rotation maps onto the gyro's (the fit's residual above calibrate's share of the
  motion, ``FrameOptions.max_rate_residual``): refused, naming the file (another recording's, a time
  unit, the quaternions' order), not an extrinsic;
* too few pairs or too little turning to tell: not checked, and the summary says so.

Below the refusal, a rotation the rates fix (every axis turning) to at least :data:`TURN_MIN_DEG` and
:data:`TURN_SPREADS` bootstrap spreads is a frame the poses are really in, and :func:`turned_onto_gyro`
turns them onto the IMU's before the fusion (``--keep-aiding-frame`` keeps them as they are).
ORB-SLAM2's stereo poses are the *rectified* left camera's, 0.62° from EuRoC's raw ``cam0`` (its
settings' ``LEFT.R``), so ``--extrinsics cam0_sensor.yaml`` leaves them 0.6° off; the relative poses'
translations are then rotated by that much in the body frame, which the filter takes into its tilt, and
a camera gap coasts on it (docs/experiments/navigate-vo.md, "The poses' frame turned onto the gyro's").
The same rule as calibrate's for a given extrinsic (:func:`imu_learn.calib.reference.check_extrinsic_rotation`,
which refuses it there: a profile would carry the difference to every other recording).

The result goes into the summary's ``aiding.frame_check``."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Dict, Optional

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.calib.frames import kabsch, trimmed_kabsch
from imu_learn.calib.reference import FrameOptions, glitch_cap, no_frame, planar_ratio, rotation_spread
from imu_learn.fuse.aiding.pairs import rotation_pairs
from imu_learn.fuse.aiding.types import AidingRows

MAX_ROTATION_DEG = 5.0  # refused above: the calibrate plausibility rule's misalignment limit
WARN_ROTATION_DEG = 1.0  # warned above: calibrate's ``identity_deg`` (below it a frame counts as the IMU's)
MIN_PAIRS = 20  # pairs of consecutive rows needed to tell
MIN_RATE_RMS = 0.05  # rad/s: the centred rates' RMS below which the motion cannot tell the frame
# rates over at least this span [s] (a 20 Hz VO: its pairs as they are): a 90-120 Hz motion capture's rates between consecutive rows carry its
# orientation noise / 10 ms (0.1-0.2 rad/s on Fetch), which spreads a ground robot's yaw over every axis
MIN_SPAN_S = 0.05
TURN_MIN_DEG = FrameOptions.extrinsic_tolerance_deg  # 0.3°: below it a frame is left as it is
TURN_SPREADS = FrameOptions.extrinsic_sigmas  # and it must be this many bootstrap spreads off


@dataclass(frozen=True)
class FrameCheck:
    """``rotation_deg``: the estimated angle between the aiding's body frame and the IMU's (the main
    axis's angle when ``axis_only``), None when not checked; ``pairs``: the row pairs used;
    ``verdict``: "same frame", "warned", "refused" or "not checked"; ``why``: one line."""

    rotation_deg: Optional[float]
    axis_only: bool
    pairs: int
    verdict: str
    why: str
    # False: the rates match in no frame (another recording's trajectory, a time unit, the quaternions'
    # order): refused, and no extrinsic is to blame
    matches: bool = True
    # every axis turning: the rotation (aiding body -> IMU: ω_imu ≈ R ω_aiding + bias) and its bootstrap spread
    rotation: Optional[np.ndarray] = None
    spread_deg: Optional[float] = None
    turned: bool = False  # the poses were turned onto the IMU's frame by ``rotation`` (:func:`turned_onto_gyro`)

    @property
    def resolved(self) -> bool:
        """A rotation the rates fix well enough to turn the poses by (module docstring)."""
        return (self.rotation is not None and self.verdict in ("same frame", "warned") and self.spread_deg is not None
                and self.rotation_deg >= TURN_MIN_DEG and self.rotation_deg > TURN_SPREADS * self.spread_deg)

    def to_dict(self) -> Dict[str, object]:
        return {"rotation_deg": None if self.rotation_deg is None else round(self.rotation_deg, 2),
                "spread_deg": None if self.spread_deg is None else round(self.spread_deg, 3),
                "axis_only": self.axis_only, "pairs": self.pairs, "verdict": self.verdict, "why": self.why,
                "matches_a_frame": self.matches, "turned": self.turned}


def paired_rates(imu_t_ns: np.ndarray, gyro: np.ndarray, rows: AidingRows, max_gap_s: float,
                 C: Optional[np.ndarray] = None) -> tuple:
    """(IMU mean rates, aiding body-frame rates), (P, 3) each, over the pairs of consecutive rows
    (:func:`.pairs.rotation_pairs`: at most ``max_gap_s`` apart), less the pairs whose aiding rate no
    gyro reading comes near (:func:`imu_learn.calib.reference.glitch_cap`: a motion-capture quaternion
    that jumps for a frame), averaged over :data:`MIN_SPAN_S` where the rows are denser (the noise of
    consecutive rows made Fetch's yaw turns look like motion about every axis: 154°);
    ``C``: the gyro's orientation (:func:`.pairs.gyro_orientation`) when already computed."""
    pairs = rotation_pairs(imu_t_ns, rows.sample, rows.R, max_gap_s, C=C, gyro=gyro)
    if not len(pairs):
        return np.zeros((0, 3)), np.zeros((0, 3))
    a, b = (Rotation.from_matrix(m).as_rotvec() / pairs.dt_s[:, None] for m in (pairs.gyro, pairs.aiding))
    keep = np.linalg.norm(b, axis=1) <= glitch_cap(np.linalg.norm(a, axis=1))  # the aiding's own jumps out
    a, b, dt = a[keep], b[keep], pairs.dt_s[keep]
    k = int(math.ceil(MIN_SPAN_S / max(float(np.median(dt)), 1e-9))) if len(dt) else 1
    if k <= 1:
        return a, b
    n = len(dt) // k * k  # mean rates over k consecutive pairs (weighted by their spans)
    w = dt[:n].reshape(-1, k, 1)
    return tuple((x[:n].reshape(-1, k, 3) * w).sum(1) / w.sum(1) for x in (a, b))


def check_frame(imu_t_ns: np.ndarray, gyro: np.ndarray, rows: AidingRows, max_gap_s: float = 0.5,
                C: Optional[np.ndarray] = None) -> FrameCheck:
    """The aiding's body frame against the IMU's (module docstring), pairing rows at most ``max_gap_s``
    apart (``--max-relative-gap-s``); ``C``: the gyro's orientation when already computed. Never
    raises: the caller refuses on ``verdict == "refused"``."""
    if rows.R is None:
        return FrameCheck(None, False, 0, "not checked", "the aiding holds no rotations")
    a, b = paired_rates(imu_t_ns, gyro, rows, max_gap_s, C)
    n = len(a)
    if n < MIN_PAIRS:
        return FrameCheck(None, False, n, "not checked", f"{n} pairs of consecutive rows; {MIN_PAIRS} needed")
    bc = b - b.mean(0)
    _, sv, vt = np.linalg.svd(bc, full_matrices=False)
    rms = float(np.sqrt(np.sum(sv ** 2) / n))
    if rms < MIN_RATE_RMS:
        return FrameCheck(None, False, n, "not checked",
                          f"the aiding turns too little to tell its frame (rates' RMS {rms:.3f} rad/s)")
    axis_only = planar_ratio((a, b)) < FrameOptions.planar_ratio  # calibrate's rule
    if axis_only:  # one axis: the gyro's rates that go with the aiding's main axis against that axis
        u = vt[0]
        d = (a - a.mean(0)).T @ (bc @ u)
        angle = math.degrees(math.acos(np.clip(d @ u / max(np.linalg.norm(d), 1e-12), -1.0, 1.0)))
    R = spread = None
    if not axis_only:
        R, c, mse = kabsch(a, b)
        angle = math.degrees(Rotation.from_matrix(R).magnitude())
        motion = float(np.sqrt(np.mean(np.sum((a - a.mean(0)) ** 2, axis=1))))
        if math.sqrt(mse) > FrameOptions.max_rate_residual * motion:  # calibrate's rule (calib.reference)
            return FrameCheck(angle, False, n, "refused", f"its {no_frame(math.sqrt(mse), motion)}", matches=False)
        R, _, keep = trimmed_kabsch(a, b, start=(R, c))  # the rotation without the aiding's glitches
        angle = math.degrees(Rotation.from_matrix(R).magnitude())
        spread = rotation_spread((a[keep], b[keep]))
    what = "its main rotation axis is" if axis_only else "its body frame is"
    line = f"{what} {angle:.1f}° from the IMU's (from {n} rotation increments)"
    verdict = "refused" if angle > MAX_ROTATION_DEG else ("warned" if angle > WARN_ROTATION_DEG else "same frame")
    return FrameCheck(angle, axis_only, n, verdict, line, rotation=R, spread_deg=spread)


def turned_onto_gyro(rows: AidingRows, check: FrameCheck) -> AidingRows:
    """``rows`` with their body frame turned onto the IMU's by the check's rotation where it is
    :attr:`FrameCheck.resolved` (R_WB = R_WA Rᵀ; the positions stay: the turn is about the IMU's origin,
    0.7 mm on a 7 cm lever arm at 0.6°) and ``frame`` the check marked ``turned``; the rows as they are
    otherwise."""
    if not check.resolved or rows.R is None:
        return rows
    return replace(rows, R=np.einsum("nij,kj->nik", rows.R, check.rotation),
                   frame=replace(check, turned=True))
