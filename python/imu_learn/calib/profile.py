"""A device profile: what ``imu-learn calibrate`` learned about one IMU, as one self-describing JSON
file (``profile.json``), and the floor it applies (:meth:`Profile.apply`).

Conventions (also written into the file's ``conventions`` entry, so the file explains itself):

* body frame = the IMU's own axes; world frame = the reference's gravity-aligned frame, z up;
  quaternions (where any appear) Hamilton, w,x,y,z, body -> world.
* time offset: the corrected sample at stamp t is the recorded signal at ``t + time_offset_s``
  (linear interpolation, ends held); ``floor.time_offset`` is the same in samples of the input's
  median period, which is what :meth:`Profile.apply` uses.
* gyroscope: ``w = M_g (LP_g(w_m) - b_g) - G LP_g(a_m)`` [rad/s]; accelerometer:
  ``a = M_a (LP_a(a_m) - b_a)`` [m/s^2]; ``M`` 3x3 (scale on the diagonal, misalignment off it),
  ``b`` bias in the measured units, ``G`` the g-sensitivity [rad/s per m/s^2], ``LP`` a zero-phase
  Butterworth low-pass (``floor.cutoff_*``, null: none). This is ``imu-learn evaluate``'s
  ``traditional+timing`` method; ``floor`` holds that method's own parameter dict (its
  ``to_dict``), and :meth:`Profile.apply` gives the same samples bit for bit as its ``refine``.
* noise in Kalibr's units: white-noise densities [rad/s/sqrt(Hz)], [m/s^2/sqrt(Hz)]; bias random
  walks [rad/s^2/sqrt(Hz)], [m/s^3/sqrt(Hz)]; bias instability [rad/s], [m/s^2].

Every estimate carries its uncertainty (one standard deviation; null where none could be given)
and, for the noise, its source: ``residuals`` (calibrated IMU against the reference trajectory),
``allan`` (Allan deviation of still stretches), ``datasheet``, or ``class_default``: a figure (a bias
random walk; a white noise whose only estimate is the reference's noise) that no fit observed holds the device-class default (:data:`CLASS_DEFAULTS`) as its ``value``, its
``detail`` kind ``not observed`` with the bound the data gave (``upper_bound``, ``upper_bound_per_axis``,
``upper_bound_from``): a bound is never written as a value. (Profiles written before this kept the
bound as the value, kind ``upper bound``; :meth:`Profile.kalibr` reads both as the class default.)

Errors: :meth:`Profile.load` raises :class:`imu_learn.errors.ProfileError` naming the file and the
field. No torch here: applying a profile needs numpy and scipy only.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from imu_learn.baselines.affine import Floor, TraditionalParams
from imu_learn.core.stamps import checked_stamps_ns
from imu_learn.errors import InvalidInputError, ProfileError
from imu_learn.util.atomic import atomic_write_text
from imu_learn.util.file_kind import mix_up

PROFILE_FORMAT = "imu-learn device profile"
PROFILE_VERSION = 1
NOISE_KEYS = ("gyroscope_noise_density", "gyroscope_random_walk",
              "accelerometer_noise_density", "accelerometer_random_walk")
NOISE_UNITS = {
    "gyroscope_noise_density": "rad/s/sqrt(Hz)", "gyroscope_random_walk": "rad/s^2/sqrt(Hz)",
    "accelerometer_noise_density": "m/s^2/sqrt(Hz)", "accelerometer_random_walk": "m/s^3/sqrt(Hz)",
    "gyroscope_bias_instability": "rad/s", "accelerometer_bias_instability": "m/s^2",
}
SOURCES = ("residuals", "allan", "datasheet", "class_default")
NOT_OBSERVED = "not observed"  # a noise term's detail kind: the value is the class default (module doc)
# What a consumer of the profile (imu.yaml, navigate) uses for a bias random walk that no fit observed
# (an Allan upper bound is a bound, not a value): Kalibr's published figures of a MEMS IMU (EuRoC's
# ADIS16448 sensor.yaml), the same as the fusion's built-in noise.
CLASS_DEFAULTS = {"gyroscope_noise_density": 1.6968e-4, "accelerometer_noise_density": 2.0e-3,
                  "gyroscope_random_walk": 1.9393e-5, "accelerometer_random_walk": 3.0e-3}
CLASS_DEFAULT_SOURCE = "MEMS class default (EuRoC ADIS16448 sensor.yaml)"
CONVENTIONS = {
    "body_frame": "the IMU's own axes",
    "world_frame": "the reference's gravity-aligned frame, z up",
    "quaternion": "Hamilton, w,x,y,z, body -> world",
    "time_offset": "corrected(t) = recorded(t + time_offset_s), linear interpolation, ends held",
    "gyroscope_model": "w = M_g (LP_g(w_m) - b_g) - G LP_g(a_m)",
    "accelerometer_model": "a = M_a (LP_a(a_m) - b_a)",
    "uncertainty": "one standard deviation; null where none could be given",
}
FRAMES = {"body": "the IMU's own axes (gyro, acc and every matrix and bias here)",
          "world": "the reference trajectory's frame, gravity along -z"}
UNITS = {"gyroscope": "rad/s", "accelerometer": "m/s^2", "time": "s", "g_sensitivity": "rad/s per m/s^2"}

Number = Optional[float]


def _num(x: Any) -> Number:
    """A float for JSON: NaN and inf become null."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def clean(x: Any) -> Any:
    """``x`` as strict JSON values: numpy arrays and numbers as lists and floats, NaN and inf as null."""
    if isinstance(x, dict):
        return {str(k): clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return clean(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return _num(x)
    return x


def _arr(x: Any) -> Any:
    a = np.asarray(x, dtype=np.float64)
    return [_arr(r) for r in a] if a.ndim > 1 else [_num(v) for v in a]


@dataclass
class Affine:
    """One sensor's affine calibration: ``matrix`` (3, 3) and ``bias`` (3,) in ``unit`` (see the
    module's conventions), each with a standard deviation of the same shape (NaN: unknown)."""

    matrix: np.ndarray
    bias: np.ndarray
    unit: str
    matrix_std: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))
    bias_std: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))

    def to_dict(self) -> Dict[str, Any]:
        return {"unit": self.unit, "matrix": _arr(self.matrix), "matrix_std": _arr(self.matrix_std),
                "bias": _arr(self.bias), "bias_std": _arr(self.bias_std)}


