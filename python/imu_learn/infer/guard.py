"""Does a recording look like the data a model (or profile) was made from? A guard that needs no
ground truth.

**What is recorded** (:func:`input_stats`, per training recording; a checkpoint's ``inputs``, written
by :func:`imu_learn.infer.checkpoint.training_record`): the sample rate and length; per axis of gyro
[rad/s] and accelerometer [m/s^2] the median, standard deviation and the 1st / 99th percentiles;
the 5 / 50 / 95th percentiles of |gyro| and |acc|; and a low-order spectrum (the share of each
sensor's variance, axes summed, in the bands 0-1, 1-5, 5-20 Hz and 20 Hz to Nyquist). For a model
also the size of what it adds (:func:`residual_rms`: the RMS per axis of refined - input, on each
training recording, by the windowing rule it is applied with).

**The rule** (:func:`compare`): each statistic of the recording against its range over the training
recordings [lo, hi], widened (the spectrum is recorded for reading, not checked: a minute's crop of a
training flight already moves its shares by more than a different device does):

* a location (per-axis median, median |acc|) may lie at most ``max(0.5 (hi - lo), floor)`` outside,
  either side, with the floor :data:`SHIFT_FLOOR` (gyro median 0.05 rad/s, accelerometer median
  0.5 m/s^2, median |acc| 0.3 m/s^2): an offset, a scale error, another mounting;
* a tail (per-axis 1st percentile below, 99th above) at most ``max(0.5 (hi - lo), the training's
  mean standard deviation of that axis)`` beyond: motion more violent than any seen (a gentler
  recording is inside what the model saw, and is not flagged);
* a spread (per-axis standard deviation, |gyro| median, 95th percentiles of |gyro| and |acc|) at
  most :data:`SPREAD_FACTOR` (2) x the largest (again only upwards);
* the model's residual: its RMS on the recording at most :data:`RESIDUAL_FACTOR` (3) x the largest
  on a training recording (plus 1e-4 rad/s, 1e-3 m/s^2), per axis.

Any statistic outside is a warning (one line naming the worst few); the verdict and every figure go
into refine's summary. One case stops (:func:`unit_mistake`, before any work): the gyro's per-axis medians
outside the location bound as read and inside it once the unit the user declared (``--gyro-unit``) is
swapped for the other (x 180/pi, x pi/180): the profile's own device then decides the unit. Otherwise it
warns, never stops: a recording can be unlike the training data and still
be refined well, and one like it can still be refined badly; the guard says only that the model is
used outside what it saw. A checkpoint or profile without ``inputs`` (written before this) cannot be
checked: one info line.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.core.stamps import sample_rate_hz

VERSION = 1
BANDS_HZ = (0.0, 1.0, 5.0, 20.0)  # lower edges; the last band runs to Nyquist
SHIFT_FLOOR = {"gyro_median": 0.05, "acc_median": 0.5, "acc_norm_median": 0.3}  # [rad/s], [m/s^2]
PERCENTILE_FLOOR = 1.0  # x the training's mean standard deviation of that axis
SPREAD_FACTOR = 2.0
RESIDUAL_FACTOR = 3.0
RESIDUAL_FLOOR = {"gyro": 1e-4, "acc": 1e-3}
SHOWN = 3  # statistics named in the warning line


def _vec(x: np.ndarray) -> List[float]:
    return [float(v) for v in np.asarray(x, dtype=np.float64).ravel()]


def _bands(x: np.ndarray, rate_hz: float) -> List[float]:
    """Share of the variance (axes summed) in each of :data:`BANDS_HZ`."""
    x = np.asarray(x, dtype=np.float64)
    if len(x) < 16 or not rate_hz:
        return [math.nan] * len(BANDS_HZ)
    p = (np.abs(np.fft.rfft(x - x.mean(0), axis=0)) ** 2).sum(1)
    f = np.fft.rfftfreq(len(x), 1.0 / rate_hz)
    edges = list(BANDS_HZ) + [math.inf]
    total = float(p[1:].sum())
    if total <= 0:
        return [0.0] * len(BANDS_HZ)
    return [float(p[1:][(f[1:] >= lo) & (f[1:] < hi)].sum() / total) for lo, hi in zip(edges[:-1], edges[1:])]


def input_stats(t_ns: Optional[np.ndarray], gyro: np.ndarray, acc: np.ndarray,
                rate_hz: Optional[float] = None) -> Dict[str, Any]:
    """The statistics of one recording's IMU (module doc), plain values. ``rate_hz``: the rate when
    there are no stamps (else the one sample-rate rule over ``t_ns``)."""
    gyro, acc = np.asarray(gyro, dtype=np.float64), np.asarray(acc, dtype=np.float64)
    if t_ns is not None and len(t_ns) > 1:
        rate_hz = sample_rate_hz(np.asarray(t_ns, dtype=np.int64))
    out: Dict[str, Any] = {"rate_hz": float(rate_hz) if rate_hz else None, "samples": int(len(gyro)),
                           "seconds": float(len(gyro) / rate_hz) if rate_hz else None}
    for name, x in (("gyro", gyro), ("acc", acc)):
        q = np.percentile(x, [1, 50, 99], axis=0)
        out[f"{name}_median"] = _vec(q[1])
        out[f"{name}_std"] = _vec(x.std(0))
        out[f"{name}_p01"] = _vec(q[0])
        out[f"{name}_p99"] = _vec(q[2])
        n = np.percentile(np.linalg.norm(x, axis=1), [5, 50, 95])
        out[f"{name}_norm_p05"], out[f"{name}_norm_median"], out[f"{name}_norm_p95"] = (float(v) for v in n)
        out[f"{name}_bands"] = _bands(x, rate_hz or 0.0)
    return out


def residual_rms(gyro_in: np.ndarray, acc_in: np.ndarray, gyro_out: np.ndarray, acc_out: np.ndarray) -> Dict[str, List[float]]:
    """RMS per axis of what a model added (out - in), gyro [rad/s] and acc [m/s^2]."""
    def rms(d: np.ndarray) -> List[float]:
        return _vec(np.sqrt(np.mean(np.asarray(d, dtype=np.float64) ** 2, axis=0)))

    return {"gyro": rms(np.asarray(gyro_out) - gyro_in), "acc": rms(np.asarray(acc_out) - acc_in)}


def training_inputs(recordings: Sequence[Tuple[str, Optional[np.ndarray], np.ndarray, np.ndarray]]) -> Dict[str, Any]:
    """A checkpoint's or profile's ``inputs``: :func:`input_stats` of each (name, t_ns, gyro, acc)."""
    return {"version": VERSION, "recordings": [{"name": n, **input_stats(t, g, a)} for n, t, g, a in recordings]}


# -- the comparison ----------------------------------------------------------------------------------


def _training_range(recs: List[Dict[str, Any]], key: str) -> Tuple[np.ndarray, np.ndarray]:
    v = np.array([np.atleast_1d(np.asarray(r[key], dtype=np.float64)) for r in recs])
    return np.nanmin(v, 0), np.nanmax(v, 0)


def _check(name: str, value: Any, lo: np.ndarray, hi: np.ndarray, allowed_lo: np.ndarray, allowed_hi: np.ndarray,
           how: str) -> List[Dict[str, Any]]:
    v = np.atleast_1d(np.asarray(value, dtype=np.float64))
    out = []
    for i in range(len(v)):
        if not math.isfinite(v[i]) or allowed_lo[i] <= v[i] <= allowed_hi[i]:
            continue
        # how far outside, in widths of the allowed margin (for ordering the warning)
        margin = max(allowed_hi[i] - hi[i], hi[i] - lo[i], 1e-12) if v[i] > hi[i] else max(lo[i] - allowed_lo[i], hi[i] - lo[i], 1e-12)
        far = (v[i] - hi[i]) / margin if v[i] > hi[i] else (lo[i] - v[i]) / margin
        axis = f"[{'xyz'[i]}]" if len(v) == 3 else (f"[band {i}]" if len(v) > 1 else "")
        out.append({"statistic": f"{name}{axis}", "value": float(v[i]), "training": [float(lo[i]), float(hi[i])],
                    "allowed": [float(allowed_lo[i]), float(allowed_hi[i])], "rule": how, "outside_by": float(far)})
    return out


def _location_bounds(recs: List[Dict[str, Any]], key: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(lo, hi, allowed lo, allowed hi) of a location statistic: the training's range widened by
    max(half of it, :data:`SHIFT_FLOOR`) either side."""
    lo, hi = _training_range(recs, key)
    m = np.maximum(0.5 * (hi - lo), SHIFT_FLOOR[key])
    return lo, hi, lo - m, hi + m


