"""``imu-learn calibrate``'s work: recordings in, a device profile and its files out.

The recordings come from a reference source (:mod:`imu_learn.calib.sources`: poses, positions, a
config's split, still). With a reference (segments with ground truth): the floor the source fits
(:meth:`Source.fit_floor <imu_learn.calib.sources.Source.fit_floor>`: the affine fit of
:mod:`imu_learn.calib.fit`, unless the source fits its own), its spread between recordings,
gravity, the noise from the residuals (:func:`noise.residual_noise`) and from still stretches
(:func:`noise.still_stretches`, :func:`noise.allan_noise`); with ``select`` (``--select``) the floor's
terms chosen on the recordings each was not fitted on (:mod:`imu_learn.calib.select`). Without one (a still recording's IMU
alone): the noise from its still stretches only. Writes, each atomically,
``profile.json``, ``imu.yaml`` (Kalibr) and ``calibration.png`` into the output folder.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from imu_learn.baselines.affine import Floor, TraditionalParams
from imu_learn.calib import fit as ff
from imu_learn.calib import noise as nz
from imu_learn.calib.kalibr import write_kalibr_yaml
from imu_learn.calib.plausible import LIMITS, held_back_errors, held_back_findings, parameter_findings
from imu_learn.calib.plot import plot_calibration
from imu_learn.calib.profile import (
    CLASS_DEFAULT_SOURCE,
    CLASS_DEFAULTS,
    NOISE_KEYS,
    NOISE_UNITS,
    Affine,
    NoiseTerm,
    Profile,
    noise_only,
    unobserved_term,
)
from imu_learn.calib.select import select_floor
from imu_learn.calib.sources import TIME_OFFSET_PRIOR_SAMPLES, CalibInputs, Recording, StillPiece
from imu_learn.core.stamps import median_period_ns, sample_rate_hz
from imu_learn.errors import ImplausibleProfileError, InvalidInputError, NothingObservedError
from imu_learn.infer.guard import training_inputs
from imu_learn.util.staging import staged_dir

Progress = Callable[[str], None]
logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class CalibOptions:
    min_still_s: float = 10.0  # total still time the Allan noise needs (τ = 1 s with ~10 clusters)
    still: nz.StillSettings = nz.StillSettings()
    plot: bool = True
    force: bool = False  # write a profile that fails a plausibility check (with a warning)
    # the floor's terms chosen on held-out recordings (calib.select; --select / --no-select); None: chosen
    # for a poses reference that cannot resolve accelerations (SELECT_BY_DEFAULT), every term otherwise
    select: Optional[bool] = None


@dataclass
class CalibResult:
    profile: Profile
    files: Dict[str, Path]
    residual_before: Optional[nz.ResidualNoise]
    residual_after: Optional[nz.ResidualNoise]
    allan: Optional[nz.AllanNoise]
    seconds: float


def _rate(ts: Sequence[np.ndarray]) -> float:
    rates = [sample_rate_hz(t) for t in ts if len(t) > 1]
    if not rates:
        raise InvalidInputError("calibrate: no recording has two samples")
    return float(np.median(rates))


def still_pieces(inp: CalibInputs, settings: nz.StillSettings) -> List[Tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """Still stretches of every segment and IMU-only piece, raw samples (name, t_ns, gyro, acc)."""
    out = []
    named = [(g, s.t_ns, s.gyro, s.acc) for s, g in zip(inp.train + inp.val, inp.groups + inp.val_groups)]
    named += [(p.name, p.t_ns, p.gyro, p.acc) for p in inp.imu_only]
    for name, t, g, a in named:
        for i0, i1 in nz.still_stretches(t, g, a, settings):
            out.append((name, t[i0:i1], g[i0:i1], a[i0:i1]))
    return out


def raw_imu(inp: CalibInputs) -> List[Tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """The raw IMU the profile was made from (name, t_ns, gyro, acc): every segment with a reference and
    every IMU-only piece, for the profile's ``inputs`` (:func:`imu_learn.infer.guard.training_inputs`)."""
    return ([(s.name, s.t_ns, s.gyro, s.acc) for s in inp.train + inp.val]
            + [(p.name, p.t_ns, p.gyro, p.acc) for p in inp.imu_only])


def noise_terms(chosen: Dict[str, Tuple[nz.Estimate, float, float]]) -> Dict[str, NoiseTerm]:
    out = {}
    for name, (c, value, std) in chosen.items():
        if c.kind == "upper bound" and name in CLASS_DEFAULTS:  # a bound is never written as a value
            out[name] = unobserved_term(name, c.per_axis, value, c.source, dict(c.detail))
            continue
        out[name] = NoiseTerm(c.per_axis, value, std, NOISE_UNITS[name], c.source,
                              {"kind": c.kind, **{k: v for k, v in c.detail.items()}})
    return out


