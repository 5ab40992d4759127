"""``--bias METHOD``: the registry of a recording's own gyro-bias estimators (refine's and navigate's),
each estimate bounded by what the device's bias can be.

**The registry** (:data:`REGISTRY`, name -> :class:`Estimator`): each estimator runs on what the steps
before it give (a profile's floor, a model) and returns a :class:`BiasEstimate`: the estimate [rad/s],
its information (the inverse covariance over the directions it observed; zero along those it did not),
and its own summary. ``still`` (:func:`imu_learn.core.still.still_bias`, the still rule with the
recording's prior), ``gravity`` (:func:`imu_learn.core.bias_gravity.gravity_bias`), ``still+gravity``
(the still estimate along gravity, gravity consistency's across it), ``auto`` (every estimator without a
model, with the prior, combined by their information), ``moving`` (refine only: a bias that moves,
:func:`imu_learn.core.bias_gravity.moving_gravity_bias`, per sample; ``auto``'s where the profile's
``bias_prior`` keeps it out, :data:`MOVING_GATE_RULE`) and ``learned`` (refine only; a model, torch).
The command-line choices and their help are made from it (:func:`choices`, :func:`help_text`).

**The bound** (:func:`bound`): the device prior (:class:`imu_learn.core.still.BiasPrior`: a profile's
bias spread, else a MEMS gyro's) says how far a recording's bias can lie from the device's. For each
observed direction u, z = |u.(b - b0)| / sqrt(u' P0 u + u' P u) (P0 the prior's covariance, P the
estimate's). z <= :data:`ACCEPT_SIGMAS` (3): applied as estimated; up to :data:`REJECT_SIGMAS` (6):
shrunk to the precision-weighted combination (P0^-1 + P^-1)^-1 (P0^-1 b0 + P^-1 b); beyond: rejected,
nothing subtracted (the profile's bias kept). One log line and the summary's ``bias.bound`` say which
and why. Uncertainties: the still estimate's white-noise standard error and the spread between its
stretches, floored at :data:`STILL_STD_FLOOR` (a rest of seconds leaves 1-3 mrad/s on EuRoC's test
flights: the bias moves from rest to motion); gravity consistency's per direction (its eigen-directions,
the information its data gave; observed where its data, not its prior, set them); the learned estimator's a fixed
:data:`LEARNED_STD` (its held-out bias error on the Fetch robot).

**The device's training recordings** (a profile's ``bias_prior``, :func:`measure_prior`): a still
stretch measures the bias at rest, open loop needs the bias while moving. Where the profile measured,
on the recordings it was fitted on, each estimator's RMS error against their moving bias and the
profile alone's, ``auto`` admits only the estimators that were the closer (:func:`better_than_prior`),
and so do the named options (:func:`admit`: ``still``, ``gravity``, ``learned``; ``still+gravity`` each
part; ``moving`` its own gate): one kept out subtracts nothing beyond the profile's floor (decision
``gated``, one log line, the figures in the entry's ``gate``), one the profile has no figure for is
applied as bounded ("not measured");
the still estimate adds the device's systematic rest-to-motion change measured there (:func:`rest_to_motion`:
moving minus still, per axis where it is significant and holds on recordings held out in turn; the bias
of a vibrating drone's gyro in flight is not the one on the ground), its uncertainty floor is raised to the
spread left after that, and gravity consistency's error beyond its own uncertainty is added to its
variance. A profile without ``bias_prior``: as before.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from imu_learn.core.bias_gravity import MovingSettings, gravity_bias, moving_gravity_bias, moving_prior_information
from imu_learn.core.still import BIAS_SETTINGS, MEMS_PRIOR, STILL_SIGMAS, BiasPrior, still_bias, still_stretches
from imu_learn.errors import InvalidInputError

log = logging.getLogger(__name__)

# One step of a refinement: (t_ns or None, gyro, acc) -> (gyro, acc, per-sample variances (N, 6) or None).
Step = Callable[[Optional[np.ndarray], np.ndarray, np.ndarray], Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]]

ACCEPT_SIGMAS = 3.0  # z at or below: the estimate applied as it is
REJECT_SIGMAS = 6.0  # z above: rejected (nothing subtracted); between: shrunk toward the prior
STILL_STD_FLOOR = 0.003  # rad/s: the least uncertainty of a still estimate (rest-to-motion change of the bias)
LEARNED_STD = 0.003  # rad/s: the learned estimator's uncertainty (its held-out bias error on Fetch, 2.3 mrad/s)


def _vec(x: Optional[np.ndarray]) -> Optional[List[float]]:
    return None if x is None else [float(v) for v in np.ravel(x)]


@dataclass
class BiasEstimate:
    """One estimator's answer: ``gyro_bias`` [rad/s] (3,) or None (nothing estimated; ``missing``
    says why), ``information`` (3, 3) its inverse covariance over the directions it observed (zero
    along the others), ``detail`` its own summary (a dict)."""

    method: str
    gyro_bias: Optional[np.ndarray]
    information: np.ndarray
    detail: Dict[str, Any]
    missing: Optional[str] = None
    unseen: Optional[np.ndarray] = None  # (3, 3) projection onto what it did not observe; None: from the information
    # a bias that moves (``moving``): (N, 3) per sample and its standard deviation; ``gyro_bias`` their
    # time average (what the bound and the gate judge)
    per_sample: Optional[np.ndarray] = None
    per_sample_std: Optional[np.ndarray] = None

    @property
    def std(self) -> Optional[np.ndarray]:
        """(3,) per axis, inf on an axis it did not observe."""
        if self.gyro_bias is None:
            return None
        d = np.diag(np.linalg.pinv(self.information, hermitian=True))
        return np.where(np.diag(self.information) > 0, np.sqrt(np.maximum(d, 0.0)), np.inf)

    def observed(self) -> Tuple[np.ndarray, np.ndarray]:
        """(directions (k, 3), std (k,)): the eigen-directions of the information it observed."""
        lam, vec = np.linalg.eigh(self.information)
        keep = lam > 1e-12 * max(1.0, float(lam.max(initial=0.0)))
        return vec.T[keep], 1.0 / np.sqrt(lam[keep])

    def unobserved(self) -> np.ndarray:
        """(3, 3) projection onto the body-frame directions it did not observe (the identity without an
        estimate)."""
        if self.gyro_bias is None:
            return np.eye(3)
        if self.unseen is not None:
            return self.unseen
        dirs, _ = self.observed()
        return np.eye(3) - sum((np.outer(d, d) for d in dirs), np.zeros((3, 3)))


def info_diag(std: np.ndarray) -> np.ndarray:
    return np.diag(1.0 / np.asarray(std, dtype=np.float64) ** 2)


# -- the estimators ---------------------------------------------------------------------------------


@dataclass
class Context:
    """What an estimator gets besides the samples: gravity's magnitude [m/s^2] (the still rule's
    norm check), the device prior, the learned estimator's model."""

    gravity: float = 9.80665
    prior: BiasPrior = MEMS_PRIOR
    model: Optional[Path] = None


