"""Whether relative-pose aiding with breaks stays in one map: a visual SLAM system that loses track and
relocalises (or motion capture that drops out) gives poses after a break in the same world as before; a
visual odometry that restarts gives them in a new one. Only the first may be tied to one world across
its breaks (:class:`.types.WorldPoses`); the second chains each run on its own, as before.

Each break (consecutive rows further apart than ``--max-relative-gap-s``, rows ``a`` then ``b``) is
compared with the IMU's dead reckoning over it, before any fusion:

* **the gyro's bias across it**: the median rate of the aiding's rotation increments against the gyro's
  over :data:`BIAS_PAIR_S` inside the runs on either side, within :data:`BIAS_S` of the break (raw
  MEMS gyros read tens of mrad/s off: EuRoC's ADIS16448 80 mrad/s on z, 46° over a 10 s break), taken
  off the gyro over the break before it is compared;
* **rotation**: the aiding's ``R_aᵀ R_b`` against the gyro's chain ``C_aᵀ C_b``
  (:func:`.pairs.gyro_orientation`, its bias taken off), within :data:`ROT_DEG` plus
  :data:`GYRO_DRIFT_DEG_S` per second of the break (what is left of the bias: its change and its
  estimate's error) plus :data:`ROT_FRACTION` of the turn over it (an aiding body frame a degree or two
  off the IMU's: on TUM-VI's motion capture 1.7-2.8° over turns of 60-140°), the median over the
  pairs of the :data:`EDGE_ROWS` rows on each side (a pose at a break's edge is often off: TUM-VI's
  motion capture 2.8° at one dropout); a new map's first frame is the camera's pose at its restart,
  tens of degrees off in general;
* **translation**: ``p_b − p_a`` against the aiding's velocity before the break (its last
  :data:`VELOCITY_S`) times the break plus the accelerometer's double integral over it, turned into the
  aiding's world by its attitude at ``a`` and the gyro's chain, with gravity in that world estimated
  from the runs themselves (the median over half-second triples of the aiding's change of mean velocity
  less the IMU's: :mod:`imu_learn.calib.metric_scale`'s terms); within ``½ a T² + VEL_ERR T +``
  :data:`POS_FLOOR_M`, ``a`` = :data:`ACC_ERR` (a MEMS accelerometer's bias and the tilt it leaves) plus
  gravity times half the rotation bound (the attitude error it allows), and the aiding's velocity error.

One map where every break passes both; otherwise none is tied (one line says which break failed and
how). A map restarted near its first origin with the attitude it started with passes, and is then
tied wrongly: the bounds are a MEMS IMU's over a few seconds, loose on long breaks (at 10 s the
translation bound is 30-40 m; the rotation check then decides).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.calib import metric_scale

from .pairs import gyro_orientation, rotation_pairs, runs, within

ROT_DEG = 5.0
GYRO_DRIFT_DEG_S = 0.1
# the aiding's body frame a degree or two off the IMU's (TUM-VI's motion-capture marker frame), or a gyro
# scale error of a few 0.1 %: the rotation across a break then differs by that fraction of the turn
ROT_FRACTION = 0.03
G = 9.81
EDGE_ROWS = 3  # rows on each side of a break compared (the median over their pairs)
ACC_ERR = 0.3  # m/s^2: a MEMS accelerometer's bias plus the tilt error it leaves, over a break
VEL_ERR = 0.1  # m/s: the aiding's velocity from its last VELOCITY_S
POS_FLOOR_M = 0.1
VELOCITY_S = 0.5
BIAS_S = 10.0  # s of the runs on either side of a break whose rotation increments give the gyro's bias
BIAS_PAIR_S = 0.5  # s: the span of each increment (rows this far apart)


@dataclass(frozen=True)
class OneMap:
    """The verdict (every break passed: one map), each break's figures, and why not (empty when one map)."""

    verdict: bool
    breaks: List[Dict[str, float]] = field(default_factory=list)
    why: str = ""

    def to_dict(self) -> Dict[str, object]:
        return {"one_map": self.verdict, "breaks": self.breaks, "why": self.why or None}


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def gravity_in_world(S: metric_scale.Integrals, C: np.ndarray, tau: np.ndarray, sample: np.ndarray,
                     p: np.ndarray, R: np.ndarray, run: np.ndarray) -> Optional[np.ndarray]:
    """Gravity in the aiding's world [m/s²] (:func:`imu_learn.calib.metric_scale.gravity`) over the
    half-second triples inside runs; None with too few."""
    stride = metric_scale.stride_of(float(np.median(np.diff(tau))))
    a = within(run, 2 * stride)
    if len(a) < metric_scale.MIN_TRIPLES:
        return None
    return metric_scale.gravity(metric_scale.pose_terms(S, C, tau, sample, p, R, a, stride))


