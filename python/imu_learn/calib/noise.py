"""The noise of an IMU: white-noise density, bias random walk and bias instability, per axis, from
two kinds of data.

**Residuals against a reference** (:func:`residual_noise`). With the floor applied (time offset and
affine model, *without* its low-pass: a filter would hide the very noise measured), the residual
rate of each sample is what the reference cannot explain:

    gyroscope      e_i = w_i - Log(q_i^-1 q_i+1) / dt_i                      [rad/s]
    accelerometer  e_i = a_i - R_i^T ((v_i+1 - v_i) / dt_i - g_w)             [m/s^2]

(the zero-order hold the floor was fitted for: sample i acts over [t_i, t_i+1] with the attitude
at t_i). The overlapping Allan deviation of e is the spread of the mean residual over windows of
τ seconds, differenced between neighbouring windows: over short windows that is the spread of the
calibrated increments against the reference increments (the white-noise density), over long ones
the drift of a per-window bias (the random walk); a constant bias and constant calibration errors
cancel in the difference. The reference adds its own error: a noisy attitude or velocity enters
through the end points of each window only, so its Allan variance falls as τ^-2. Hence the fit, per
axis, by non-negative weighted least squares of the Allan *variance* (IEEE Std 952's power-law sum,
each point weighted by its relative error) over every τ whose relative error is at most 0.3::

    σ²(τ) = R/τ²  +  N²/τ  +  F  +  K² τ / 3
            reference   white    flat (bias instability)   rate random walk

N (density) and K (random walk) are Kalibr's figures; their standard deviations come from the fit's
covariance scaled by its reduced χ² (the points are correlated, so this is a floor on the truth).
A coefficient fitted to zero is *not observed* (NaN). What this cannot separate: motion-correlated
errors (a vibrating platform, calibration errors that vary with the motion, a smoothed reference)
that happen to fall on one of these slopes; that is why a still stretch, when there is one, wins.

**Still stretches** (:func:`allan_noise`): where the IMU itself is still (the package's one
detector, :func:`imu_learn.core.still.still_stretches`: every axis's spread over ``window_s`` small
against the quietest part of the recording and below absolute caps; no gravity check here), the overlapping Allan deviation of the raw samples, pooled over the stretches
(variance weighted by cluster count), with the standard slope fits of the core
(:func:`imu_learn.core.allan.fit_noise`: N at τ = 1 s on the −1/2 line, K at τ = 3 s on the +1/2
line, B at the minimum).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.core.allan import AllanDeviation, NoiseFit, allan_deviation, fit_noise
from imu_learn.core.nnls import nonneg_lstsq
from imu_learn.core.quat import quat_conj, quat_log, quat_mul, quat_rotate
from imu_learn.core.stamps import median_period_ns
from imu_learn.core.still import StillSettings, moving_std, still_stretches  # noqa: F401  (the one detector)

MAX_REL_ERR = 0.3
MIN_RANDOM_WALK_TAU_S = 1.0  # a still stretch's +1/2 slope counts as a bias random walk from here up
TERMS = ("reference", "white", "flat", "random_walk")  # powers of τ: -2, -1, 0, +1


def residual_rates(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, q_wxyz: np.ndarray, v: np.ndarray,
                   gravity: float) -> Tuple[np.ndarray, np.ndarray]:
    """(gyro, acc) residual rates (N-1, 3) of calibrated samples against the reference (module doc)."""
    dt = (np.diff(np.asarray(t_ns, dtype=np.int64)) * 1e-9)[:, None]
    q0, q1 = q_wxyz[:-1], q_wxyz[1:]
    w_ref = quat_log(quat_mul(quat_conj(q0), q1)) / dt
    g_w = np.array([0.0, 0.0, -gravity])
    a_ref = quat_rotate(quat_conj(q0), np.diff(v, axis=0) / dt - g_w)
    return np.asarray(gyro)[:-1] - w_ref, np.asarray(acc)[:-1] - a_ref


def cluster_sizes(n_max: int, per_decade: int = 10) -> np.ndarray:
    """Log-spaced cluster sizes 1 .. n_max // 2 (distinct integers)."""
    if n_max < 4:
        return np.array([1], dtype=np.uint64)
    m = np.unique(np.round(np.logspace(0, math.log10(n_max // 2), max(2, int(per_decade * math.log10(n_max / 2)) + 1))))
    return m.astype(np.uint64)


def pooled_allan(series: Sequence[np.ndarray], period_s: float, per_decade: int = 10) -> Optional[AllanDeviation]:
    """Overlapping Allan deviation of several gap-free stretches (each (N_j, k)) of one period,
    pooled: at each cluster size the variance is the mean of the stretches' variances weighted by
    their cluster counts (stretches shorter than two clusters left out). None if nothing is long
    enough."""
    series = [np.ascontiguousarray(s, dtype=np.float64) for s in series if len(s) >= 4]
    if not series:
        return None
    m = cluster_sizes(max(len(s) for s in series), per_decade)
    k = series[0].shape[1]
    var, count = np.zeros((len(m), k)), np.zeros(len(m))
    for s in series:
        ok = m <= len(s) // 2
        if not ok.any():
            continue
        d = allan_deviation(s, period_s, m=m[ok])
        w = d.n_clusters.astype(np.float64)
        var[ok] += w[:, None] * d.adev**2
        count[ok] += w
    keep = count > 1
    m, var, count = m[keep], var[keep], count[keep]
    rel = 1.0 / np.sqrt(2.0 * (count - 1.0))
    return AllanDeviation(m * period_s, m, count.astype(np.uint64), rel, np.sqrt(var / count[:, None]), period_s,
                          int(sum(len(s) for s in series)))


@dataclass
class PowerLawFit:
    """Per axis (k,): the coefficients of the module's power-law sum and their standard deviations
    (NaN: not observed), the τ range fitted and the points used."""

    white: np.ndarray  # N
    white_std: np.ndarray
    random_walk: np.ndarray  # K
    random_walk_std: np.ndarray
    flat: np.ndarray  # sqrt(F) [unit]: the flat floor (bias instability B = sqrt(F) / 0.664)
    reference: np.ndarray  # sqrt(R) [unit·s]: the reference's own error
    tau_range: Tuple[float, float]
    points: int
    curve: Dict[str, np.ndarray] = field(default_factory=dict)  # each term's σ(τ) on dev.tau_s, for the plot


def power_law_fit(dev: AllanDeviation, max_rel_err: float = MAX_REL_ERR) -> PowerLawFit:
    """The non-negative weighted least-squares fit of σ²(τ) (module doc), each axis of ``dev``."""
    use = dev.rel_err <= max_rel_err
    tau, rel = dev.tau_s[use], dev.rel_err[use]
    k = dev.adev.shape[1]
    out = {n: np.full(k, np.nan) for n in ("N", "Ns", "K", "Ks", "F", "R")}
    curve = {t: np.full((len(dev.tau_s), k), np.nan) for t in TERMS}
    if len(tau) < 5:
        return PowerLawFit(out["N"], out["Ns"], out["K"], out["Ks"], out["F"], out["R"], (math.nan, math.nan), 0, curve)
    basis = lambda t: np.stack([t**-2.0, t**-1.0, np.ones_like(t), t / 3.0], axis=1)  # noqa: E731
    A = basis(tau)
    for j in range(k):
        y = dev.adev[use, j] ** 2
        w = 1.0 / (2.0 * rel * y)  # σ² of a variance point ≈ (2 rel y)²
        c, _ = nonneg_lstsq(A * w[:, None], y * w)
        r = (A @ c - y) * w
        active = c > 0
        cov = np.full((4, 4), np.nan)
        if active.any() and len(y) > active.sum():
            Aa = (A * w[:, None])[:, active]
            s2 = float(r @ r) / (len(y) - active.sum())
            ca = np.linalg.pinv(Aa.T @ Aa) * max(s2, 1.0)
            cov[np.ix_(active, active)] = ca
        if c[1] > 0:
            out["N"][j] = math.sqrt(c[1])
            out["Ns"][j] = math.sqrt(max(cov[1, 1], 0.0)) / (2.0 * out["N"][j])
        if c[3] > 0:
            out["K"][j] = math.sqrt(c[3])  # the basis holds τ/3: c[3] = K²
            out["Ks"][j] = math.sqrt(max(cov[3, 3], 0.0)) / (2.0 * out["K"][j])
        out["F"][j] = math.sqrt(c[2]) if c[2] > 0 else math.nan
        out["R"][j] = math.sqrt(c[0]) if c[0] > 0 else math.nan
        full = basis(dev.tau_s)
        for i, t in enumerate(TERMS):
            curve[t][:, j] = np.sqrt(full[:, i] * c[i]) if c[i] > 0 else np.nan
    return PowerLawFit(out["N"], out["Ns"], out["K"], out["Ks"], out["F"], out["R"],
                       (float(tau[0]), float(tau[-1])), int(len(tau)), curve)


# An IMU's white noise shows in its own sample-to-sample variation: the robust spread of its second
# differences (6 σ² for white noise; smooth motion adds little at the sampling rate, vibration adds its
# share) gives the density its samples allow (:func:`own_density`). The IMU's internal low-pass lowers that
# spread: a cut-off at a quarter of the rate by 3.6x, hence the margin. A residual white noise above
# OWN_MARGIN times it is the reference's noise (a motion capture interpolated onto the IMU's stamps:
# TUM-VI's 8e-3 rad/s/sqrt(Hz) against the 1e-4 the BMI160's samples allow), not the IMU's.
OWN_MARGIN = 5.0


def own_density(t_ns: Sequence[np.ndarray], x: Sequence[np.ndarray]) -> np.ndarray:
    """Per axis, the white-noise density [unit/sqrt(Hz)] the samples ``x`` (segments of (N, 3)) allow: the
    median absolute second difference over every segment, as a standard deviation (/0.6745), / sqrt(6),
    / sqrt(rate)."""
    d2 = [np.diff(np.asarray(v, dtype=np.float64), n=2, axis=0) for v in x if len(v) > 2]
    if not d2:
        return np.full(3, np.nan)
    period_s = float(np.median([median_period_ns(t) for t in t_ns])) * 1e-9
    sigma = np.median(np.abs(np.concatenate(d2)), axis=0) / 0.6745 / math.sqrt(6.0)
    return sigma * math.sqrt(period_s)


@dataclass
class ResidualNoise:
    """The residuals' Allan deviations (gyro, acc) and their power-law fits; ``*_own``: the white-noise
    density the calibrated samples themselves allow (:func:`own_density`), per axis."""

    gyro_dev: Optional[AllanDeviation]
    acc_dev: Optional[AllanDeviation]
    gyro: Optional[PowerLawFit]
    acc: Optional[PowerLawFit]
    seconds: float
    gyro_own: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    acc_own: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))


def residual_noise(segments: Sequence, calibrated: Sequence[Tuple[np.ndarray, np.ndarray]], gravity: float) -> ResidualNoise:
    """Residual noise of ``segments`` (each with t_ns, q_wxyz, v) given their calibrated (gyro, acc)."""
    eg, ea, secs = [], [], 0.0
    for s, (g, a) in zip(segments, calibrated):
        rg, ra = residual_rates(s.t_ns, g, a, s.q_wxyz, s.v, gravity)
        eg.append(rg)
        ea.append(ra)
        secs += float(s.t_ns[-1] - s.t_ns[0]) * 1e-9
    if not segments:
        return ResidualNoise(None, None, None, None, 0.0)
    period_s = float(np.median([median_period_ns(s.t_ns) for s in segments])) * 1e-9
    dg, da = pooled_allan(eg, period_s), pooled_allan(ea, period_s)
    stamps = [s.t_ns for s in segments]
    return ResidualNoise(dg, da, power_law_fit(dg) if dg else None, power_law_fit(da) if da else None, secs,
                         own_density(stamps, [g for g, _ in calibrated]), own_density(stamps, [a for _, a in calibrated]))


@dataclass
class AllanNoise:
    """Still stretches' pooled Allan deviation (six axes: gyro x, y, z, acc x, y, z) and the core's
    slope fits."""

    dev: AllanDeviation
    fit: NoiseFit
    seconds: float
    stretches: List[Dict[str, object]]


def allan_noise(pieces: Sequence[Tuple[str, np.ndarray, np.ndarray, np.ndarray]]) -> Optional[AllanNoise]:
    """Allan noise of still stretches, each (name, t_ns, gyro, acc) gap-free; None without any."""
    pieces = [p for p in pieces if len(p[1]) >= 4]
    if not pieces:
        return None
    period_s = float(np.median([median_period_ns(p[1]) for p in pieces])) * 1e-9
    dev = pooled_allan([np.hstack([g, a]) for _, _, g, a in pieces], period_s, per_decade=20)
    if dev is None:
        return None
    info = [{"recording": name, "t0_ns": int(t[0]), "t1_ns": int(t[-1]), "duration_s": round(float(t[-1] - t[0]) * 1e-9, 3)}
            for name, t, _, _ in pieces]
    secs = sum(float(t[-1] - t[0]) * 1e-9 for _, t, _, _ in pieces)
    return AllanNoise(dev, fit_noise(dev), secs, info)


# -- choosing the figures a profile carries -----------------------------------------------------------

SENSORS = (("gyroscope", slice(0, 3), "gyro"), ("accelerometer", slice(3, 6), "acc"))


def _rms(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if len(x) else math.nan


def _rms_std(value: np.ndarray, std: np.ndarray) -> float:
    """First-order standard deviation of the RMS over axes, from each axis's (independent) std."""
    ok = np.isfinite(value) & np.isfinite(std)
    if not ok.any():
        return math.nan
    v, s = value[ok], std[ok]
    r = math.sqrt(float(np.mean(v * v)))
    return float(np.sqrt(np.sum((v * s) ** 2)) / (len(v) * r)) if r > 0 else math.nan


BOUND_REL_ERR = 0.1  # the points an upper bound is read from


def upper_bound(dev: AllanDeviation, power: float, cols: slice, max_rel_err: float = BOUND_REL_ERR) -> np.ndarray:
    """Per axis, the smallest σ(τ)·sqrt(τ^power · c) over the τ whose relative error is at most
    ``max_rel_err``: every term of σ² is non-negative, so N ≤ min σ(τ) √τ (power 1) and
    K ≤ min σ(τ) √(3/τ) (power -1)."""
    use = dev.rel_err <= max_rel_err
    if not use.any():
        return np.full(cols.stop - cols.start, np.nan)
    # each point raised by three times its relative error: the minimum of many noisy points is not
    # biased below the truth
    scale = np.sqrt(dev.tau_s[use] ** power * (3.0 if power < 0 else 1.0)) * (1.0 + 3.0 * dev.rel_err[use])
    return (dev.adev[use][:, cols] * scale[:, None]).min(0)


@dataclass
class Estimate:
    """One candidate for one figure (a dict entry of the profile's ``noise_estimates``)."""

    name: str
    per_axis: np.ndarray
    std: np.ndarray
    source: str
    kind: str  # "fit" | "standard slope fit" | "upper bound"
    detail: Dict[str, object]

    @property
    def observed(self) -> np.ndarray:
        """Axes with a value whose standard deviation (where known) is below half of it."""
        v, s = self.per_axis, self.std
        return np.isfinite(v) & (v > 0) & ~(np.isfinite(s) & (s > 0.5 * v))


def _reference_noise(white: np.ndarray, own: np.ndarray, band_limit: Optional[str]) -> Optional[str]:
    """Why the residuals' white noise is not the IMU's (None: it is): a reference below the IMU's band, or a
    density more than OWN_MARGIN x what the IMU's own samples allow (the reference's noise)."""
    if band_limit is not None:
        return band_limit
    if np.any(white > OWN_MARGIN * own):
        return (f"the residuals' white noise ({_rms(white):.3g}) lies above {OWN_MARGIN:g}x the density the IMU's own "
                f"samples allow ({_rms(own):.3g}, their second differences in motion): it is the reference's noise")
    return None


def candidates(residual: Optional[ResidualNoise], allan: Optional[AllanNoise], min_still_s: float,
               band_limit: Optional[str] = None) -> List[Estimate]:
    """Every estimate of the four Kalibr figures and the bias instability, best first per figure.
    ``band_limit``: why the reference cannot measure the IMU's white noise (a reference smoothed below the
    IMU's rate, :meth:`imu_learn.calib.sources.Source.band_limit`): the residuals' white noise is then a
    bound, never the IMU's value (the car drive's positions reference: acc 0.037 m/s^2/sqrt(Hz), 2.4x what
    the navigator's innovations fit in motion; docs/experiments/references.md, "Positions only")."""
    out: List[Estimate] = []
    if allan is not None and allan.seconds >= min_still_s:
        f, pl = allan.fit, power_law_fit(allan.dev)
        for sensor, cols, _ in SENSORS:
            n = f.white.value[cols].copy()
            n_std = (f.white.value * f.white.rel_err)[cols].copy()
            weak = f.white.points[cols] < 3  # a line read off fewer than 3 points: the power-law fit instead
            n[weak], n_std[weak] = pl.white[cols][weak], pl.white_std[cols][weak]
            info = {"still_s": round(allan.seconds, 3), "tau_s": [float(f.white.tau_lo[cols].min()), float(f.white.tau_hi[cols].max())],
                    "axes_from_power_law_fit": [int(i) for i in np.flatnonzero(weak)]}
            out.append(Estimate(f"{sensor}_noise_density", n, n_std, "allan", "standard slope fit", info))
            # a +1/2 slope below MIN_RANDOM_WALK_TAU_S is vibration or aliasing, not a bias random walk
            k = np.where(f.random_walk.tau_lo[cols] >= MIN_RANDOM_WALK_TAU_S, f.random_walk.value[cols], np.nan)
            out.append(Estimate(f"{sensor}_random_walk", k, k * f.random_walk.rel_err[cols],
                                "allan", "standard slope fit", {"still_s": round(allan.seconds, 3)}))
            b = np.where(f.bias_observed[cols], f.bias_instability[cols], np.nan)
            out.append(Estimate(f"{sensor}_bias_instability", b, b * f.bias_rel_err[cols], "allan", "standard slope fit",
                                {"tau_s": [float(x) for x in f.tau_bias[cols]]}))
    if residual is not None:
        for sensor, _, key in SENSORS:
            dev, pl = getattr(residual, f"{key}_dev"), getattr(residual, key)
            if dev is None or pl is None:
                continue
            info = {"reference_s": round(residual.seconds, 3), "tau_s": list(pl.tau_range), "points": pl.points}
            own = getattr(residual, f"{key}_own")
            why = _reference_noise(pl.white, own, band_limit)
            if why is not None:  # a bound, never the IMU's value
                detail = {**info, "fit_per_axis": [float(x) for x in pl.white], "why": why}
                if band_limit is None:
                    detail["own_density_per_axis"] = [float(x) for x in own]
                out.append(Estimate(f"{sensor}_noise_density", np.fmin(pl.white, upper_bound(dev, 1.0, slice(0, 3))),
                                    np.full(3, np.nan), "residuals", "upper bound", detail))
            else:
                out.append(Estimate(f"{sensor}_noise_density", pl.white, pl.white_std, "residuals", "fit", info))
            out.append(Estimate(f"{sensor}_random_walk", pl.random_walk, pl.random_walk_std, "residuals", "fit", info))
            nan3 = np.full(3, np.nan)
            out.append(Estimate(f"{sensor}_noise_density", upper_bound(dev, 1.0, slice(0, 3)), nan3, "residuals", "upper bound", info))
            out.append(Estimate(f"{sensor}_random_walk", upper_bound(dev, -1.0, slice(0, 3)), nan3, "residuals", "upper bound", info))
    if allan is not None:  # too little still time for a fit: its bounds still hold
        for sensor, cols, _ in SENSORS:
            info = {"still_s": round(allan.seconds, 3)}
            out.append(Estimate(f"{sensor}_noise_density", upper_bound(allan.dev, 1.0, cols), np.full(3, np.nan), "allan", "upper bound", info))
            out.append(Estimate(f"{sensor}_random_walk", upper_bound(allan.dev, -1.0, cols), np.full(3, np.nan), "allan", "upper bound", info))
    return out


def choose(cands: List[Estimate], names: Sequence[str]) -> Dict[str, Tuple[Estimate, float, float]]:
    """Per figure: the first candidate (``candidates`` orders them) whose axes are all observed;
    else the tightest upper bound. Returns name -> (estimate, Kalibr scalar, its std)."""
    out = {}
    for name in names:
        mine = [c for c in cands if c.name == name]
        fits = [c for c in mine if c.kind != "upper bound" and c.observed.all()]
        if fits:
            c = fits[0]
            out[name] = (c, _rms(c.per_axis), _rms_std(c.per_axis, c.std))
            continue
        bounds = [c for c in mine if c.kind == "upper bound" and np.isfinite(c.per_axis).all()]
        if bounds:
            c = min(bounds, key=lambda c: _rms(c.per_axis))
            out[name] = (c, _rms(c.per_axis), math.nan)
    return out