def _still(ctx: Context, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> BiasEstimate:
    est = still_bias(t_ns, gyro, acc, replace(BIAS_SETTINGS, gravity=float(ctx.gravity), prior=ctx.prior))
    detail = est.to_dict()
    if est.gyro_bias is None:
        why = "no still stretch in {where} (docs/refine.md: the detector's thresholds and the still rule)"
        if est.refused:
            top = max(max(abs(v) for v in r["gyro_mean_rad_s"]) for r in est.refused)
            why = ("no still stretch in {where}: " + f"{len(est.refused)} quiet stretch(es) refused by the still "
                   f"rule (mean gyro up to {top:.3f} rad/s, beyond {STILL_SIGMAS:g} sigma of what the device's "
                   "gyro reads at rest: a steady turn, not rest)")
        return BiasEstimate("still", None, np.zeros((3, 3)), detail, why)
    # the rest-to-motion change: the fixed floor, raised to what the device's training recordings
    # measured where the profile says (prior.still_error_std)
    rest = STILL_STD_FLOOR if ctx.prior.still_error_std is None else np.maximum(STILL_STD_FLOOR,
                                                                                np.asarray(ctx.prior.still_error_std))
    var = est.gyro_bias_std ** 2 + rest ** 2
    if est.between_stretches is not None:
        var = var + est.between_stretches ** 2
    detail["std_rad_s"] = _vec(np.sqrt(var))
    b = est.gyro_bias
    if ctx.prior.rest_to_motion is not None:  # the bias while moving: the device's measured change added
        b = b + ctx.prior.shift()
        detail.update(at_rest_rad_s=_vec(est.gyro_bias), rest_to_motion_rad_s=_vec(ctx.prior.shift()),
                      gyro_bias_rad_s=_vec(b), gyro_bias_deg_s=_vec(np.rad2deg(b)))
    return BiasEstimate("still", b, np.diag(1.0 / var), detail)


def _gravity_info(grav: Any, extra: Optional[float] = None) -> np.ndarray:
    """The information its data gave (its eigen-directions' less its prior's), every direction;
    ``extra`` [rad/s]: its error beyond that, measured on the device's training recordings (the
    prior's ``gravity_error_std``), added to each direction's variance."""
    if grav.gyro_bias is None or grav.directions is None:
        return np.zeros((3, 3))
    info = np.zeros((3, 3))
    for d, s in zip(grav.directions, grav.direction_std):
        lam = max(1.0 / s ** 2 - 1.0 / grav.settings.prior_sigma ** 2, 0.0)
        if extra and lam > 0:
            lam = 1.0 / (1.0 / lam + extra ** 2)
        info += np.outer(d, d) * lam
    return info


def _gravity_unseen(grav: Any) -> np.ndarray:
    """Projection onto its directions its prior, not its data, set (``direction_observed`` false)."""
    if grav.gyro_bias is None or grav.directions is None:
        return np.eye(3)
    return sum((np.outer(d, d) for d, s in zip(grav.directions, grav.direction_std)
                if s > grav.settings.observed_below), np.zeros((3, 3)))


def disagreement(grav: BiasEstimate, still: BiasEstimate) -> Optional[float]:
    """How far gravity consistency's estimate lies from the still stretches' of the same recording: the
    largest distance over the directions gravity consistency observed, in their combined sigmas (None
    where either has no estimate)."""
    if grav.gyro_bias is None or still.gyro_bias is None:
        return None
    cov = np.linalg.pinv(still.information, hermitian=True)
    d = np.asarray(grav.gyro_bias) - np.asarray(still.gyro_bias)
    dirs, std = grav.observed()
    return max((abs(float(u @ d)) / np.sqrt(s ** 2 + float(u @ cov @ u)) for u, s in zip(dirs, std)), default=0.0)


def still_checked(grav: BiasEstimate, still: BiasEstimate) -> BiasEstimate:
    """``grav`` where the recording's own still stretches support it (within :data:`ACCEPT_SIGMAS`
    combined sigmas, :func:`disagreement`), else kept out: two estimates of one bias that disagree
    beyond their uncertainties cannot both hold, and the still stretches measure it directly where
    gravity consistency infers it from the motion. The check goes into ``detail["still_check"]``."""
    z = disagreement(grav, still)
    if z is None:
        return grav
    grav.detail["still_check"] = {"z_sigmas": round(float(z), 3), "limit_sigmas": ACCEPT_SIGMAS,
                                  "kept": bool(z <= ACCEPT_SIGMAS)}
    if z <= ACCEPT_SIGMAS:
        return grav
    return replace(grav, gyro_bias=None, information=np.zeros((3, 3)), unseen=None,
                   missing=f"gravity consistency's estimate is {z:.1f} sigma from the still stretches' in "
                   "{where}: kept out (the still stretches measure the bias directly)")


def _gravity_estimate(ctx: Context, est: Any) -> BiasEstimate:
    """Gravity consistency's result (:func:`gravity_bias`) as a :class:`BiasEstimate`."""
    if est.gyro_bias is None:
        s = est.settings
        return BiasEstimate("gravity", None, np.zeros((3, 3)), est.to_dict(),
                            "{where} is shorter than " + f"{s.min_windows} windows of {s.window_s:g} s")
    return BiasEstimate("gravity", est.gyro_bias, _gravity_info(est, ctx.prior.gravity_error_std), est.to_dict(),
                        unseen=_gravity_unseen(est))


def gravity_alone(ctx: Context, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> BiasEstimate:
    """Gravity consistency's estimate as it is (before :func:`still_checked`)."""
    return _gravity_estimate(ctx, gravity_bias(t_ns, gyro, acc))


def _gravity(ctx: Context, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> BiasEstimate:
    """Gravity consistency, checked against the recording's still stretches (:func:`still_checked`)."""
    return still_checked(gravity_alone(ctx, t_ns, gyro, acc), _still(ctx, t_ns, gyro, acc))


def still_along_gravity(still: Optional[np.ndarray], grav: Any) -> Optional[np.ndarray]:
    """The still stretches' bias along gravity's body direction and gravity consistency's across it
    (gravity consistency cannot see the rate about gravity; the still estimate carries the rest-to-
    motion change of the bias across it, docs/experiments/learning.md "Flight by flight against the
    peers"); either alone where the other has none."""
    if still is None:
        return grav.gyro_bias
    if grav.gyro_bias is None or grav.gravity_body is None:
        return still
    u = np.asarray(grav.gravity_body, dtype=np.float64)
    u = u / np.linalg.norm(u)
    return grav.gyro_bias + u * float(u @ (np.asarray(still) - grav.gyro_bias))


def _still_gravity(ctx: Context, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> BiasEstimate:
    still, grav = _still(ctx, t_ns, gyro, acc), gravity_bias(t_ns, gyro, acc)
    still_detail, grav_detail = still.detail, grav.to_dict()
    # each part admitted as auto admits it (better_than_prior): one kept out counts as absent
    gates: Dict[str, Any] = {}
    for part, b_part in (("still", still.gyro_bias), ("gravity", grav.gyro_bias)):
        if b_part is None:
            continue
        ok, rms = better_than_prior(BiasEstimate(part, b_part, np.zeros((3, 3)), {}), ctx.prior)
        gates[part] = gate_entry(ok, rms)
        if not ok and part == "still":
            still = replace(still, gyro_bias=None, information=np.zeros((3, 3)),
                            missing="the still estimate kept out by the gate")
        elif not ok:
            grav = replace(grav, gyro_bias=None)
    part = still_checked(_gravity_estimate(ctx, grav), still)  # the two parts must agree
    check = part.detail.get("still_check")
    if part.gyro_bias is None:
        grav = replace(grav, gyro_bias=None)
    b = still_along_gravity(still.gyro_bias, grav)
    g_info = part.information
    unseen = np.zeros((3, 3))
    if still.gyro_bias is None:
        info, unseen = g_info, _gravity_unseen(grav)
    elif grav.gyro_bias is None or grav.gravity_body is None:
        info = still.information
    else:  # the still estimate's information along gravity, gravity consistency's across it
        u = np.asarray(grav.gravity_body, dtype=np.float64)
        u = u / np.linalg.norm(u)
        A, Q = np.outer(u, u), np.eye(3) - np.outer(u, u)
        info = A @ still.information @ A + Q @ g_info @ Q
    detail = {"gyro_bias_rad_s": _vec(b), "gyro_bias_deg_s": None if b is None else _vec(np.rad2deg(b)),
              "rule": "the still stretches' estimate along gravity, gravity consistency's across it (either alone "
                      "where the other has none); each part admitted as auto admits it (its gate)",
              "still": still_detail, "gravity": grav_detail, "gate": gates, "still_check": check}
    missing = None
    if b is None:
        out = [f"{k} ({gate_words(v)})" for k, v in gates.items() if not v["entered"]]
        missing = ("neither a still stretch nor enough windows in {where}" if not out else
                   "nothing left in {where} after the gate: " + "; ".join(out)
                   + ("" if len(out) == 2 else "; the other part gave no estimate"))
    return BiasEstimate("still+gravity", b, info if b is not None else np.zeros((3, 3)), detail, missing, unseen)


def _learned(ctx: Context, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> BiasEstimate:
    from imu_learn.nn.bias_net import load_bias_net, predict_bias

    if ctx.model is None:
        raise InvalidInputError("--bias learned needs --bias-model PATH (a bias estimator, imu_learn.train.bias_train)")
    net, record = load_bias_net(ctx.model, with_record=True)
    b = predict_bias(net, t_ns, gyro, acc)
    detail = {"gyro_bias_rad_s": _vec(b), "gyro_bias_deg_s": None if b is None else _vec(np.rad2deg(b)),
              "model": str(ctx.model), "window_s": net.cfg.window_s, "trained_on": record.get("device"),
              "std_rad_s": [LEARNED_STD] * 3,
              "observable": "learned from the training recordings (a random bias injected per window); its "
                            f"uncertainty taken as {LEARNED_STD:g} rad/s per axis (docs/refine.md)"}
    if b is None:
        return BiasEstimate("learned", None, np.zeros((3, 3)), detail,
                            "{where} is shorter than " + f"the estimator's window of {net.cfg.window_s:g} s")
    return BiasEstimate("learned", np.asarray(b, dtype=np.float64), info_diag(np.full(3, LEARNED_STD)), detail)


def model_device(path: Path) -> Optional[str]:
    """The device a ``--bias-model`` was trained on (its record's ``device``; None: not recorded); the file is
    read and checked here, before the recording is."""
    from imu_learn.nn.bias_net import load_bias_net

    return load_bias_net(path, with_record=True)[1].get("device")


def _rest_sigma(prior: BiasPrior) -> np.ndarray:
    return (np.full(3, STILL_STD_FLOOR) if prior.still_error_std is None
            else np.maximum(STILL_STD_FLOOR, np.asarray(prior.still_error_std)))


def moving_raw(ctx: Context, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> BiasEstimate:
    """``moving`` without its gate: :func:`imu_learn.core.bias_gravity.moving_gravity_bias` with every
    still stretch (the still rule's, as ``still``) at its time, the random walk the prior's (the
    profile's), the rest-to-motion spread the still estimate's floor."""
    t = np.asarray(t_ns, dtype=np.int64)
    g = np.asarray(gyro, dtype=np.float64)
    found = still_stretches(t, g, acc, replace(BIAS_SETTINGS, gravity=float(ctx.gravity), prior=ctx.prior))
    shift = ctx.prior.shift()  # each still's bias while moving (the device's rest-to-motion change)
    stills = [(int((t[a] + t[b - 1]) // 2), g[a:b].mean(0) + shift, g[a:b].std(0, ddof=1) / np.sqrt(b - a))
              for a, b in found]
    # each still's rest-to-motion uncertainty as the still estimate's (its floor, raised to the profile's
    # measured spread); no prior on the level (the measured moving-bias spread as one: worse on EuRoC's
    # training flights, docs/experiments/bias_prior.md)
    s = MovingSettings(rest_sigma=tuple(float(v) for v in _rest_sigma(ctx.prior)))
    if ctx.prior.random_walk is not None:
        s = replace(s, random_walk=float(ctx.prior.random_walk))
    est = moving_gravity_bias(t, g, acc, stills, s)
    if est is None:
        return BiasEstimate("moving", None, np.zeros((3, 3)), {"gyro_bias_rad_s": None},
                            "neither a still stretch nor enough windows in {where}")
    b, sd = est.at(t)
    # the time average's information from its data: its posterior's less the priors' alone (knots'
    # prior and random walk), every direction; unseen where the priors, not the data, set it
    J = len(est.knots)
    Wm = np.kron(est.weights(t).mean(0)[None, :], np.eye(3))
    Hp = moving_prior_information(J, (t[-1] - t[0]) * 1e-9, s)
    Pm = Wm @ np.linalg.inv(Hp) @ Wm.T
    lam, vec = np.linalg.eigh(np.linalg.inv(est.mean_cov) - np.linalg.inv(Pm))
    lam_p = np.array([float(v @ np.linalg.inv(Pm) @ v) for v in vec.T])
    seen = lam > lam_p
    info = (vec[:, seen] * np.maximum(lam[seen], 0.0)) @ vec[:, seen].T
    unseen = vec[:, ~seen] @ vec[:, ~seen].T
    detail = {**est.to_dict(), "std_rad_s": _vec(np.sqrt(np.diag(est.mean_cov)))}
    return BiasEstimate("moving", est.mean, info, detail, unseen=unseen, per_sample=b, per_sample_std=sd)


MOVING_GATE_RULE = ("moving enters only where, on the device's training recordings (the profile's bias_prior), its "
                    "time average lay closer to the bias while moving than the profile alone, the still estimate "
                    "(the other estimate of every axis) and auto (as it runs there, along the directions moving "
                    "observed) did; elsewhere auto's constant estimate is used")
MOVING_GATE_NO_AUTO = ("this profile's bias_prior has no auto figure (fitted before auto was measured): judged against "
                       "the profile alone and the still estimate only; refit it with experiments/bias_prior.py fit "
                       "--write to judge it against auto")


def moving_admitted(prior: BiasPrior) -> Tuple[bool, Optional[Dict[str, float]]]:
    """(whether ``moving``'s own estimate is used, the training figures it was judged on [rad/s], None
    where the profile has not measured them): :data:`MOVING_GATE_RULE`; a ``bias_prior`` without the
    ``auto`` figure (an older profile): against the profile alone and the still estimate only
    (:data:`MOVING_GATE_NO_AUTO`)."""
    rms = {k: (e, a) for k, e, a in prior.measured_rms}
    if "moving" not in rms:
        return True, None
    figures = {"moving": rms["moving"][0], "profile_alone": rms["moving"][1]}
    for other in ("still", "auto"):
        if other in rms:
            figures[other] = rms[other][0]
    return figures["moving"] < min(v for k, v in figures.items() if k != "moving"), figures


def _moving(ctx: Context, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> BiasEstimate:
    ok, figures = moving_admitted(ctx.prior)
    gate = None
    if figures is not None:
        gate = {"entered": ok, "training_rms_rad_s": figures, "compared_with_auto": "auto" in figures,
                "rule": MOVING_GATE_RULE if "auto" in figures else MOVING_GATE_RULE + "; " + MOVING_GATE_NO_AUTO}
        if "auto" not in figures:
            log.info("--bias moving: %s", MOVING_GATE_NO_AUTO)
    if ok:
        est = moving_raw(ctx, t_ns, gyro, acc)
        if gate:
            est.detail["gate"] = gate
        return est
    assert gate is not None and figures is not None  # not admitted: judged on measured figures
    best = min((k for k in figures if k != "moving"), key=lambda k: figures[k])
    log.warning("--bias moving: on the device's training recordings it lay further from the bias while moving (RMS "
                "%.3g mrad/s) than %s (%.3g): auto's constant estimate is removed instead (the summary's moving_gate)",
                figures["moving"] * 1e3, best.replace("_", " "), figures[best] * 1e3)
    est = _auto(ctx, t_ns, gyro, acc)  # method "auto": its parts bounded each (bound)
    est.detail = {**est.detail, "moving_gate": gate, "rule": gate["rule"] + "; " + est.detail["rule"]}
    return est


def _auto(ctx: Context, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> BiasEstimate:
    still = _still(ctx, t_ns, gyro, acc)
    parts = [still, still_checked(gravity_alone(ctx, t_ns, gyro, acc), still)]
    if ctx.model is not None:
        parts.append(_learned(ctx, t_ns, gyro, acc))
    return combine(parts, ctx.prior)


@dataclass(frozen=True)
class Estimator:
    """One ``--bias`` name: ``run(context, t_ns, gyro, acc)``, its summary line (``words``), its help
    text, and where it is offered (``navigate``: without a model)."""

    name: str
    run: Callable[[Context, np.ndarray, np.ndarray, np.ndarray], BiasEstimate]
    words: str
    help: str  # {model}: where refine (which takes --bias-model) says what a model adds; navigate takes none
    navigate: bool = True
    needs_model: bool = False


REGISTRY: Dict[str, Estimator] = {e.name: e for e in (
    Estimator("auto", _auto, "the recording's own gyro bias removed: every estimator and the device prior combined by "
              "their uncertainties",
              "every estimator without a model{model} and the device prior, "
              "combined by their uncertainties (recommended)"),
    Estimator("still", _still, "the recording's own gyro bias from its still stretches removed",
              "the mean gyro over its still stretches (the still rule: quiet, at gravity's norm, the gyro within "
              "3 sigma of what the device's gyro reads at rest)"),
    Estimator("gravity", _gravity, "the recording's own gyro bias from gravity consistency removed (rates "
              "perpendicular to gravity only)",
              "gravity consistency over 10 s windows (rates perpendicular to gravity only; kept out where the "
              "recording's still stretches read a bias more than 3 sigma from it)"),
    Estimator("still+gravity", _still_gravity, "the recording's own gyro bias removed: from its still stretches "
              "along gravity, from gravity consistency across it",
              "the still estimate along gravity, gravity's across it"),
    Estimator("moving", _moving, "the recording's own gyro bias, moving over time, removed: gravity consistency "
              "with a random-walk bias and every still stretch at its time (auto's where the profile's bias_prior "
              "keeps it out)",
              "a bias that moves: gravity consistency with the bias piecewise linear in time (its random walk the "
              "profile's) and every still stretch at its time; where the profile's bias_prior measured it no "
              "closer than the profile alone, the still estimate and auto, auto's", navigate=False),
    Estimator("learned", _learned, "the recording's own gyro bias from the learned estimator removed",
              "the long-context estimator of --bias-model", navigate=False, needs_model=True),
)}


def choices(navigate: bool = False) -> Tuple[str, ...]:
    """The ``--bias`` names refine (or navigate) accepts: ``none`` and the registry's."""
    return ("none",) + tuple(n for n, e in REGISTRY.items() if e.navigate or not navigate)


def help_text(navigate: bool = False) -> str:
    """``--bias``'s help, made from the registry (the same words for refine and navigate)."""
    model = "" if navigate else " (with --bias-model, the learned one too)"
    items = "; ".join(f"{n}: {e.help.format(model=model)}" for n, e in REGISTRY.items() if e.navigate or not navigate)
    where = ("on the IMU as fused (after --profile's floor, --checkpoint or --calibration), subtracted before the "
             "fusion" if navigate else "after the profile and model")
    return (f"the recording's own gyro bias, estimated {where} and bounded by the device's bias spread "
            f"(the profile's; an estimate far from it is shrunk or rejected): {items}; none: nothing "
            "(default). docs/refine.md; the estimate goes into the summary's bias")


# -- the bound --------------------------------------------------------------------------------------


def prior_information(prior: BiasPrior) -> np.ndarray:
    return info_diag(np.asarray(prior.std))


def combine(parts: List[BiasEstimate], prior: BiasPrior, with_prior: bool = False) -> BiasEstimate:
    """``auto``: the estimates each bounded (:func:`bound`: shrunk ones enter as shrunk, rejected ones
    are dropped), combined by their information, b = (sum Li)^+ sum Li bi, and the prior's mean
    along the directions none observed. ``with_prior``: the prior averaged in everywhere,
    b = (L0 + sum Li)^-1 (L0 b0 + sum Li bi) (measured worse: docs/refine.md). A prior measured on
    the device's training recordings (a profile's ``bias_prior``) gates each estimator first
    (:func:`better_than_prior`)."""
    b0, L0 = np.asarray(prior.bias, dtype=np.float64), prior_information(prior)
    used, info, num, details, seen = [], np.zeros((3, 3)), np.zeros(3), {}, np.zeros((3, 3))
    out: List[str] = []  # why each part that did not enter stayed out
    for p in parts:
        verdict = bound(p, prior)
        details[p.method] = {**p.detail, "bound": verdict.to_dict()}
        if verdict.decision not in ("applied", "shrunk"):
            out.append(f"{p.method} " + ("found none" if verdict.decision == "none" else "rejected by the bound"))
            continue
        ok, rms = better_than_prior(p, prior)
        if rms is not None:
            details[p.method]["gate"] = gate_entry(ok, rms)
        if not ok:
            out.append(f"{p.method} kept out by the device's training recordings")
            continue
        used.append(p.method)
        info += p.information
        num += p.information @ verdict.gyro_bias
        seen += np.eye(3) - p.unobserved()
    detail: Dict[str, Any] = {"rule": "every estimate bounded by the device prior, those kept combined by their "
                                      "information (inverse covariances), the prior's mean where none observed"
                                      + ("; the prior averaged in everywhere" if with_prior else "")
                                      + ("; each estimator gated by its error on the device's training recordings"
                                         if prior.measured_rms else ""),
                              "used": used, **details}
    if not used:
        detail.update({"gyro_bias_rad_s": None, "gyro_bias_deg_s": None})
        return BiasEstimate("auto", None, np.zeros((3, 3)), detail,
                            "no estimator entered in {where} (" + ", ".join(out) + ")")
    if with_prior:
        b = np.linalg.solve(L0 + info, L0 @ b0 + num)
    else:
        lam, vec = np.linalg.eigh(info)
        keep = lam > 1e-12 * max(1.0, float(lam.max()))
        V = vec[:, keep]
        b = V @ ((V.T @ num) / lam[keep]) + (np.eye(3) - V @ V.T) @ b0
    detail.update({"gyro_bias_rad_s": _vec(b), "gyro_bias_deg_s": _vec(np.rad2deg(b))})
    # bounded already, each: the combined estimate's own information is what the estimators gave
    lam, vec = np.linalg.eigh(seen)
    unseen = vec[:, lam < 1e-9] @ vec[:, lam < 1e-9].T
    return BiasEstimate("auto", b, info, detail, unseen=unseen)


GATE_RULE = ("an estimator enters only where, on the device's training recordings (the profile's bias_prior), "
             "its estimate lay closer to the bias while moving than the profile alone did (RMS over the recordings "
             "and the directions it observed); a device without that figure: every estimator enters")


def better_than_prior(est: BiasEstimate, prior: BiasPrior) -> Tuple[bool, Optional[Tuple[float, float]]]:
    """(whether ``est`` enters ``auto``, (its RMS error, the profile alone's) [rad/s] on the device's
    training recordings, None where the profile has not measured them): :data:`GATE_RULE`."""
    rms = {k: (e, a) for k, e, a in prior.measured_rms}.get(est.method)
    return (True, None) if rms is None else (rms[0] < rms[1], rms)


NOT_MEASURED = ("not measured: the profile's bias_prior has no training figure for this estimator (or the profile "
                "has no bias_prior), so it is applied ungated")


def gate_entry(ok: bool, rms: Optional[Tuple[float, float]]) -> Dict[str, Any]:
    """The summary's ``gate`` of one estimator (auto's parts, the named options): whether it entered,
    the training figures it was judged on [rad/s] and :data:`GATE_RULE`; "not measured" without them."""
    if rms is None:
        return {"entered": True, "measured": False, "rule": NOT_MEASURED}
    return {"entered": ok, "measured": True, "training_rms_error_rad_s": rms[0],
            "training_rms_profile_alone_rad_s": rms[1], "rule": GATE_RULE}


def gate_words(gate: Dict[str, Any]) -> str:
    """One line of a ``gate`` entry: the figures and the verdict."""
    if not gate.get("measured"):
        return NOT_MEASURED
    e, a = gate["training_rms_error_rad_s"], gate["training_rms_profile_alone_rad_s"]
    return (f"training RMS error {e * 1e3:.2f} mrad/s " + ("below" if gate["entered"] else "not below")
            + f" the profile alone's {a * 1e3:.2f} mrad/s (the profile's bias_prior.rms_rad_s)")


GATED = ("still", "gravity", "learned")  # the named options gated in bias_step (still+gravity per part, moving its own)


def admit(est: BiasEstimate, verdict: Verdict, prior: BiasPrior) -> Verdict:
    """A named option (``--bias still|gravity|learned``) admitted as ``auto`` admits its parts
    (:func:`better_than_prior`, :data:`GATE_RULE`): kept out, nothing subtracted beyond the profile's
    floor (decision ``gated``); the figures go into ``est.detail["gate"]`` ("not measured" where the
    profile has none: applied as bounded)."""
    if est.method not in GATED or est.gyro_bias is None:
        return verdict
    ok, rms = better_than_prior(est, prior)
    est.detail["gate"] = gate_entry(ok, rms)
    if ok or verdict.gyro_bias is None:
        return verdict
    return Verdict("gated", verdict.z, None, "kept out by the device's training recordings: "
                   + gate_words(est.detail["gate"]) + "; the profile alone used (nothing subtracted beyond its "
                   "floor); rule: " + GATE_RULE + f" (the bound alone: {verdict.decision})", prior)


@dataclass
class Verdict:
    """What :func:`bound` made of an estimate: ``decision`` (applied / shrunk / rejected / none; gated:
    kept out by :func:`admit`), ``z`` the largest distance from the prior in combined sigmas over its
    observed directions, ``gyro_bias`` what is subtracted (None: nothing), ``why`` one line."""

    decision: str
    z: Optional[float]
    gyro_bias: Optional[np.ndarray]
    why: str
    prior: BiasPrior = field(default_factory=lambda: MEMS_PRIOR)

    def to_dict(self) -> Dict[str, Any]:
        return {"decision": self.decision, "z_sigmas": None if self.z is None else round(float(self.z), 3),
                "accept_sigmas": ACCEPT_SIGMAS, "reject_sigmas": REJECT_SIGMAS,
                "subtracted_rad_s": _vec(self.gyro_bias), "why": self.why, "prior": self.prior.to_dict()}


def bound(est: BiasEstimate, prior: BiasPrior) -> Verdict:
    """The estimate against the device prior (module doc): applied, shrunk or rejected."""
    if est.gyro_bias is None:
        return Verdict("none", None, None, "no estimate: " + str(est.missing).replace(" in {where}", "").replace("{where}", "the recording"), prior)
    b0 = np.asarray(prior.bias, dtype=np.float64)
    P0 = np.diag(np.asarray(prior.std, dtype=np.float64) ** 2)
    dirs, std = est.observed()
    if est.method == "auto":  # each part bounded already: the combination is applied as it is
        return Verdict("applied", None, est.gyro_bias, "every estimate it combines bounded on its own (bound of each: "
                       "its entry)", prior)
    d = est.gyro_bias - b0
    z = max((abs(float(u @ d)) / np.sqrt(float(u @ P0 @ u) + s ** 2) for u, s in zip(dirs, std)), default=0.0)
    what = f"{z:.1f} sigma from the device prior ({prior.source})"
    if z <= ACCEPT_SIGMAS:
        return Verdict("applied", z, est.gyro_bias, f"{what}: within {ACCEPT_SIGMAS:g}, applied as estimated", prior)
    if z <= REJECT_SIGMAS:
        L0 = np.linalg.inv(P0)
        b = np.linalg.solve(L0 + est.information, L0 @ b0 + est.information @ est.gyro_bias)
        return Verdict("shrunk", z, b, f"{what}: beyond {ACCEPT_SIGMAS:g}, shrunk toward it (precision-weighted)", prior)
    return Verdict("rejected", z, None, f"{what}: beyond {REJECT_SIGMAS:g}, rejected; the profile's bias kept "
                   "(nothing subtracted)", prior)


# -- the prior measured on the device's training recordings ---------------------------------------------

REST_TO_MOTION_MIN = 3  # recordings with a still stretch needed to measure the rest-to-motion change
REST_TO_MOTION_SIGMAS = ACCEPT_SIGMAS  # the mean kept only this many standard errors from zero
REST_TO_MOTION_RULE = ("moving minus still, the mean over the training recordings with a still stretch, per body axis "
                       f"where it lies at least {REST_TO_MOTION_SIGMAS:g} standard errors from zero and holding each "
                       f"recording out in turn (at least {REST_TO_MOTION_MIN}) lowered the RMS of the still estimate's "
                       "error against the moving bias on that axis; zero elsewhere")


def rest_to_motion(still_err: List[np.ndarray]) -> Tuple[Optional[np.ndarray], List[np.ndarray]]:
    """The device's rest-to-motion change of the bias (:data:`REST_TO_MOTION_RULE`) from each training
    recording's still minus moving bias, and the still estimate's errors with it (each recording's with
    the change measured on the others: held out; as they are on the axes where it is zero). None (and
    the errors as they are) under :data:`REST_TO_MOTION_MIN` recordings."""
    n = len(still_err)
    if n < REST_TO_MOTION_MIN:
        return None, list(still_err)
    D = np.asarray(still_err, dtype=np.float64)  # still - moving, (n, 3)
    held = np.stack([D[r] - np.delete(D, r, axis=0).mean(0) for r in range(n)])  # still + (moving - still) of the others
    sig = np.abs(D.mean(0)) >= REST_TO_MOTION_SIGMAS * D.std(0, ddof=1) / np.sqrt(n)
    keep = sig & (np.sqrt(np.mean(held ** 2, axis=0)) < np.sqrt(np.mean(D ** 2, axis=0)))
    shift = np.where(keep, -D.mean(0), 0.0)
    return shift, list(np.where(keep, held, D))


def measure_prior(recordings: List[Tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
                  ctx: Context) -> Dict[str, Any]:
    """A profile's ``bias_prior`` (:class:`imu_learn.core.still.BiasPrior`, read back by its
    ``from_bias_std(measured=...)``) from the device's training recordings: each (name, t_ns, gyro,
    acc, moving bias) with the profile's floor applied and its bias *while moving* (fitted on its
    ground truth, rad/s). Per recording, the ``still`` and ``gravity`` estimates (``ctx``: the
    recording's gravity and the profile's prior) against the moving bias: ``moving_std_rad_s`` the
    moving bias's spread about zero per axis (x n/(n-1): the floor was fitted on them; None under two
    recordings), ``rest_to_motion_rad_s`` the device's rest-to-motion change (:func:`rest_to_motion`),
    ``still_error_std_rad_s`` the RMS of still - moving per axis after it (held out; before it:
    ``still_error_unshifted_std_rad_s``), ``gravity_error_std_rad_s``
    gravity consistency's error beyond its own uncertainty along the directions its data set (pooled),
    and ``rms_rad_s`` per estimator its RMS error and the profile alone's (the moving bias) over the
    same recordings and directions: ``still`` and ``gravity`` (``auto``'s gate, :func:`better_than_prior`);
    then, with the prior these figures make (``ctx``'s with them: as a profile carrying them runs),
    ``moving`` (its time average, :func:`moving_raw`, bounded as :func:`bias_step` bounds it) and
    ``auto`` (:func:`combine` of still and gravity with that prior and its gate, bounded; nothing
    subtracted where it gives none), both along the directions ``moving`` observed on each recording
    (``moving``'s gate, :func:`moving_admitted`, compares them like for like)."""
    rows, moving, still_err, still_mov, grav_err, grav_mov, mov_err, mov_mov, auto_err = ([] for _ in range(9))
    for name, t, g, a, b in recordings:
        b = np.asarray(b, dtype=np.float64)
        st, gr = _still(ctx, t, g, a), gravity_bias(t, g, a)
        row: Dict[str, Any] = {"recording": name, "moving_bias_rad_s": _vec(b), "still_minus_moving_rad_s": None,
                               "gravity_error_along_observed_rad_s": None}
        moving.append(b)
        if st.gyro_bias is not None:
            still_err.append(st.gyro_bias - b)
            still_mov.append(b)
            row["still_minus_moving_rad_s"] = _vec(st.gyro_bias - b)
        if gr.gyro_bias is not None and gr.directions is not None:
            # its data's own std along each direction it observed (its prior's information taken out, as
            # _gravity_info), the one the error beyond it is added to
            inv_p = 1.0 / gr.settings.prior_sigma ** 2
            seen = [(np.asarray(u), float(1.0 / np.sqrt(max(1.0 / s ** 2 - inv_p, 1e-30))))
                    for u, s in zip(gr.directions, gr.direction_std) if s <= gr.settings.observed_below]
            e = [(float(u @ (gr.gyro_bias - b)), s) for u, s in seen]
            grav_err.extend(e)
            grav_mov.extend(float(u @ b) for u, _ in seen)
            row["gravity_error_along_observed_rad_s"] = [x for x, _ in e]
            row["gravity_own_std_rad_s"] = [s for _, s in e]
        rows.append(row)

    def rms(x: List[Any]) -> Optional[float]:
        return float(np.sqrt(np.mean(np.square(np.asarray(x, dtype=np.float64))))) if len(x) else None

    n = len(moving)
    extra = None
    if grav_err:
        extra = float(np.sqrt(max(float(np.mean([x * x - s * s for x, s in grav_err])), 0.0)))
    gate: Dict[str, Any] = {}
    shift, still_left = rest_to_motion(still_err)
    if still_err:
        gate["still"] = {"error": rms(still_left), "profile_alone": rms(still_mov)}
    if grav_err:
        gate["gravity"] = {"error": rms([x for x, _ in grav_err]), "profile_alone": rms(grav_mov)}
    out: Dict[str, Any] = {
        "moving_std_rad_s": _vec(np.sqrt(np.mean(np.square(moving), axis=0) * n / (n - 1))) if n >= 2 else None,
        "still_error_std_rad_s": _vec(np.sqrt(np.mean(np.square(still_left), axis=0))) if still_err else None,
        "still_error_unshifted_std_rad_s": _vec(np.sqrt(np.mean(np.square(still_err), axis=0))) if still_err else None,
        "rest_to_motion_rad_s": _vec(shift), "rest_to_motion_rule": REST_TO_MOTION_RULE,
        "still_recordings": len(still_err), "gravity_error_std_rad_s": extra, "gravity_directions": len(grav_err)}
    # the prior as a profile carrying these figures runs: the still estimate's floor, gravity
    # consistency's extra variance and auto's gate from them, the rest (random walk, spread) ctx's
    made = BiasPrior.from_bias_std(ctx.prior.std, ctx.prior.source, measured={**out, "rms_rad_s": gate})
    run = replace(ctx, prior=replace(ctx.prior, moving_std=made.moving_std, still_error_std=made.still_error_std,
                                     gravity_error_std=made.gravity_error_std, measured_rms=made.measured_rms,
                                     rest_to_motion=made.rest_to_motion))
    for row, (_, t, g, a, b) in zip(rows, recordings):
        b = np.asarray(b, dtype=np.float64)
        mv = moving_raw(run, t, g, a)
        if mv.gyro_bias is None:
            continue
        lam, vec = np.linalg.eigh(np.eye(3) - mv.unobserved())
        dirs = vec.T[lam > 0.5]
        # what each subtracts on average as it runs (bias_step: bounded; nothing where rejected)
        sub_mv = bound(mv, run.prior).gyro_bias
        au = _auto(run, t, g, a)
        sub_au = bound(au, run.prior).gyro_bias
        sub_mv = np.zeros(3) if sub_mv is None else sub_mv
        sub_au = np.zeros(3) if sub_au is None else sub_au
        row["moving_error_along_observed_rad_s"] = [float(u @ (sub_mv - b)) for u in dirs]
        row["auto_error_along_moving_observed_rad_s"] = [float(u @ (sub_au - b)) for u in dirs]
        row["auto_used"] = au.detail.get("used")
        mov_err.extend(row["moving_error_along_observed_rad_s"])
        auto_err.extend(row["auto_error_along_moving_observed_rad_s"])
        mov_mov.extend(float(u @ b) for u in dirs)
    if mov_err:  # time averages against the moving bias (constant per recording), the directions moving observed
        gate["moving"] = {"error": rms(mov_err), "profile_alone": rms(mov_mov)}
        gate["auto"] = {"error": rms(auto_err), "profile_alone": rms(mov_mov)}
    return {"recordings": rows, **out, "rms_rad_s": gate}


# -- the step and the summary ----------------------------------------------------------------------


def bias_step(method: str, gravity: float, sink: Dict[str, Any], model: Optional[Path] = None,
              prior: BiasPrior = MEMS_PRIOR) -> Step:
    """The step of ``--bias METHOD``: the estimator of :data:`REGISTRY` on what the steps before give,
    bounded (:func:`bound`) and subtracted. ``sink[method]`` gets the estimate, ``sink["bound"]`` the
    verdict."""
    if method not in REGISTRY:
        raise InvalidInputError(f"--bias: one of {', '.join(choices())}, got {method!r}")
    if REGISTRY[method].needs_model and model is None:
        raise InvalidInputError(f"--bias {method} needs --bias-model PATH (a bias estimator, "
                                "imu_learn.train.bias_train)")
    ctx = Context(float(gravity), prior, None if model is None else Path(model))

    def step(t_ns: Optional[np.ndarray], gyro: np.ndarray, acc: np.ndarray):
        if t_ns is None:
            raise InvalidInputError(f"--bias {method} needs the recording's stamps")
        est = REGISTRY[method].run(ctx, t_ns, gyro, acc)
        verdict = admit(est, bound(est, prior), prior)
        sink[method], sink["bound"] = est, verdict
        if verdict.gyro_bias is None:
            return gyro, acc, None
        if est.per_sample is not None:  # a bias that moves: shifted as the bound moved its average
            return gyro - (est.per_sample + (verdict.gyro_bias - est.gyro_bias)), acc, None
        return gyro - verdict.gyro_bias, acc, None

    return step


def bias_entry(method: str, sink: Dict[str, Any], where: str) -> Tuple[Dict[str, Any], Optional[str]]:
    """(the summary's ``bias`` entry, the log line: a warning when nothing was subtracted, else an info
    line saying how the bound took the estimate). The entry holds the estimator's own summary (its
    ``gyro_bias_rad_s`` the estimate as made), ``applied`` (whether anything was subtracted), ``bound``
    (the verdict and what was subtracted) and ``unobserved_directions_body`` (what the estimate did
    not see: a prior keeps the device bias there)."""
    if method == "none":
        return {"method": "none"}, None
    est: BiasEstimate = sink[method]
    verdict: Verdict = sink["bound"]
    dirs = np.linalg.eigh(est.unobserved())
    unseen = [_vec(v) for lam, v in zip(dirs[0], dirs[1].T) if lam > 0.5]
    entry = {"method": method, "applied": verdict.gyro_bias is not None, **est.detail,
             "bound": verdict.to_dict(), "unobserved_directions_body": unseen}
    if verdict.decision == "none":
        return entry, f"--bias {method}: " + str(est.missing).replace("{where}", where) + "; no bias subtracted"
    if verdict.decision in ("rejected", "gated"):
        return entry, f"--bias {method}: the estimate in {where} is {verdict.why}"
    turns = _turns_refused(entry)
    if verdict.decision == "applied":
        return entry, None if not turns else (
            f"--bias {method}: {len(turns)} quiet stretch(es) in {where} refused as a steady turn, not rest (mean gyro "
            f"up to {max(max(abs(v) for v in r['gyro_mean_rad_s']) for r in turns):.3f} rad/s); the estimate from the "
            "rest")
    return entry, f"--bias {method}: the estimate in {where} is {verdict.why}"


def _turns_refused(entry: Any) -> List[Dict[str, Any]]:
    """The still rule's refused stretches (``refused_as_turning``) anywhere in an estimate's summary."""
    if isinstance(entry, dict):
        found = list(entry.get("refused_as_turning") or [])
        return found + [r for k, v in entry.items() if k != "refused_as_turning" for r in _turns_refused(v)]
    if isinstance(entry, list):
        return [r for v in entry for r in _turns_refused(v)]
    return []
