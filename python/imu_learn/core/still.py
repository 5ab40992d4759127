"""Still stretches: where an IMU is at rest, found from its own samples, and the gyro bias they give.

**The detector** (:func:`still_stretches`, the package's one): over a sliding window of ``window_s``
centred on each sample, every axis's standard deviation (gyro and accelerometer) must be below
``factor`` x its 5th percentile over the recording (the quietest part sets the scale: no device's
noise is hard-coded) and below absolute caps (``gyro_cap`` rad/s, ``acc_cap`` m/s^2: a recording
that never rests has no quiet part to compare with). With ``gravity`` set, the window's mean
accelerometer norm must also lie within ``gravity_tol`` of it: a smooth acceleration or a tilted
free fall is as quiet as rest, but not at gravity's magnitude. Stretches shorter than ``min_s`` are
dropped, ``trim_s`` is cut from each end (the onset of motion), and a gap in the stamps ends a
stretch (its longest gap-free part is kept). ``imu-learn calibrate`` finds the still stretches of
its Allan deviation with it (no gravity check there), ``imu-learn refine --bias still`` the
recording's own gyro bias (with it).

**The gyro bias** (:func:`still_bias`): at rest the gyro measures the earth's rotation (at most
7.3e-5 rad/s, left in the estimate) plus its bias, so the mean gyro over the still stretches is the
bias, every axis observable. Its uncertainty: the white-noise part, ``std / sqrt(N)`` per axis from
the samples' spread, and, with several stretches, the spread of their means (the bias moving over
the recording). What is not observable: a rotation slower than the caps that does not change the
accelerometer (a slow turn about gravity) reads as bias; the accelerometer's bias is seen only
along gravity, as the norm of its mean minus gravity, from one still attitude (its other two
components need the device at rest in several attitudes, and the scale error enters alike).

**The still rule** (:func:`at_rest`, the package's one): quiet is not enough. A wheeled robot turning
at a steady rate is as quiet as rest and keeps its accelerometer on gravity, so a window is at rest
only where the gyro itself, not only its spread, lies near what the device's bias can be: ``|mean
gyro - prior bias| <= k sigma`` on every axis (:data:`STILL_SIGMAS`, 3), sigma what the gyro reads at
rest (:meth:`BiasPrior.rest_std`: measured on the device's training recordings where its profile's
``bias_prior`` holds the figures, floored at :data:`BIAS_SPREAD_FLOOR` 5 mrad/s; else the prior's spread,
the device's bias spread between recordings, a profile's ``gyroscope.bias_std`` ×
sqrt(its recording groups), ``Profile.gyro_bias_prior_std`` (one recording: ``bias_std``), floored at
:data:`BIAS_SPREAD_FLOOR` and capped at :data:`MEMS_BIAS_BOUND` 0.05 rad/s; without a profile
the MEMS bound itself), and the mean accelerometer norm within :data:`ACC_NORM_TOL` (0.3 m/s^2, 3 %) of
gravity. Refine's and navigate's ``--bias`` detector applies it to each stretch it finds (the norm
per window, the gyro on the stretch's mean; the recording's prior: :data:`BIAS_SETTINGS` plus
``prior``), navigate's still start to every 0.25 s block
(:func:`imu_learn.fuse.start.level.block_is_still`, the MEMS prior); a recording has a still start
when it rests at least :data:`MIN_STILL_START_S` from its first sample. ``imu-learn calibrate``'s
Allan stretches keep the spread check only (the raw device's bias is what it fits).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.core.stamps import median_period_ns

# The still rule's constants (module doc).
STILL_SIGMAS = 3.0  # |mean gyro - prior bias| within this many of the prior's sigmas
BIAS_SPREAD_FLOOR = 0.005  # rad/s: the least bias spread a prior is given (a profile fitted on few recordings)
MEMS_BIAS_BOUND = 0.05  # rad/s: a MEMS gyro's bias spread without a profile, and the most a profile's is taken as
ACC_NORM_TOL = 0.3  # m/s^2: the mean accelerometer norm's distance from gravity at rest (3 % of g)
MIN_STILL_START_S = 1.0  # s: a recording "has a still start" when it rests this long from its first sample
STILL_MAX_SPEED_MPS = 0.1  # m/s: the most GNSS speed a still start allows (a GNSS start's check)


def prior_spread(bias_std: Optional[Sequence[float]]) -> np.ndarray:
    """(3,) rad/s: a profile's ``gyroscope.bias_std`` floored at :data:`BIAS_SPREAD_FLOOR` and capped at
    :data:`MEMS_BIAS_BOUND` (NaN or None: the MEMS bound)."""
    s = np.full(3, np.nan) if bias_std is None else np.asarray(bias_std, dtype=np.float64).reshape(3)
    s = np.where(np.isfinite(s), s, MEMS_BIAS_BOUND)
    return np.clip(s, BIAS_SPREAD_FLOOR, MEMS_BIAS_BOUND)


MEASURED_STD_FLOOR = 0.0005  # rad/s: the least a measured spread (of few recordings) is taken as


def _vector(x: object) -> Optional[Tuple[float, float, float]]:
    """A finite 3-vector of a profile's ``bias_prior``, None where absent or malformed."""
    if x is None:
        return None
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    return (float(a[0]), float(a[1]), float(a[2])) if a.size == 3 and np.all(np.isfinite(a)) else None