@dataclass
class NoiseTerm:
    """One noise figure: per axis (NaN where an axis gave none), the one scalar Kalibr takes
    (``value``: the root mean square over the axes that gave one), its standard deviation, unit and
    source, and what it came from (``detail``: e.g. the τ range of the fit)."""

    per_axis: np.ndarray
    value: float
    std: float
    unit: str
    source: str
    detail: Dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> Dict[str, Any]:
        return {"value": _num(self.value), "std": _num(self.std), "unit": self.unit, "source": self.source,
                "per_axis": _arr(self.per_axis), "detail": clean(self.detail)}

    @property
    def bounded_only(self) -> bool:
        """No fit observed it: the data gave an upper bound alone (its value the class default where one
        exists, else that bound; profiles written before the class default kept the bound)."""
        return self.detail.get("kind") in (NOT_OBSERVED, "upper bound")

    @property
    def bound(self) -> float:
        """The upper bound the data gave (NaN where the term was observed)."""
        if self.detail.get("kind") == NOT_OBSERVED:
            return float(_nulls_to_nan(self.detail.get("upper_bound")))
        return float(self.value) if self.bounded_only else math.nan


def unobserved_value(key: str, bound: float) -> Tuple[float, str]:
    """(value, where it came from) of a figure no fit observed: the device-class default, or the data's upper
    ``bound`` where that is lower (the default would contradict the data: BROAD's accelerometer random walk is
    bounded by 7.7e-4, the class default 3e-3); never a bound above the default (bounds run to 10-100x it)."""
    d = CLASS_DEFAULTS[key]
    if bound is not None and math.isfinite(bound) and 0 < bound < d:
        return float(bound), f"the data's upper bound {bound:.3g}, below the {CLASS_DEFAULT_SOURCE}'s {d:.3g}"
    return d, CLASS_DEFAULT_SOURCE