def bias_instability(cands: List[nz.Estimate]) -> Dict[str, NoiseTerm]:
    out = {}
    for c in cands:
        if c.name.endswith("bias_instability") and np.isfinite(c.per_axis).any():
            out[c.name] = NoiseTerm(c.per_axis, nz._rms(c.per_axis), nz._rms_std(c.per_axis, c.std),
                                    NOISE_UNITS[c.name], c.source, {"kind": c.kind, **c.detail})
    return out


def estimate_dicts(cands: List[nz.Estimate]) -> List[Dict[str, Any]]:
    return [NoiseTerm(c.per_axis, nz._rms(c.per_axis), math.nan, NOISE_UNITS[c.name], c.source,
                      {"kind": c.kind, **c.detail}).to_dict() | {"name": c.name} for c in cands]


def unobservable(has_ref: bool, allan: Optional[nz.AllanNoise], noise: Dict[str, NoiseTerm],
                 options: CalibOptions) -> List[Dict[str, str]]:
    """What could not be observed, and why (the profile's ``unobservable``)."""
    out = []
    if not has_ref:
        out.append({"what": "time offset, affine calibration (scale, misalignment, bias), g-sensitivity, gravity",
                    "why": "no reference trajectory: a recording's IMU alone gives its noise only"})
    else:
        out.append({"what": "gravity magnitude (independently of the accelerometer scale)",
                    "why": "the floor fixes g and fits the accelerometer's scale against it; the two are nearly "
                           "degenerate, so gravity_mps2 is a consistency check of the floor"})
    still_s = allan.seconds if allan else 0.0
    if still_s < options.min_still_s:
        out.append({"what": "noise from the Allan deviation of still stretches",
                    "why": f"needs still stretches of >= {options.min_still_s:g} s in total; found {still_s:.1f} s"})
    for key in NOISE_KEYS:
        t = noise.get(key)
        if t is None:
            out.append({"what": key, "why": "no estimate: neither a reference nor a still stretch; imu.yaml holds the "
                                            f"{CLASS_DEFAULT_SOURCE} (put your datasheet's there)"})
        elif t.bounded_only:
            src = t.detail.get("upper_bound_from", t.source)
            bound = "min over τ of the Allan deviation on the term's line"
            written = (f"the value written is the {CLASS_DEFAULT_SOURCE}; the data bound it above by "
                       f"{t.bound:.3g} (detail.upper_bound, {bound})" if t.source == "class_default" else
                       f"the value written is an upper bound ({bound})")
            found = t.detail.get("why") or (f"no fit found it ({src}: no region of its slope, or its uncertainty "
                                              "above half its value)")
            out.append({"what": key, "why": f"{found}; {written}" + (
                            "; motion-correlated errors (vibration, reference noise, calibration errors that vary "
                            "with the motion) dominate the residuals" if src == "residuals" and "why" not in t.detail
                            else "")})
    return out


SELECT_BY_DEFAULT_FOR = "a poses reference (motion capture, a VIO/SLAM trajectory)"
SELECT_BY_DEFAULT = (SELECT_BY_DEFAULT_FOR + ": every term of the floor fitted against it lost to simpler floors on "
                     "recordings it did not see (BROAD's unseen trials 05 and 14, four trials fitted: open-loop "
                     "rotation over 200 samples 0.587 deg against raw's 0.441, AOE 72 deg against 34; TUM-VI's unseen "
                     "rooms 1.24x raw in rotation over 20 s; docs/experiments/references.md), or fitted the noise of "
                     "axes the motion does not turn about (Fetch's gyro x scale 0.80)")


def selects(option: Optional[bool], inp: CalibInputs) -> bool:
    """Whether the floor's terms are chosen on held-out recordings: as asked, else (None) for every poses
    reference (:data:`SELECT_BY_DEFAULT`); positions and odometry fit only what they observe."""
    if option is not None:
        return option
    return inp.source.kind == "poses"