@dataclass(frozen=True)
class _Imu:
    """The IMU as the check uses it: stamps [ns as read; s from the first sample], dt, the gyro [rad/s] and
    its chain ``C``, the accelerometer [m/s²], and gravity in the aiding's world ``g``."""

    t_ns: np.ndarray
    t: np.ndarray
    dt: np.ndarray
    gyro: np.ndarray
    C: np.ndarray
    acc: np.ndarray
    g: np.ndarray

    def chain(self, s0: int, s1: int, bias: np.ndarray) -> np.ndarray:
        """(s1 - s0 + 1, 3, 3) the gyro's orientation at samples ``s0..s1`` in the frame of ``s0``, ``bias``
        taken off."""
        return gyro_orientation(self.t_ns[s0:s1 + 1], self.gyro[s0:s1 + 1] - bias)


def one_map(imu_t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, sample: np.ndarray, aid_t_ns: np.ndarray,
            p: np.ndarray, R: np.ndarray, max_gap_s: float, C: Optional[np.ndarray] = None) -> Optional[OneMap]:
    """The check (module docstring) of rows at IMU samples ``sample``, stamps ``aid_t_ns``, body poses ``R``,
    ``p`` in the aiding's world; None where the rows have no break. ``C``: :func:`.pairs.gyro_orientation`
    when already computed."""
    run = runs(imu_t_ns, sample, max_gap_s)
    if run[-1] == 0:
        return None
    t0 = int(imu_t_ns[0])
    t = (np.asarray(imu_t_ns, dtype=np.int64) - t0) * 1e-9
    tau = (np.asarray(aid_t_ns, dtype=np.int64) - t0) * 1e-9
    C = gyro_orientation(imu_t_ns, gyro) if C is None else C
    dt = np.r_[np.diff(t), 0.0]
    S = metric_scale.gyro_frame_integrals(t, C, acc)
    g = gravity_in_world(S, C, tau, sample, p, R, run)
    if g is None:
        return OneMap(False, [], "too few rows inside the runs to find gravity in the aiding's world")
    imu = _Imu(np.asarray(imu_t_ns, dtype=np.int64), t, dt, np.asarray(gyro, dtype=np.float64), C,
               np.asarray(acc, dtype=np.float64), g)
    rates = _Rates.of(imu_t_ns, sample, R, max_gap_s, C, tau)
    out: List[Dict[str, float]] = []
    why = ""
    for b in np.flatnonzero(np.diff(run)) + 1:
        entry, fail = _check_break(imu, tau, sample, p, R, run, int(b), rates)
        out.append(entry)
        why = why or fail
    return OneMap(not why, out, why)


@dataclass(frozen=True)
class _Rates:
    """Inside the runs, rows ``i`` and ``j`` :data:`BIAS_PAIR_S` apart (:func:`.pairs.rotation_pairs`) and
    the rate [rad/s] of the gyro's rotation over each against the aiding's, ``log((R_iᵀ R_j)ᵀ C_iᵀ C_j) / Δt``."""

    i: np.ndarray
    j: np.ndarray
    rate: np.ndarray

    @staticmethod
    def of(imu_t_ns: np.ndarray, sample: np.ndarray, R: np.ndarray, max_gap_s: float, C: np.ndarray,
           tau: np.ndarray) -> _Rates:
        k = max(1, int(round(BIAS_PAIR_S / max(float(np.median(np.diff(tau))), 1e-3))))
        pr = rotation_pairs(imu_t_ns, sample, R, max_gap_s, k, C=C)
        if not len(pr):
            return _Rates(pr.a, pr.b, np.zeros((0, 3)))
        rate = Rotation.from_matrix(np.einsum("nki,nkj->nij", pr.aiding, pr.gyro)).as_rotvec() / pr.dt_s[:, None]
        return _Rates(pr.a, pr.b, rate)