def _measured(x: object, isotropic: bool) -> Optional[Tuple[float, float, float]]:
    """A measured per-axis spread [rad/s] of a profile's ``bias_prior`` (floored at
    :data:`MEASURED_STD_FLOOR`; ``isotropic``: its largest axis on every axis), None where absent."""
    if x is None:
        return None
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    if a.size not in (1, 3) or not np.all(np.isfinite(a)):
        return None
    a = np.maximum(np.broadcast_to(a, (3,)), MEASURED_STD_FLOOR)
    a = np.full(3, a.max()) if isotropic else a
    return (float(a[0]), float(a[1]), float(a[2]))


@dataclass(frozen=True)
class BiasPrior:
    """What the device's gyro bias can be where an estimator runs: ``bias`` [rad/s] (3,) its mean
    (zero after a profile's floor, which removed the device's own) and ``std`` [rad/s] (3,) its spread
    (:func:`prior_spread`: the still rule's and the bound's); ``source`` says where they came from.

    Measured on the device's training recordings (a profile's ``bias_prior``, written by
    ``experiments/bias_prior.py fit``; None on a profile without it, and then nothing below applies):
    ``moving_std`` the recording-to-recording spread of the bias *while moving* after the floor
    (recorded; the summary shows it), ``still_error_std`` how far a still stretch's (resting) bias
    lies from the moving one per axis (it raises the still estimate's fixed uncertainty floor),
    ``gravity_error_std`` gravity consistency's error beyond its own uncertainty along the directions
    it observed, ``measured_rms`` per estimator (``still``, ``gravity``) its RMS error against the
    moving bias and the profile alone's (the moving bias itself) over the same recordings and
    directions (``--bias auto``'s gate). ``rest_to_motion`` [rad/s] (3,): the device's systematic
    change of the bias from rest to motion (moving minus still, the mean over the training recordings,
    per axis where holding each recording out in turn showed it lowered the still estimate's error;
    zero elsewhere), which the still estimate adds; then ``still_error_std`` is the spread left after it.
    None where not measured, and for an IMU rotated into another frame (``isotropic``: its axes are not
    the profile's; the spread before it is used)."""

    bias: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    std: Tuple[float, float, float] = (MEMS_BIAS_BOUND,) * 3
    source: str = f"no profile: a MEMS gyro's bias spread, {MEMS_BIAS_BOUND:g} rad/s"
    moving_std: Optional[Tuple[float, float, float]] = None
    still_error_std: Optional[Tuple[float, float, float]] = None
    gravity_error_std: Optional[float] = None
    # estimator -> (its RMS error, the profile alone's) [rad/s] on the training recordings (the gate)
    measured_rms: Tuple[Tuple[str, float, float], ...] = ()
    # the gyro's bias random walk [rad/s/sqrt(s)] (the profile's gyroscope_random_walk, copied into its
    # bias_prior by experiments/bias_prior.py fit): ``--bias moving``'s prior on how fast the bias moves
    random_walk: Optional[float] = None
    rest_to_motion: Optional[Tuple[float, float, float]] = None

    @classmethod
    def from_bias_std(cls, bias_std: Optional[Sequence[float]], source: str, isotropic: bool = False,
                      measured: Optional[Dict[str, object]] = None) -> BiasPrior:
        """Zero mean (after the floor), the spread of ``bias_std`` (``isotropic``: its largest axis on
        every axis, for an IMU rotated into another frame); ``measured``: a profile's ``bias_prior``
        (class doc; empty or None: none)."""
        s = prior_spread(bias_std)
        s = np.full(3, s.max()) if isotropic else s
        m = measured or {}
        g = m.get("gravity_error_std_rad_s")
        g = float(g) if isinstance(g, (int, float)) and math.isfinite(g) else None
        rms = []
        for name, r in (m.get("rms_rad_s") or {}).items():
            if (isinstance(r, dict) and all(isinstance(r.get(k), (int, float)) and math.isfinite(r[k])
                                            for k in ("error", "profile_alone"))):
                rms.append((str(name), float(r["error"]), float(r["profile_alone"])))
        rw = m.get("random_walk_rad_s_sqrt_s")
        rw = float(rw) if isinstance(rw, (int, float)) and math.isfinite(rw) and rw > 0 else None
        shift = None if isotropic else _vector(m.get("rest_to_motion_rad_s"))
        # the still estimate's spread after the shift where it applies, else the one before it
        still_std = m.get("still_error_std_rad_s") if shift is not None or "rest_to_motion_rad_s" not in m else \
            m.get("still_error_unshifted_std_rad_s")
        return cls((0.0, 0.0, 0.0), tuple(float(v) for v in s), source,
                   _measured(m.get("moving_std_rad_s"), isotropic), _measured(still_std, isotropic),
                   g, tuple(rms), rw, shift)

    def to_dict(self) -> Dict[str, object]:
        out: Dict[str, object] = {"bias_rad_s": [float(v) for v in self.bias], "std_rad_s": [float(v) for v in self.std],
                                  "source": self.source, "spread_floor_rad_s": BIAS_SPREAD_FLOOR,
                                  "mems_bound_rad_s": MEMS_BIAS_BOUND}
        if (self.moving_std is not None or self.still_error_std is not None or self.gravity_error_std is not None
                or self.measured_rms):
            out["measured"] = {"moving_std_rad_s": None if self.moving_std is None else list(self.moving_std),
                               "still_error_std_rad_s": None if self.still_error_std is None else list(self.still_error_std),
                               "gravity_error_std_rad_s": self.gravity_error_std,
                               "rms_rad_s": {k: {"error": e, "profile_alone": a} for k, e, a in self.measured_rms},
                               "random_walk_rad_s_sqrt_s": self.random_walk,
                               "rest_to_motion_rad_s": None if self.rest_to_motion is None else list(self.rest_to_motion)}
        return out

    def shift(self) -> np.ndarray:
        """The rest-to-motion change the still estimate adds [rad/s] (3,): zero where not measured."""
        return np.zeros(3) if self.rest_to_motion is None else np.asarray(self.rest_to_motion, dtype=np.float64)

    def rest_std(self) -> np.ndarray:
        """(3,) rad/s: the spread of what the gyro reads at rest, the still rule's sigma. Where the device's
        training recordings measured it (``moving_std``): sqrt(moving_std² + still_error_std² + shift²) per
        axis (the bias while moving, how far rest reads from it, the systematic change between them),
        floored at :data:`BIAS_SPREAD_FLOOR` and at most ``std``; else ``std``. A profile's ``bias_std``
        is the spread of its full floor's refits per recording, where a bias trades with terms the motion
        barely excites (a level robot's g-sensitivity: Fetch's 34-138 mrad/s against 1-5 measured), so
        that spread lets a slow steady turn pass for rest."""
        std = np.asarray(self.std, dtype=np.float64)
        if self.moving_std is None:
            return std
        parts = [np.asarray(self.moving_std), np.zeros(3) if self.still_error_std is None
                 else np.asarray(self.still_error_std), self.shift()]
        spread = np.sqrt(sum(np.square(x) for x in parts))
        return np.minimum(np.maximum(spread, BIAS_SPREAD_FLOOR), std)