def floor_profile(inp: CalibInputs, progress: Progress, uncertainty: bool = True,
                  select: bool = False) -> Tuple[Profile, nz.ResidualNoise, nz.ResidualNoise]:
    """The floor part of the profile (with the reference): the floor its source fits, and the
    residuals before/after it (``uncertainty=False``: no refits per recording, the standard
    deviations NaN; ``select``: its terms chosen on held-out recordings, :mod:`imu_learn.calib.select`)."""
    fit = inp.source.fit_floor(inp, progress, uncertainty)
    fit, selection = select_floor(inp, fit, progress) if select else (fit, {})
    f, std = fit.floor, fit.std
    segs, groups = inp.train + inp.val, inp.groups + inp.val_groups
    progress("gravity and the residual noise")
    g, g_std, g_per = ff.fit_gravity(segs, f, groups)
    ident = Floor(TraditionalParams.identity(), f.method, f.filter_order)
    before = nz.residual_noise(segs, ff.calibrated(segs, ident, False), inp.settings.gravity)
    after = nz.residual_noise(segs, ff.calibrated(segs, f, False), inp.settings.gravity)
    rate = _rate([s.t_ns for s in segs])
    period = float(np.median([median_period_ns(s.t_ns) for s in segs])) * 1e-9
    prof = Profile.of_floor(
        inp.device, rate, period, f, std, g, g_std,
        fit_log={**fit.log_entries(), "gravity_per_group": g_per, "floor_gravity_mps2": inp.settings.gravity,
                 "floor_settings": inp.settings.record(), "g_sensitivity_std": std.G},
        selection=selection,
    )
    return prof, before, after


# the sensor a held-back finding concerns, and that sensor's parameters in profile.json's ``observed``
HELD_BACK_SENSORS = {"held_back.rotation": "gyroscope", "held_back.translation": "accelerometer"}
PRIOR_TERMS = {"gyroscope": ("gyroscope.matrix", "gyroscope.bias", "g_sensitivity", "cutoff_gyro"),
               "accelerometer": ("accelerometer.matrix", "accelerometer.bias", "cutoff_acc")}


def at_prior(prof: Profile, sensor: str) -> None:
    """``prof`` with ``sensor``'s terms at their prior (identity matrix, zero bias, no g-sensitivity,
    no low-pass), their standard deviations unknown; the time offset and the other sensor as fitted."""
    assert prof.floor is not None
    i, unknown = TraditionalParams.identity(), TraditionalParams.unknown()
    if sensor == "gyroscope":
        prof.floor = prof.floor.with_params(M_g=i.M_g, b_g=i.b_g, G=i.G, cutoff_gyro=None)
        prof.gyro = Affine(i.M_g.copy(), i.b_g.copy(), prof.gyro.unit, unknown.M_g, unknown.b_g)
        prof.g_sensitivity = i.G.copy()
    else:
        prof.floor = prof.floor.with_params(M_a=i.M_a, b_a=i.b_a, cutoff_acc=None)
        prof.acc = Affine(i.M_a.copy(), i.b_a.copy(), prof.acc.unit, unknown.M_a, unknown.b_a)


def _held_back(prof: Profile, inp: CalibInputs) -> Dict[str, Any]:
    held = inp.val if inp.val else []
    assert prof.floor is not None
    return held_back_errors(held, ff.calibrated(held, prof.floor, True), inp.settings.window, inp.settings.gravity)


def keep_unsupported_at_prior(prof: Profile, inp: CalibInputs, errs: Dict[str, Any]
                              ) -> Tuple[Dict[str, Any], List[Dict[str, str]]]:
    """Held-back raises the block's noise explains (:mod:`imu_learn.calib.plausible`), the rotation's
    first (the gyroscope moves the translation too): the concerned sensor's terms kept at their prior
    (:func:`at_prior`), the block scored again, until none is left or one is beyond the noise; each
    said in one log line, ``observed`` and the returned entries. Returns (the block's errors now, what
    was kept at the prior)."""
    kept: List[Dict[str, str]] = []
    found = held_back_findings(errs)
    while found and all(f.within_noise for f in found):
        f = found[0]
        sensor = HELD_BACK_SENSORS[f.field]
        if any(k["sensor"] == sensor for k in kept) or _at_prior_already(prof, sensor):
            break  # nothing of this sensor's left to hold (the raise is the time offset's or the noise's)
        why = f"the held-back block cannot tell the fitted terms from none: {f.message}"
        at_prior(prof, sensor)
        kept.append({"sensor": sensor, "why": why})
        for k in PRIOR_TERMS[sensor]:
            prof.observed[k] = {"observed": False, "why": why}
        logger.warning("%s: the fitted terms kept at their prior (identity, zero bias, no filter): %s", sensor, why)
        short = "gyro" if sensor == "gyroscope" else "acc"
        if short in prof.selection:  # the summary's "terms chosen" line says what the profile now holds
            prof.selection[short] = f"{prof.selection[short]}, then kept at its prior (the held-back block)"
        errs = _held_back(prof, inp)
        found = held_back_findings(errs)
    return errs, kept