# the unit a user declared for the gyro columns -> (the factor from what was read to what the other unit
# reads, the other unit's option)
OTHER_GYRO_UNIT = {"deg/s": (180.0 / math.pi, "drop --gyro-unit deg/s (the columns are in rad/s)"),
                   "rad/s": (math.pi / 180.0, "add --gyro-unit deg/s")}


def unit_mistake(training: Optional[Dict[str, Any]], gyro: np.ndarray, gyro_unit: Optional[str], what: str
                 ) -> Optional[str]:
    """One line (None: no such mistake) where the gyro's per-axis medians [rad/s, as read in ``gyro_unit``]
    lie outside the location bound of ``what``'s training recordings and inside it once read in the other
    unit (module doc). ``gyro_unit`` None: the format fixes the unit (nothing declared to doubt)."""
    if not training or not training.get("recordings") or gyro_unit not in OTHER_GYRO_UNIT or not len(gyro):
        return None
    _, _, a_lo, a_hi = _location_bounds(training["recordings"], "gyro_median")
    med = np.median(np.asarray(gyro, dtype=np.float64), axis=0)
    k, fix = OTHER_GYRO_UNIT[gyro_unit]
    outside = (med < a_lo) | (med > a_hi)
    if not outside.any() or np.any((med * k < a_lo) | (med * k > a_hi)):
        return None
    axes = "".join("xyz"[i] for i in np.flatnonzero(outside))
    return (f"the gyro's median per axis ({', '.join(f'{v:.3g}' for v in med)} rad/s, read as {gyro_unit}) lies "
            f"outside what {what}'s device reads on axis {axes} (allowed {', '.join(f'{lo:.3g}..{hi:.3g}' for lo, hi in zip(a_lo, a_hi))}) "
            f"and inside it read in the other unit (x{k:.4g}): {fix}")