MEMS_PRIOR = BiasPrior()


def at_rest(gyro_mean: np.ndarray, acc_norm: Optional[np.ndarray], gravity: Optional[float],
            prior: BiasPrior = MEMS_PRIOR, sigmas: float = STILL_SIGMAS,
            acc_tol: float = ACC_NORM_TOL) -> np.ndarray:
    """THE still rule (module doc), on quiet windows: the mean gyro (..., 3) within ``sigmas`` of the
    prior's spread of its bias on every axis, and (``gravity`` set) the mean accelerometer norm (...)
    within ``acc_tol`` of ``gravity``. Returns a bool array (...)."""
    g = np.asarray(gyro_mean, dtype=np.float64)
    ok = np.all(np.abs(g - np.asarray(prior.bias)) <= sigmas * prior.rest_std(), axis=-1)
    if gravity is not None and acc_norm is not None:
        ok &= np.abs(np.asarray(acc_norm, dtype=np.float64) - gravity) <= acc_tol
    return ok


@dataclass(frozen=True)
class StillSettings:
    """How still stretches are found (module doc): every axis's moving standard deviation over
    ``window_s`` below ``factor`` x its 5th percentile over the recording and below the caps; with
    ``gravity`` [m/s^2] set, the window's mean accelerometer norm within ``gravity_tol`` of it;
    stretches shorter than ``min_s`` dropped, ``trim_s`` cut from each end."""

    window_s: float = 1.0
    factor: float = 3.0
    gyro_cap: float = 0.05  # rad/s
    acc_cap: float = 0.5  # m/s^2
    min_s: float = 2.0
    trim_s: float = 0.25
    gravity: Optional[float] = None  # m/s^2; None: the norm is not checked
    gravity_tol: float = ACC_NORM_TOL  # m/s^2
    prior: Optional[BiasPrior] = None  # the still rule's gyro check on each stretch (module doc); None: not checked