def _at_prior_already(prof: Profile, sensor: str) -> bool:
    """Whether ``sensor``'s terms are all at their prior (identity, zero bias, no g-sensitivity, no
    low-pass): a level ``offset`` chose none of them."""
    assert prof.floor is not None
    p = prof.floor.params
    if sensor == "gyroscope":
        return (np.array_equal(p.M_g, np.eye(3)) and not np.any(p.b_g) and not np.any(p.G)
                and p.cutoff_gyro is None)
    return np.array_equal(p.M_a, np.eye(3)) and not np.any(p.b_a) and p.cutoff_acc is None


# per sensor and chosen level, the floor parameters --select left at their prior
NOT_SELECTED = {
    "gyro": {"offset": ("gyroscope.bias", "gyroscope.matrix", "g_sensitivity", "cutoff_gyro"),
             "bias": ("gyroscope.matrix", "g_sensitivity", "cutoff_gyro"), "scale": ("g_sensitivity", "cutoff_gyro"),
             "affine": ("g_sensitivity", "cutoff_gyro"), "g_sensitivity": ("cutoff_gyro",)},
    "acc": {"offset": ("accelerometer.bias", "accelerometer.matrix", "cutoff_acc"),
            "bias": ("accelerometer.matrix", "cutoff_acc"), "scale": ("cutoff_acc",), "affine": ("cutoff_acc",)},
}


def at_prior_observed(prof: Profile, observed: Dict[str, Dict[str, Any]]) -> Dict[str, Dict[str, Any]]:
    """The source's ``observed`` with what the fit held at its prior said so: a time offset its validation
    refused (fitted, then 0 kept: its spread is then unknown, not 0), and the terms ``--select`` did not
    choose (written at identity / zero with no spread)."""
    out = dict(observed)
    fl = prof.fit_log.get("floor", {}) if isinstance(prof.fit_log, dict) else {}
    fitted, kept = (fl.get("tau_fitted") or [None])[0], (fl.get("tau_samples") or [None])[0]
    if out.get("time_offset", {}).get("observed") and kept == 0.0 and fitted:
        out["time_offset"] = {"observed": False, "why": f"fitted at {fitted:+.3f} samples on the training windows, "
                              "but it did not lower the validation cost: held at its prior (0)"}
        prof.time_offset_s_std = math.nan
    for sensor, levels in NOT_SELECTED.items():
        for key in levels.get(str(prof.selection.get(sensor)), ()):
            if out.get(key, {}).get("observed", True):
                out[key] = {"observed": False, "why": f"not selected: the {sensor} level chosen on held-out recordings "
                            f"is {prof.selection[sensor]}; held at its prior"}
    return out


def plausibility(prof: Profile, inp: CalibInputs, options: CalibOptions, progress: Progress) -> Dict[str, Any]:
    """The checks of :mod:`imu_learn.calib.plausible` on the fitted floor and on the held-back block;
    a failure stops calibrate (:class:`ImplausibleProfileError`) unless ``options.force``. Held-back
    raises within the block's noise (every parameter plausible, no ``--force``): the sensor's terms
    kept at their prior (:func:`keep_unsupported_at_prior`) and checked again."""
    progress("checking the profile: plausibility and the held-back block")
    assert prof.floor is not None
    found = parameter_findings(prof.floor, prof.gravity_mps2)
    errs = _held_back(prof, inp)
    kept: List[Dict[str, str]] = []
    if not found and not options.force:
        errs, kept = keep_unsupported_at_prior(prof, inp, errs)
    held = held_back_findings(errs)
    # a raise within the block's noise for a sensor at its prior (kept there above, or a level ``offset`` chose no
    # term: what is left is the shared time offset) is no finding: nothing more can be held back, and the block
    # cannot tell it from none (BROAD's trial 21 alone: offset / offset, 0.215° against raw 0.215°, was refused)
    at_prior_sensors = {k["sensor"] for k in kept} | {s for s in ("gyroscope", "accelerometer")
                                                      if _at_prior_already(prof, s)}
    within = [f for f in held if f.within_noise and HELD_BACK_SENSORS[f.field] in at_prior_sensors]
    found += [f for f in held if f not in within]
    checks = {"limits": LIMITS, "held_back": errs, "failed": [f.line() for f in found], "forced": bool(found),
              **({"kept_at_prior": kept} if kept else {}),
              **({"within_noise_at_prior": [f.line() for f in within]} if within else {})}
    for f in within:
        logger.info("held-back block: %s; the sensor's terms are at their prior already: written", f.line())
    if found and not options.force:
        hint = "" if inp.source.kind != "poses" or prof.selection else (
            "; --select fits only the terms held-out recordings support")
        raise ImplausibleProfileError(f"calibrate: the profile is not written: {found[0].line()}"
                                      + (f" (and {len(found) - 1} more)" if len(found) > 1 else "")
                                      + "; check the reference's frame, units and clock (imu-learn groundtruth)"
                                      + hint + ", or write it anyway with --force", found[0].field)
    for f in found:
        logger.warning("written with --force although %s", f.line())
    return checks


