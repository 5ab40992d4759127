"""Is a fitted profile physically plausible, and does it help where it was not fitted?

A profile outside what a MEMS IMU can be is the symptom of a wrong frame, unit or lag in the input,
not a finding (design: references users have). ``imu-learn calibrate`` writes a profile only when
every check here passes; otherwise it stops (exit 2) with one line naming the parameter and the
likely cause; ``--force`` writes it with a warning.

The limits (MEMS IMUs; :data:`LIMITS`, each documented in docs/your-device.md):

* scale (each diagonal entry of M_g, M_a) within 0.8-1.25;
* misalignment (each off-diagonal entry over its row's diagonal, as an angle) below 5°;
* |gyro bias| below 0.1 rad/s per axis, |acc bias| below 1 m/s^2 per axis;
* no row of a calibration matrix near zero (an axis that reads nothing);
* the floor's gravity consistency within 5 % of 9.81 m/s^2;
* on the held-back block (the validation segments, never fitted), the floor lowers the relative
  rotation error over ``window`` samples against the raw IMU, and does not raise the translation
  error by more than ``HELD_BACK_SLACK`` (the translation of a sparse reference is noisier than the
  accelerometer, so a tie counts as no harm).

**Within the block's noise.** Each held-back finding carries ``z``: the paired difference of the
windows' squared errors (profile minus raw; their mean is the difference of the two mean squares)
over its standard error (windows half-overlap: half their count taken as independent). A raise
above :data:`HELD_BACK_Z` standard errors is harm (the frame, unit, clock or the fit is wrong):
calibrate stops. One within it (or on fewer than :data:`HELD_BACK_MIN_WINDOWS` windows: it cannot
tell, and stops too) says the block cannot tell the fitted terms from none: calibrate keeps that
sensor's terms at their prior (:func:`imu_learn.calib.run.plausibility`), so the profile never
claims a correction the reference does not support.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.baselines.affine import Floor, TraditionalParams
from imu_learn.score.metrics import relative_pose_errors, rmse, with_imu

LIMITS: Dict[str, Any] = {
    "scale": (0.8, 1.25),
    "misalignment_deg": 5.0,
    "gyro_bias_rad_s": 0.1,
    "acc_bias_mps2": 1.0,
    "row_norm_min": 0.5,
    "gravity_rel": 0.05,
}
HELD_BACK_SLACK = 1.02
HELD_BACK_Z = 2.0  # a held-back raise beyond this many standard errors of the paired difference: harm
HELD_BACK_MIN_WINDOWS = 8  # fewer held-back windows: the noise of the difference is not known
G = 9.81


@dataclass
class Finding:
    """One failed check: ``field`` (profile.json's name), what was found and the likely cause."""

    field: str
    message: str
    within_noise: bool = False  # a held-back raise the block's own noise explains (HELD_BACK_Z)

    def line(self) -> str:
        return f"{self.field}: {self.message}"


def _scale_cause(d: float, unit: Tuple[float, str], other: str) -> str:
    """The likely cause of a scale ``d`` outside the limits: the unit mistake ``unit`` = (factor, words)
    where ``d`` is within a factor 1.5 of it or of its inverse, else a term the motion did not fix."""
    k, words = unit
    if d > 0 and min(abs(math.log(d / k)), abs(math.log(d * k))) < math.log(1.5):
        return words
    return (f"not a unit mistake (that reads x{k:.3g} or x{1 / k:.3g}): a term the recordings' motion does not fix "
            f"(its noise fitted), or {other}")


def _matrix_findings(name: str, m: np.ndarray, unit: Tuple[float, str], other: str) -> List[Finding]:
    out = []
    lo, hi = LIMITS["scale"]
    for i in range(3):
        row = m[i]
        if np.linalg.norm(row) < LIMITS["row_norm_min"]:
            out.append(Finding(f"{name}.matrix[{i}]", f"row {i} is near zero (|row| {np.linalg.norm(row):.3g}): that "
                                                      "axis reads nothing in the reference's motion; a constant or "
                                                      "swapped column, or a frame the reference cannot resolve"))
            continue
        d = row[i]
        if not lo <= d <= hi:
            out.append(Finding(f"{name}.matrix[{i}][{i}]", f"scale {d:.4g} outside {lo}-{hi}: "
                                                           + _scale_cause(float(d), unit, other)))
        for j in range(3):
            if j != i:
                ang = math.degrees(math.atan2(abs(row[j]), abs(d)))
                if ang >= LIMITS["misalignment_deg"]:
                    out.append(Finding(f"{name}.matrix[{i}][{j}]", f"misalignment {ang:.1f}° (limit "
                                       f"{LIMITS['misalignment_deg']:g}°): the reference is not in the IMU's frame, "
                                       "or its motion does not excite this term"))
    return out


def _params(floor: Any) -> TraditionalParams:
    """The parameters of a Floor, of TraditionalParams, or of a (partial) saved dict (the rest identity)."""
    if isinstance(floor, Floor):
        return floor.params
    if isinstance(floor, TraditionalParams):
        return floor
    return TraditionalParams.from_dict({**TraditionalParams.identity().to_dict(), **floor})


def parameter_findings(floor: Any, gravity_mps2: Optional[float]) -> List[Finding]:
    """Every limit of the module doc that ``floor`` (the profile's Floor, its parameters or saved
    dict) breaks."""
    p = _params(floor)
    out = _matrix_findings("gyroscope", p.M_g, (math.degrees(1.0), "a gyro unit off (deg/s read as rad/s: 57x) or a "
                                                                   "reference rotation in another unit"),
                           "a reference rotation that does not follow the IMU's")
    out += _matrix_findings("accelerometer", p.M_a, (G, "an acc unit off (g read as m/s^2: 9.8x)"),
                            "a reference position scale off (monocular VO)")
    bg = np.abs(p.b_g)
    if np.any(bg >= LIMITS["gyro_bias_rad_s"]):
        out.append(Finding("gyroscope.bias", f"|bias| {bg.max():.3g} rad/s (limit {LIMITS['gyro_bias_rad_s']:g}): a "
                                             "reference in another frame, or a gyro unit off"))
    ba = np.abs(p.b_a)
    if np.any(ba >= LIMITS["acc_bias_mps2"]):
        out.append(Finding("accelerometer.bias", f"|bias| {ba.max():.3g} m/s^2 (limit {LIMITS['acc_bias_mps2']:g}): a "
                                                 "reference world not levelled, a lever arm, a reference not in metres, or an acc unit off"))
    if gravity_mps2 is not None and math.isfinite(gravity_mps2) and abs(gravity_mps2 / G - 1) > LIMITS["gravity_rel"]:
        out.append(Finding("gravity_mps2", f"{gravity_mps2:.3f} m/s^2 after the profile (limit +-"
                                           f"{100 * LIMITS['gravity_rel']:g} % of {G}): the acc unit, or a reference "
                                           "whose world is not gravity-aligned or not metric"))
    return out


def _paired_z(raw: List[np.ndarray], cal: List[np.ndarray]) -> float:
    """The mean of the windows' squared-error differences (cal minus raw) over its standard error,
    half the windows counted as independent (they half-overlap); NaN with too few windows."""
    d = np.concatenate(cal) ** 2 - np.concatenate(raw) ** 2
    if len(d) < HELD_BACK_MIN_WINDOWS:
        return math.nan
    se = float(np.std(d, ddof=1)) / math.sqrt(len(d) / 2)
    return float(np.mean(d)) / se if se > 0 else (0.0 if np.mean(d) == 0 else math.copysign(math.inf, np.mean(d)))


def held_back_errors(segs: Sequence[Any], calibrated: Sequence[Tuple[np.ndarray, np.ndarray]], n: int,
                     gravity: float = G) -> Dict[str, float]:
    """Relative rotation [deg] and translation [m] RMSE over ``n`` samples on ``segs`` (the held-back
    block), raw and with each segment's ``calibrated`` (gyro, acc), stride n/2, and the paired
    differences' ``z`` (module doc; NaN: too few windows)."""
    raw_r, raw_t, cal_r, cal_t = [], [], [], []
    stride = max(1, n // 2)
    for s, (g, a) in zip(segs, calibrated):
        if len(s) <= n:
            continue
        e0 = relative_pose_errors(s, n, stride, gravity)
        e1 = relative_pose_errors(with_imu(s, g, a), n, stride, gravity)
        raw_r.append(e0["rot_rad"])
        raw_t.append(e0["trans_m"])
        cal_r.append(e1["rot_rad"])
        cal_t.append(e1["trans_m"])
    if not raw_r:
        return {}
    return {"window_samples": n, "windows": int(sum(len(r) for r in raw_r)),
            "raw_rot_deg": math.degrees(rmse(np.concatenate(raw_r))),
            "raw_trans_m": rmse(np.concatenate(raw_t)), "profile_rot_deg": math.degrees(rmse(np.concatenate(cal_r))),
            "profile_trans_m": rmse(np.concatenate(cal_t)), "z_rot": _paired_z(raw_r, cal_r),
            "z_trans": _paired_z(raw_t, cal_t)}


def _noise_words(z: Optional[float]) -> Tuple[bool, str]:
    """(whether the raise is within the block's noise, the words that say so)."""
    if z is None:
        return False, ""
    if not math.isfinite(z):
        return False, "; too few held-back windows to tell a raise from noise"
    within = z <= HELD_BACK_Z
    return within, (f"; {z:.1f} standard errors, " + ("within" if within else "beyond")
                    + f" the block's noise ({HELD_BACK_Z:g})")


def held_back_findings(errs: Dict[str, float]) -> List[Finding]:
    """The held-back check of the module doc (nothing to say without a held-back block); each finding
    says whether the block's noise explains it (``within_noise``)."""
    if not errs:
        return []
    out = []
    if errs["profile_rot_deg"] > errs["raw_rot_deg"]:
        within, words = _noise_words(errs.get("z_rot"))
        out.append(Finding("held_back.rotation", f"the profile raises the rotation error on the held-back block "
                                                 f"({errs['profile_rot_deg']:.3f}° against raw {errs['raw_rot_deg']:.3f}° "
                                                 f"over {errs['window_samples']} samples{words})", within))
    if errs["profile_trans_m"] > HELD_BACK_SLACK * errs["raw_trans_m"]:
        within, words = _noise_words(errs.get("z_trans"))
        out.append(Finding("held_back.translation", f"the profile raises the translation error on the held-back "
                                                    f"block ({errs['profile_trans_m']:.4f} m against raw "
                                                    f"{errs['raw_trans_m']:.4f} m over {errs['window_samples']} "
                                                    f"samples{words})", within))
    return out


def applied_floor_finding(floor: Any, gravity_mps2: Optional[float], where: str) -> Optional[Tuple[str, str]]:
    """(the one line, the field) saying why a profile's floor about to be applied (refine, navigate, evaluate's
    ``profile:``) lies outside what calibrate writes for a MEMS IMU (:func:`parameter_findings`), or None."""
    findings = parameter_findings(floor, gravity_mps2) if floor is not None else []
    if not findings:
        return None
    f = findings[0]
    more = f" (and {len(findings) - 1} more)" if len(findings) > 1 else ""
    return (f"{where}: field '{f.field}': {f.message}{more}; outside what calibrate writes for a MEMS IMU (edited, or "
            "from another tool?)", f.field)