def moving_mean(x: np.ndarray, n: int) -> np.ndarray:
    """Mean of each column over the n samples centred on each sample (edges: the nearest full window)."""
    x = np.asarray(x, dtype=np.float64)
    x2 = x.reshape(len(x), -1)
    if len(x2) < n or n < 1:
        return np.full(x.shape, np.nan)
    c = np.concatenate([np.zeros((1, x2.shape[1])), np.cumsum(x2, axis=0)])
    m = (c[n:] - c[:-n]) / n
    return _centre(m, len(x2), n).reshape(x.shape)


def _centre(w: np.ndarray, length: int, n: int) -> np.ndarray:
    lo = n // 2
    out = np.empty((length, w.shape[1]))
    out[lo:lo + len(w)] = w
    out[:lo] = w[0]
    out[lo + len(w):] = w[-1]
    return out


def moving_std(x: np.ndarray, n: int) -> np.ndarray:
    """Standard deviation of each column over the n samples centred on each sample (edges: the
    nearest full window)."""
    x = np.asarray(x, dtype=np.float64)
    if len(x) < n or n < 2:
        return np.full(x.shape, np.inf)
    c1 = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x - x.mean(0), axis=0)])
    c2 = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum((x - x.mean(0)) ** 2, axis=0)])
    s1, s2 = c1[n:] - c1[:-n], c2[n:] - c2[:-n]
    sd = np.sqrt(np.maximum(s2 / n - (s1 / n) ** 2, 0.0))
    return _centre(sd, len(x), n)