def compare(training: Dict[str, Any], recording: Dict[str, Any],
            residual: Optional[Dict[str, Any]] = None, training_residual: Optional[Sequence[Dict[str, Any]]] = None,
            device_only: bool = False) -> List[Dict[str, Any]]:
    """The statistics of ``recording`` (:func:`input_stats`) outside the rule's bounds around
    ``training`` (:func:`training_inputs`), worst first; with ``residual`` (:func:`residual_rms` on
    the recording) and ``training_residual`` (one per training recording), the model's residual too.
    ``device_only`` (a profile: an affine floor does not depend on how hard the recording moves): the
    locations alone (per-axis medians, median |acc|), which another device or mounting moves."""
    recs = training["recordings"]
    out: List[Dict[str, Any]] = []
    inf = np.full(3, np.inf)
    for sensor in ("gyro", "acc"):
        mean_std = np.mean([r[f"{sensor}_std"] for r in recs], axis=0)
        key = f"{sensor}_median"
        out += _check(key, recording[key], *_location_bounds(recs, key), "within max(half the training range, the floor)")
        if device_only:
            continue
        lo, hi = _training_range(recs, f"{sensor}_p01")
        m = np.maximum(0.5 * (hi - lo), PERCENTILE_FLOOR * mean_std)
        out += _check(f"{sensor}_p01", recording[f"{sensor}_p01"], lo, hi, lo - m, inf,
                      "not below by more than max(half the training range, the training std)")
        lo, hi = _training_range(recs, f"{sensor}_p99")
        m = np.maximum(0.5 * (hi - lo), PERCENTILE_FLOOR * mean_std)
        out += _check(f"{sensor}_p99", recording[f"{sensor}_p99"], lo, hi, -inf, hi + m,
                      "not above by more than max(half the training range, the training std)")
        for key in (f"{sensor}_std", f"{sensor}_norm_p95") + ((f"{sensor}_norm_median",) if sensor == "gyro" else ()):
            lo, hi = _training_range(recs, key)
            out += _check(key, recording[key], lo, hi, np.full(len(lo), -np.inf), hi * SPREAD_FACTOR,
                          f"at most {SPREAD_FACTOR:g} x the largest")
    out += _check("acc_norm_median", recording["acc_norm_median"], *_location_bounds(recs, "acc_norm_median"),
                  f"within max(half the training range, {SHIFT_FLOOR['acc_norm_median']:g} m/s^2)")
    if residual is not None and training_residual:
        for sensor in ("gyro", "acc"):
            top = np.max([r[sensor] for r in training_residual], axis=0)
            allowed = RESIDUAL_FACTOR * top + RESIDUAL_FLOOR[sensor]
            out += _check(f"model_residual_rms_{sensor}", residual[sensor], np.zeros(3), top, np.full(3, -np.inf), allowed,
                          f"at most {RESIDUAL_FACTOR:g} x the largest on a training recording")
    return sorted(out, key=lambda d: -d["outside_by"])


def verdict(training: Optional[Dict[str, Any]], recording: Dict[str, Any], what: str,
            residual: Optional[Dict[str, Any]] = None, device_only: bool = False
            ) -> Tuple[Dict[str, Any], Optional[str], Optional[str]]:
    """(the summary's ``guard`` entry, a warning line or None, an info line or None) for applying
    ``what`` (a model or profile with training ``inputs``, None: not recorded) to a recording;
    ``device_only``: :func:`compare`'s (a profile)."""
    if not training or not training.get("recordings"):
        info = f"{what} records no statistics of its training data: the guard cannot check the recording against them"
        return {"verdict": "unchecked", "recording": recording, "residual_rms": residual}, None, info
    outside = compare(training, recording, residual, training.get("residual_rms"), device_only)
    entry = {"verdict": "unlike the training data" if outside else "like the training data",
             "rule": "docs/refine.md (Guard)" + (": the locations alone (a profile)" if device_only else ""),
             "outside": outside, "recording": recording, "residual_rms": residual,
             "training_recordings": [r.get("name") for r in training["recordings"]]}
    if not outside:
        return entry, None, None
    shown = "; ".join(f"{d['statistic']} {d['value']:.4g} (training {d['training'][0]:.4g}..{d['training'][1]:.4g})"
                      for d in outside[:SHOWN])
    more = f" and {len(outside) - SHOWN} more" if len(outside) > SHOWN else ""
    if device_only:
        return entry, (f"the recording looks unlike the IMU {what} was fitted on: {shown}{more}; another device or "
                       "mounting? its floor may make the data worse (the summary lists every statistic)"), None
    return entry, (f"the recording looks unlike {what}'s training data: {shown}{more}; its output may be worse than "
                   "the input (the summary lists every statistic)"), None