def unobserved_term(key: str, per_axis: np.ndarray, bound: float, source: str, detail: Dict[str, Any]) -> NoiseTerm:
    """A figure that no fit observed: its value :func:`unobserved_value` (the class default, or a lower
    bound of the data), the bound the data gave (``per_axis``, ``bound``, from ``source``) in its detail."""
    value, value_from = unobserved_value(key, bound)
    return NoiseTerm(np.full(3, math.nan), value, math.nan, NOISE_UNITS[key], "class_default",
                     {**detail, "kind": NOT_OBSERVED, "value_from": value_from, "upper_bound": _num(bound),
                      "upper_bound_per_axis": _arr(per_axis), "upper_bound_from": source})


@dataclass
class Profile:
    """A device's calibration and noise (module doc). ``floor`` is the ``traditional+timing`` floor
    that :meth:`apply` runs, a :class:`~imu_learn.baselines.affine.Floor` (None: noise only; given
    or assigned as its saved dict, it becomes one); ``gyro``/``acc``/``g_sensitivity``/
    ``time_offset_s`` restate its parameters with their uncertainties (:meth:`of_floor` derives them)."""

    device: str
    sample_rate_hz: float
    time_offset_s: float
    time_offset_s_std: float
    gyro: Affine
    acc: Affine
    g_sensitivity: np.ndarray
    gravity_mps2: float
    gravity_mps2_std: float
    floor: Optional[Floor]
    noise: Dict[str, NoiseTerm] = field(default_factory=dict)
    noise_estimates: List[Dict[str, Any]] = field(default_factory=list)  # every estimate, chosen or not
    sources: List[Dict[str, Any]] = field(default_factory=list)  # recordings and the spans used
    unobservable: List[Dict[str, str]] = field(default_factory=list)  # {"what", "why"}
    fit_log: Dict[str, Any] = field(default_factory=dict)
    # the statistics of each recording it was fitted on (imu_learn.infer.guard.training_inputs), for
    # refine's guard; written only when known
    inputs: Dict[str, Any] = field(default_factory=dict)
    # how the reference was moved into the IMU's frame (calib.reference.FrameFit.to_dict); empty: as given
    reference: Dict[str, Any] = field(default_factory=dict)
    # per floor parameter: {"observed": bool, "why": ...}; what was not observed keeps its prior
    observed: Dict[str, Any] = field(default_factory=dict)
    # the plausibility limits, the held-back block's errors and any check written through with --force
    checks: Dict[str, Any] = field(default_factory=dict)
    # the floor's terms chosen on held-out recordings (calib.select: the levels, the rule, the figures)
    selection: Dict[str, Any] = field(default_factory=dict)
    # the device's bias prior for --bias measured on its training recordings (experiments/bias_prior.py
    # fit: the moving bias's spread, the still and gravity estimators' errors); empty: none
    bias_prior: Dict[str, Any] = field(default_factory=dict)
    version: int = PROFILE_VERSION
    created: str = field(default_factory=lambda: datetime.now(timezone.utc).isoformat(timespec="seconds"))

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "floor":
            value = Floor.of(value)
        super().__setattr__(name, value)
        if name == "floor" and value is not None and "gyro" in self.__dict__:
            # the floor is what is applied: the sensors' blocks and the g-sensitivity are derived from it
            # (their standard deviations and units kept), so they never say one thing while it does another
            p = value.params
            super().__setattr__("gyro", replace(self.gyro, matrix=p.M_g.copy(), bias=p.b_g.copy()))
            super().__setattr__("acc", replace(self.acc, matrix=p.M_a.copy(), bias=p.b_a.copy()))
            super().__setattr__("g_sensitivity", p.G.copy())

    @classmethod
    def of_floor(cls, device: str, sample_rate_hz: float, period_s: float, floor: Floor, std: TraditionalParams,
                 gravity_mps2: float, gravity_mps2_std: float, **extra: Any) -> Profile:
        """A profile whose time offset [s], affine calibrations and g-sensitivity are ``floor``'s
        (its time offset in samples of ``period_s``), each with its standard deviation from ``std``."""
        p = floor.params
        return cls(
            device=device, sample_rate_hz=sample_rate_hz,
            time_offset_s=float(p.time_offset) * period_s, time_offset_s_std=float(std.time_offset) * period_s,
            gyro=Affine(p.M_g.copy(), p.b_g.copy(), UNITS["gyroscope"], std.M_g, std.b_g),
            acc=Affine(p.M_a.copy(), p.b_a.copy(), UNITS["accelerometer"], std.M_a, std.b_a),
            g_sensitivity=p.G.copy(), gravity_mps2=gravity_mps2, gravity_mps2_std=gravity_mps2_std, floor=floor, **extra)

    # -- the floor --------------------------------------------------------------------------------

    def apply(self, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Floor-calibrated (gyro, acc), each (N, 3) float64: the time offset, then the low-pass and
        the affine model, exactly as ``traditional+timing``'s ``refine`` (same operations in the same
        order, so the same bits). A profile without a floor (noise only) returns copies. ``t_ns``: int64
        nanoseconds, strictly increasing, one per row of ``gyro`` and ``acc`` ((N, 3)); anything else is
        an :class:`~imu_learn.errors.InvalidInputError` (the time offset resamples along them)."""
        gyro = np.asarray(gyro, dtype=np.float64)
        acc = np.asarray(acc, dtype=np.float64)
        t = checked_stamps_ns(t_ns)
        for what, x in (("gyro", gyro), ("acc", acc)):
            if x.shape != (len(t), 3):
                raise InvalidInputError(f"{what} must be ({len(t)}, 3), one row per stamp, got {x.shape}")
        if self.floor is None:
            return gyro.copy(), acc.copy()
        return self.floor.apply(t, gyro, acc)

    @property
    def has_floor(self) -> bool:
        return self.floor is not None

    @property
    def floor_dict(self) -> Dict[str, Any]:
        """The floor's saved dict (empty: noise only)."""
        return self.floor.to_dict() if self.floor is not None else {}

    # -- persistence ------------------------------------------------------------------------------

    def to_dict(self) -> Dict[str, Any]:
        return {
            "format": PROFILE_FORMAT, "version": self.version, "created": self.created, "device": self.device,
            "conventions": CONVENTIONS, "frames": FRAMES, "units": UNITS,
            "sample_rate_hz": _num(self.sample_rate_hz),
            "time_offset_s": _num(self.time_offset_s), "time_offset_s_std": _num(self.time_offset_s_std),
            "gyroscope": self.gyro.to_dict(), "accelerometer": self.acc.to_dict(),
            "g_sensitivity_rad_s_per_mps2": _arr(self.g_sensitivity),
            "gravity_mps2": _num(self.gravity_mps2), "gravity_mps2_std": _num(self.gravity_mps2_std),
            "noise": {k: v.to_dict() for k, v in self.noise.items()},
            "noise_estimates": clean(self.noise_estimates),
            "floor": clean(self.floor_dict), "sources": clean(self.sources), "unobservable": self.unobservable,
            "fit_log": clean(self.fit_log),
            **({"inputs": clean(self.inputs)} if self.inputs else {}),
            **{k: clean(getattr(self, k)) for k in ("reference", "observed", "checks", "selection", "bias_prior")
               if getattr(self, k)},
        }

    def save(self, path: Union[str, Path]) -> None:
        """Write ``path`` atomically (a reader sees the old file or the new one)."""
        atomic_write_text(Path(path), json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n")

    @classmethod
    def load(cls, path: Union[str, Path]) -> Profile:
        """Read a profile; a missing file is FileNotFoundError, anything malformed a
        :class:`ProfileError` naming the file and the field."""
        path = Path(path)
        if path.is_dir():
            inside = " (it holds profile.json: give that)" if (path / "profile.json").is_file() else ""
            raise ProfileError(f"{path}: a folder, not a device profile{inside}", str(path))
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            raise ProfileError(f"{path}: a binary file, not a device profile (profile.json){mix_up(path, 'profile')}",
                               str(path)) from None
        try:
            d = json.loads(text)
        except json.JSONDecodeError as e:
            raise ProfileError(f"{path}:{e.lineno}: not JSON ({e.msg}){mix_up(path, 'profile')}", str(path), e.lineno,
                               e.colno) from None
        return cls.from_dict(d, str(path))

    @classmethod
    def from_dict(cls, d: Any, where: str = "<profile>") -> Profile:
        r = _Reader(d, where)
        if not isinstance(d, dict) or d.get("format") != PROFILE_FORMAT:
            raise ProfileError(f"{where}: not an imu-learn device profile (field 'format' is not "
                               f"{PROFILE_FORMAT!r})", where, field="format")
        version = int(r.number("version"))
        if version > PROFILE_VERSION:
            raise ProfileError(f"{where}: field 'version': profile version {version} is newer than this imu-learn "
                               f"reads ({PROFILE_VERSION}); upgrade imu-learn", where, field="version")
        floor = r.get("floor", dict, {})
        if floor:
            Floor.check_dict(floor, lambda k, what: ProfileError(f"{where}: field 'floor.{k}': {what}", where,
                                                                field=f"floor.{k}"))
        noise = {k: r.noise(k) for k in r.get("noise", dict, {})}
        gyro, acc = r.affine("gyroscope"), r.affine("accelerometer")
        G = r.array("g_sensitivity_rad_s_per_mps2", (3, 3))
        if floor:
            _check_derived(where, Floor.from_dict(floor).params, gyro, acc, G)
        return cls(
            device=r.get("device", str), sample_rate_hz=r.number("sample_rate_hz"),
            time_offset_s=r.number("time_offset_s"), time_offset_s_std=r.number("time_offset_s_std", True),
            gyro=gyro, acc=acc, g_sensitivity=G,
            gravity_mps2=r.number("gravity_mps2", True), gravity_mps2_std=r.number("gravity_mps2_std", True),
            floor=floor, noise=noise, noise_estimates=r.get("noise_estimates", list, []),
            sources=r.get("sources", list, []), unobservable=r.get("unobservable", list, []),
            fit_log=r.get("fit_log", dict, {}), inputs=r.get("inputs", dict, {}), version=version,
            reference=r.get("reference", dict, {}), observed=r.get("observed", dict, {}), checks=r.get("checks", dict, {}),
            selection=r.get("selection", dict, {}), bias_prior=r.get("bias_prior", dict, {}),
            created=r.get("created", str, ""),
        )

    def kalibr(self) -> Dict[str, Optional[float]]:
        """The four Kalibr noise figures (None where the profile has none); a random walk that was not
        observed (an upper bound) is the device-class default (:data:`CLASS_DEFAULTS`), or the bound where that is
        lower (:func:`unobserved_value`), never a bound above the default."""
        return {k: (unobserved_value(k, self.noise[k].bound)[0] if self.unobserved_noise(k) else _num(self.noise[k].value) if k in self.noise
                    else None) for k in NOISE_KEYS}

    def rate_terms(self) -> str:
        """What in the floor depends on the rate it was made at, in words ("" where nothing does): a
        time offset a fit observed (in samples of that rate: an IMU at another rate has its own latency and
        filter delay; the zero-order hold's half sample that an unobserved one keeps is half a sample at
        any rate) and a low-pass (chosen against that rate's noise and bandwidth). Biases, matrices, the
        g-sensitivity and the noise densities do not depend on it."""
        if self.floor is None:
            return ""
        p = self.floor.params
        terms = []
        seen = self.observed.get("time_offset", {})
        if p.time_offset and not (isinstance(seen, dict) and seen.get("observed") is False):
            terms.append(f"time offset ({float(p.time_offset):.3g} samples)")
        cut = [f"{k} {c:g} Hz" for k, c in (("gyro", p.cutoff_gyro), ("acc", p.cutoff_acc)) if c is not None]
        if cut:
            terms.append("low-pass (" + ", ".join(cut) + ")")
        return " and ".join(terms)

    def unobserved_noise(self, key: str) -> bool:
        """A random walk the profile only bounds (an Allan or residual upper bound)."""
        t = self.noise.get(key)
        return key in CLASS_DEFAULTS and t is not None and t.bounded_only

    def recording_groups(self) -> Tuple[int, bool]:
        """(the number of groups in the fit log, whether they are recordings): one entry of
        ``fit_log["groups"]`` per recording refitted alone; a profile fitted on one recording has time
        blocks of it (``block1`` ..) as groups, whose spread is not between recordings."""
        groups = self.fit_log.get("groups") if isinstance(self.fit_log, dict) else None
        if not isinstance(groups, list):
            return 0, False
        names = [str(g.get("group", "")) if isinstance(g, dict) else "" for g in groups]
        blocks = any(n.startswith("block") and n[5:].isdigit() for n in names)
        return len(groups), not blocks

    def bias_spread(self, sensor: str = "gyro") -> Tuple[Optional[np.ndarray], str]:
        """((3,) the spread of ``sensor``'s (``gyro``/``acc``) bias *between recordings*, or None; why).

        ``bias_std`` is the standard error of the floor's mean over the fit's groups
        (:mod:`imu_learn.calib.fit`: the spread of the per-group values over sqrt(groups)), so the
        per-recording spread is ``bias_std × sqrt(groups)`` (:func:`per_recording_spread`). None where
        the profile does not give one: fewer than two groups, time blocks of one recording, or a
        ``bias_std`` not known on every axis."""
        n, recordings = self.recording_groups()
        if n < 2:
            return None, f"the fit has {n} group(s), no spread between recordings"
        if not recordings:
            return None, "the profile's groups are time blocks of one recording, not recordings"
        s = per_recording_spread((self.gyro if sensor == "gyro" else self.acc).bias_std, n)
        if not np.all(np.isfinite(s)):
            return None, "the profile's bias_std is not known on every axis"
        return s, f"bias_std x sqrt({n} groups)"

    def gyro_bias_prior_std(self) -> Tuple[np.ndarray, str]:
        """((3,) the gyro bias spread a ``--bias`` prior is given, how): the per-recording spread
        (:meth:`bias_spread`), else (one recording, no groups) ``bias_std`` itself."""
        s, why = self.bias_spread("gyro")
        if s is None:
            return np.asarray(self.gyro.bias_std, dtype=np.float64).reshape(3), f"bias_std ({why})"
        return s, f"per recording, {why}"


def per_recording_spread(bias_std: Any, groups: int) -> np.ndarray:
    """(3,) the spread of a bias between recordings from a standard error of the mean over ``groups``
    independent groups: ``bias_std × sqrt(groups)`` (NaN where unknown)."""
    return np.asarray(bias_std, dtype=np.float64).reshape(3) * math.sqrt(groups)


class _Reader:
    """Typed access to a profile dict; every failure is a ProfileError naming the file and field."""

    def __init__(self, d: Any, where: str) -> None:
        self.d = d if isinstance(d, dict) else {}
        self.where = where

    def fail(self, key: str, what: str) -> ProfileError:
        return ProfileError(f"{self.where}: field {key!r}: {what}", self.where, field=key)

    def get(self, key: str, kind: type, default: Any = ..., d: Optional[dict] = None) -> Any:
        d = self.d if d is None else d
        if key not in d:
            if default is ...:
                raise self.fail(key, "missing")
            return default
        v = d[key]
        if not isinstance(v, kind):
            raise self.fail(key, f"expected {kind.__name__}, got {type(v).__name__}")
        return v

    def number(self, key: str, nullable: bool = False, d: Optional[dict] = None) -> float:
        d = self.d if d is None else d
        if key not in d:
            raise self.fail(key, "missing")
        v = d[key]
        if v is None and nullable:
            return math.nan
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.fail(key, f"expected a finite number, got {v!r}")
        return float(v)

    def array(self, key: str, shape: Tuple[int, ...], d: Optional[dict] = None, nullable: bool = False) -> np.ndarray:
        d = self.d if d is None else d
        if key not in d:
            raise self.fail(key, "missing")
        try:
            raw = d[key]
            a = np.array(raw if not nullable else _nulls_to_nan(raw), dtype=np.float64)
        except (TypeError, ValueError):
            raise self.fail(key, f"expected numbers of shape {shape}") from None
        if a.shape != shape:
            raise self.fail(key, f"expected numbers of shape {shape}, got shape {a.shape}")
        if not nullable and not np.all(np.isfinite(a)):
            raise self.fail(key, f"holds NaN or infinite values (at {np.argwhere(~np.isfinite(a))[0].tolist()}); "
                                 "expected finite numbers")
        return a

    def affine(self, key: str) -> Affine:
        d = self.get(key, dict)
        sub = _Reader(d, self.where)
        sub.fail = lambda k, what: self.fail(f"{key}.{k}", what)  # type: ignore[method-assign]
        return Affine(sub.array("matrix", (3, 3)), sub.array("bias", (3,)), sub.get("unit", str),
                      sub.array("matrix_std", (3, 3), nullable=True), sub.array("bias_std", (3,), nullable=True))

    def noise(self, key: str) -> NoiseTerm:
        d = self.get(key, dict, d=self.get("noise", dict))
        sub = _Reader(d, self.where)
        sub.fail = lambda k, what: self.fail(f"noise.{key}.{k}", what)  # type: ignore[method-assign]
        source = sub.get("source", str)
        if source not in SOURCES:
            raise sub.fail("source", f"expected one of {', '.join(SOURCES)}, got {source!r}")
        return NoiseTerm(sub.array("per_axis", (3,), nullable=True), sub.number("value"), sub.number("std", True),
                         sub.get("unit", str), source, sub.get("detail", dict, {}))


def _nulls_to_nan(x: Any) -> Any:
    if isinstance(x, list):
        return [_nulls_to_nan(v) for v in x]
    return math.nan if x is None else x


def apply_floor(floor: Any, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """``traditional+timing``'s ``refine`` on raw arrays, from ``floor`` (a :class:`Floor` or its saved
    dict; the one torch-free home of the floor's application, :mod:`imu_learn.baselines.affine`)."""
    f = Floor.of(floor)
    assert f is not None, "apply_floor: no floor"
    return f.apply(t_ns, gyro, acc)


def noise_only(device: str, sample_rate: float, noise: Dict[str, NoiseTerm], **extra: Any) -> Profile:
    """A profile with noise and no floor (a still recording without a reference): identity
    calibration, nothing applied."""
    nan3, nan33 = np.full(3, np.nan), np.full((3, 3), np.nan)
    return Profile(device=device, sample_rate_hz=sample_rate, time_offset_s=0.0, time_offset_s_std=math.nan,
                   gyro=Affine(np.eye(3), np.zeros(3), UNITS["gyroscope"], nan33.copy(), nan3.copy()),
                   acc=Affine(np.eye(3), np.zeros(3), UNITS["accelerometer"], nan33.copy(), nan3.copy()),
                   g_sensitivity=np.zeros((3, 3)), gravity_mps2=math.nan if "gravity" not in extra else extra.pop("gravity"),
                   gravity_mps2_std=math.nan, floor=None, noise=noise, **extra)


@dataclass
class FloorFit:
    """The floor (TraditionalTiming's), its fit log, and per parameter the standard deviation over
    groups (``std``: the parameters' shapes; NaN with fewer than two groups). ``entries``: what
    profile.json's ``fit_log`` says of the fit (default: the log and the groups; a reference source
    that fits its floor otherwise says its own)."""

    floor: Floor
    log: Dict[str, list]
    std: TraditionalParams
    groups: List[Dict[str, object]]
    entries: Optional[Dict[str, Any]] = field(default=None)

    def log_entries(self) -> Dict[str, Any]:
        return self.entries if self.entries is not None else {"floor": self.log, "groups": self.groups}


def _check_derived(where: str, p: TraditionalParams, gyro: Affine, acc: Affine, G: np.ndarray) -> None:
    """A saved profile's derived blocks agree with its floor (what refine and navigate apply is the floor;
    the blocks say it in the profile's units): a hand-edited profile whose blocks were swapped or changed
    on one side only is refused, naming the field, rather than applied as one thing and read as another."""
    pairs = (("gyroscope.matrix", gyro.matrix, p.M_g, "M_g"), ("gyroscope.bias", gyro.bias, p.b_g, "b_g"),
             ("accelerometer.matrix", acc.matrix, p.M_a, "M_a"), ("accelerometer.bias", acc.bias, p.b_a, "b_a"),
             ("g_sensitivity_rad_s_per_mps2", G, p.G, "G"))
    for name, top, floor_value, key in pairs:
        if not np.allclose(top, floor_value, rtol=1e-6, atol=1e-9):
            raise ProfileError(f"{where}: field '{name}' disagrees with 'floor.{key}' (edited on one side only?): the "
                               "floor is what is applied; write the profile again with imu-learn calibrate", where,
                               field=name)
    for name, block in (("gyroscope", gyro), ("accelerometer", acc)):
        if block.unit != UNITS[name]:
            raise ProfileError(f"{where}: field '{name}.unit' is {block.unit!r}, not {UNITS[name]!r}: blocks swapped "
                               "or edited?", where, field=f"{name}.unit")