def still_stretches(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
                    settings: StillSettings = StillSettings()) -> List[Tuple[int, int]]:
    """[i0, i1) index ranges where the IMU is still (by its own samples; see :class:`StillSettings`):
    quiet windows at gravity's norm, joined into stretches; with ``settings.prior``, only the
    stretches whose mean gyro passes the still rule (:func:`at_rest`)."""
    if len(t_ns) < 4:
        return []
    period = median_period_ns(t_ns) * 1e-9
    n = max(2, int(round(settings.window_s / period)))
    sg, sa = moving_std(gyro, n).max(1), moving_std(acc, n).max(1)
    if not np.isfinite(sg).any():
        return []
    thr_g = min(settings.factor * np.percentile(sg, 5), settings.gyro_cap)
    thr_a = min(settings.factor * np.percentile(sa, 5), settings.acc_cap)
    still = (sg <= thr_g) & (sa <= thr_a)
    if settings.gravity is not None:
        norm = np.linalg.norm(moving_mean(acc, n), axis=1)
        still &= np.abs(norm - settings.gravity) <= settings.gravity_tol
    gaps = np.diff(np.asarray(t_ns, dtype=np.int64)) > 1.5 * median_period_ns(t_ns)
    edges = np.flatnonzero(np.diff(np.r_[0, still.astype(np.int8), 0]))
    trim = int(round(settings.trim_s / period))
    out = []
    for i0, i1 in zip(edges[::2], edges[1::2]):
        i0, i1 = i0 + trim, i1 - trim
        # a gap in the stamps ends a stretch: keep the longest gap-free part
        cuts = np.r_[i0, np.flatnonzero(gaps[i0:max(i0, i1 - 1)]) + i0 + 1, i1]
        a, b = max(zip(cuts[:-1], cuts[1:]), key=lambda ab: ab[1] - ab[0])
        if (b - a) * period >= settings.min_s:
            out.append((int(a), int(b)))
    if settings.prior is not None:  # the still rule's gyro check, on each stretch's mean
        out = [(a, b) for a, b in out if at_rest(gyro[a:b].mean(0), None, None, settings.prior)]
    return out


# The settings refine's and navigate's still-stretch bias uses: the detector with the still rule on
# (gravity's norm and, unless a caller gives its own prior, the MEMS prior).
BIAS_SETTINGS = StillSettings(gravity=9.80665, prior=MEMS_PRIOR)