def observed_anything(noise: Dict[str, NoiseTerm], allan: Optional[nz.AllanNoise], inp: CalibInputs,
                      options: CalibOptions) -> None:
    """``--imu-only`` (no reference): refused (:class:`NothingObservedError`) where no noise figure was measured
    (no still stretch): its profile would hold class defaults only; ``--force`` writes them, with a warning."""
    if any(noise.get(k) is not None for k in NOISE_KEYS):
        return
    still_s = allan.seconds if allan else 0.0
    text = (f"calibrate --imu-only: nothing measured in {', '.join(p.name for p in inp.imu_only)}: no reference and "
            f"{still_s:.1f} s at rest (the noise needs still stretches of >= {options.min_still_s:g} s in total)")
    if not options.force:
        raise NothingObservedError(text + "; record the IMU at rest for a minute, or give a reference "
                                          "(--groundtruth), or write the MEMS class defaults with --force")
    logger.warning("%s; written with --force: imu.yaml holds the MEMS class defaults, marked not measured", text)


OUTPUT_NAMES = ("profile.json", "imu.yaml", "calibration.png")  # what calibrate writes into its folder


def calibrate(inp: CalibInputs, out_dir: Path, options: CalibOptions = CalibOptions(),
              progress: Progress = lambda s: None) -> CalibResult:
    """Fit the profile of ``inp`` and write its files into ``out_dir``."""
    t0 = time.time() - inp.seconds
    has_ref = inp.has_reference
    if not has_ref and not inp.imu_only:
        raise InvalidInputError("calibrate: no recording to calibrate from")
    before = after = None
    if has_ref:
        select = selects(options.select, inp)
        prof, before, after = floor_profile(inp, progress, select=select)
        if select and options.select is None:
            prof.selection["by_default"] = SELECT_BY_DEFAULT
        if not select and inp.source.kind == "poses":
            logger.warning("--no-select: every term of the floor fitted, none chosen on held-out recordings; on a "
                           "recording it did not see such a profile can lose to raw (BROAD's trials 05 and 14 after "
                           "four others: open-loop AOE 72 deg against raw's 34, the selected profile's 34); without "
                           "--no-select only the terms held-out recordings support are kept")
        prof.reference = inp.source.reference()
        prof.observed = at_prior_observed(prof, inp.source.observed())
        prof.checks = plausibility(prof, inp, options, progress)
    else:
        prof = noise_only(inp.device, _rate([p.t_ns for p in inp.imu_only]), {})
    progress("still stretches and their Allan deviation")
    pieces = still_pieces(inp, options.still)
    allan = nz.allan_noise(pieces)
    cands = nz.candidates(after, allan, options.min_still_s, inp.source.band_limit() if has_ref else None)
    noise = noise_terms(nz.choose(cands, NOISE_KEYS))
    if not has_ref:
        observed_anything(noise, allan, inp, options)
    prof.noise = {**noise, **bias_instability(cands)}
    prof.noise_estimates = estimate_dicts(cands)
    prof.sources = inp.sources + ([{"still_stretches": allan.stretches, "still_s": round(allan.seconds, 3)}] if allan else [])
    prof.unobservable = unobservable(has_ref, allan, noise, options)
    prof.inputs = training_inputs(raw_imu(inp))  # refine's and navigate's guard: is a recording this device's?
    names = {"profile": "profile.json", "kalibr": "imu.yaml"}
    # the three files go in together (a Ctrl-C or an error leaves a previous run's set as it was: never this
    # run's profile beside that run's plot); other entries of out_dir (a positions reference's work) are kept
    with staged_dir(Path(out_dir), OUTPUT_NAMES) as stage:
        prof.save(stage / names["profile"])
        write_kalibr_yaml(prof, stage / names["kalibr"])
        if options.plot:
            progress("plot")
            if plot_calibration(stage / "calibration.png", inp.device, before, after, allan):
                names["plot"] = "calibration.png"
    files = {k: Path(out_dir) / v for k, v in names.items()}
    return CalibResult(prof, files, before, after, allan, time.time() - t0)


__all__ = ["CalibInputs", "CalibOptions", "CalibResult", "Recording", "StillPiece", "TIME_OFFSET_PRIOR_SAMPLES",
           "calibrate", "floor_profile"]