def gyro_bias_across(rates: _Rates, tau: np.ndarray, run: np.ndarray, b: int) -> np.ndarray:
    """(3,) the gyro's bias [rad/s] across the break before row ``b`` (module docstring): the per-axis median
    of ``rates`` inside the runs on either side, within ``BIAS_S`` of the break; zero with fewer than three."""
    a, i, j = b - 1, rates.i, rates.j
    near = (((run[i] == run[a]) & (tau[i] >= tau[a] - BIAS_S)) | ((run[i] == run[b]) & (tau[j] <= tau[b] + BIAS_S)))
    return np.median(rates.rate[near], axis=0) if near.sum() >= 3 else np.zeros(3)


def _check_break(imu: _Imu, tau: np.ndarray, sample: np.ndarray, p: np.ndarray, R: np.ndarray, run: np.ndarray,
                 b: int, rates: _Rates) -> Tuple[Dict[str, float], str]:
    """(the break's figures, why it is not in one map or "") of the break before row ``b``."""
    a = b - 1
    T = float(tau[b] - tau[a])
    # the median over the last EDGE_ROWS rows before the break and the first after it: one pose at a
    # break's edge is often off (a tracker losing or regaining its view)
    before = [i for i in range(a, a - EDGE_ROWS, -1) if i >= 0 and run[i] == run[a]]
    after = [j for j in range(b, b + EDGE_ROWS) if j < len(run) and run[j] == run[b]]
    bias = gyro_bias_across(rates, tau, run, b)
    s0 = int(sample[before[-1]])
    C = imu.chain(s0, int(sample[after[-1]]), bias)  # C[n - s0]: sample n in the frame of s0, bias off
    sa, sb = int(sample[a]), int(sample[b])
    turned = C[sa - s0].T @ C[sb - s0]
    rot = float(np.median([_angle_deg((R[i].T @ R[j]).T @ (C[sample[i] - s0].T @ C[sample[j] - s0]))
                           for i in before for j in after]))
    rot_bound = ROT_DEG + GYRO_DRIFT_DEG_S * T + ROT_FRACTION * _angle_deg(turned)
    entry = {"t_s": round(float(tau[a]), 3), "duration_s": round(T, 3), "rotation_deg": round(rot, 3),
             "rotation_bound_deg": round(rot_bound, 3),
             "gyro_bias_rad_s": [round(float(x), 5) for x in bias]}
    first = int(np.searchsorted(tau, tau[a] - VELOCITY_S))
    if not (run[first] == run[a] and first < a):
        return {**entry, "ok": False}, f"the break at {tau[a]:.1f} s follows a run shorter than {VELOCITY_S:g} s"
    v = (p[a] - p[first]) / (tau[a] - tau[first])
    Cs = C[sa - s0:sb - s0]
    acc_A = np.einsum("ij,nj->ni", R[a] @ C[sa - s0].T, np.einsum("nij,nj->ni", Cs, imu.acc[sa:sb])) + imu.g
    h = imu.dt[sa:sb, None]
    dv = np.cumsum(acc_A * h, axis=0) - acc_A * h  # velocity change at each sample's start
    predicted = v * T + np.sum(dv * h + 0.5 * acc_A * h ** 2, axis=0)
    miss = float(np.linalg.norm((p[b] - p[a]) - predicted))
    acc_err = ACC_ERR + 0.5 * G * np.radians(rot_bound)  # the attitude error the rotation bound allows tilts gravity
    pos_bound = 0.5 * acc_err * T ** 2 + VEL_ERR * T + POS_FLOOR_M
    ok = rot <= rot_bound and miss <= pos_bound
    entry = {**entry, "translation_miss_m": round(miss, 3), "translation_bound_m": round(pos_bound, 3), "ok": bool(ok)}
    if ok:
        return entry, ""
    return entry, (f"the break at {tau[a]:.1f} s ({T:.1f} s): the aiding turned {rot:.1f} deg against the gyro "
                   f"(bound {rot_bound:.1f}) and moved {miss:.2f} m off the IMU's dead reckoning (bound "
                   f"{pos_bound:.2f} m): a new map")