@dataclass
class StillBias:
    """A recording's gyro bias from its still stretches (module doc). ``gyro_bias`` [rad/s] (3,),
    None without a still stretch; ``gyro_bias_std`` its white-noise standard error per axis;
    ``between_stretches`` the standard deviation of the stretches' means per axis (None with one);
    ``acc_norm_minus_gravity`` [m/s^2] the norm of the accelerometer's mean over each stretch (its
    own attitude), averaged over the stretches by their samples, minus gravity (its bias and scale error along gravity); ``stretches`` each used one's range."""

    gyro_bias: Optional[np.ndarray]
    gyro_bias_std: Optional[np.ndarray]
    between_stretches: Optional[np.ndarray]
    acc_norm_minus_gravity: Optional[float]
    still_s: float
    samples: int
    stretches: List[Dict[str, float]]
    settings: StillSettings
    # quiet stretches (at gravity's norm) the still rule's gyro check refused: a steady turn, not rest
    refused: List[Dict[str, object]] = field(default_factory=list)

    def to_dict(self) -> Dict[str, object]:
        """Plain values for a summary (rad/s and m/s^2, with deg/s beside the bias)."""
        def vec(x: Optional[np.ndarray]) -> Optional[List[float]]:
            return None if x is None else [float(v) for v in x]

        s = self.settings
        return {
            "gyro_bias_rad_s": vec(self.gyro_bias),
            "gyro_bias_deg_s": vec(None if self.gyro_bias is None else np.rad2deg(self.gyro_bias)),
            "gyro_bias_std_rad_s": vec(self.gyro_bias_std),
            "between_stretches_std_rad_s": vec(self.between_stretches),
            "acc_norm_minus_gravity_m_s2": self.acc_norm_minus_gravity,
            "observable": "gyro bias: every axis; accelerometer bias: only along gravity (the norm above), "
                          "from one still attitude",
            "still_s": round(self.still_s, 3),
            "samples": self.samples,
            "stretches": self.stretches,
            "detector": {"window_s": s.window_s, "factor_of_5th_percentile": s.factor, "gyro_std_cap_rad_s": s.gyro_cap,
                         "acc_std_cap_m_s2": s.acc_cap, "gravity_m_s2": s.gravity, "gravity_tol_m_s2": s.gravity_tol,
                         "min_s": s.min_s, "trim_s": s.trim_s,
                         "gyro_within_sigmas_of_prior": None if s.prior is None else STILL_SIGMAS,
                         "prior": None if s.prior is None else s.prior.to_dict()},
            "refused_as_turning": self.refused,
        }


def still_bias(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
               settings: StillSettings = BIAS_SETTINGS) -> StillBias:
    """The gyro bias of a recording from its still stretches (module doc)."""
    t = np.asarray(t_ns, dtype=np.int64)
    gyro, acc = np.asarray(gyro, dtype=np.float64), np.asarray(acc, dtype=np.float64)
    found = still_stretches(t, gyro, acc, settings)
    refused = _refused(t, gyro, acc, settings, found)
    if not found:
        return StillBias(None, None, None, None, 0.0, 0, [], settings, refused)
    g = np.concatenate([gyro[a:b] for a, b in found])
    # each stretch's own attitude: the norm of its mean, weighted by its samples
    norms = np.array([np.linalg.norm(acc[a:b].mean(0)) for a, b in found])
    weights = np.array([b - a for a, b in found], dtype=np.float64)
    means = np.array([gyro[a:b].mean(0) for a, b in found])
    info = [{"t0_s": round(float(t[a] - t[0]) * 1e-9, 3), "duration_s": round(float(t[b - 1] - t[a]) * 1e-9, 3),
             "gyro_mean_rad_s": [float(v) for v in gyro[a:b].mean(0)]} for a, b in found]
    gravity = settings.gravity if settings.gravity is not None else math.nan
    return StillBias(
        gyro_bias=g.mean(0),
        gyro_bias_std=g.std(0, ddof=1) / math.sqrt(len(g)),
        between_stretches=means.std(0, ddof=1) if len(found) > 1 else None,
        acc_norm_minus_gravity=float(np.average(norms, weights=weights) - gravity) if math.isfinite(gravity) else None,
        still_s=sum(float(t[b - 1] - t[a]) * 1e-9 for a, b in found),
        samples=int(len(g)),
        stretches=info,
        settings=settings,
        refused=refused,
    )


def _refused(t: np.ndarray, gyro: np.ndarray, acc: np.ndarray, settings: StillSettings,
             found: List[Tuple[int, int]]) -> List[Dict[str, object]]:
    """The quiet stretches the still rule's gyro check refused (found without the prior, overlapping
    none found with it): each one's start, length and mean gyro."""
    if settings.prior is None:
        return []
    out = []
    for a, b in still_stretches(t, gyro, acc, replace(settings, prior=None)):
        if any(a < d and c < b for c, d in found):
            continue
        out.append({"t0_s": round(float(t[a] - t[0]) * 1e-9, 3), "duration_s": round(float(t[b - 1] - t[a]) * 1e-9, 3),
                    "gyro_mean_rad_s": [float(v) for v in gyro[a:b].mean(0)]})
    return out
