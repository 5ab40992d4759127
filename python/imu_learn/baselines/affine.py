"""The affine floor applied to raw samples, without torch: the one home of what ``traditional`` and
``traditional+timing`` do at inference (:meth:`imu_learn.baselines.traditional.Traditional.refine`)
and of what a device profile applies (:meth:`imu_learn.calib.profile.Profile.apply`).

    gyro' = M_g (LP_g(gyro) - b_g) - G LP_g(acc)        acc' = M_a (LP_a(acc) - b_a)

after the time offset (gyro and acc resampled at t + time_offset samples, :func:`.timing.resample`).
LP is a zero-phase Butterworth low-pass of each axis (``None``: no filter): ``scipy.signal``'s
``butter`` and ``sosfiltfilt`` (odd padding of 3 × (2 · sections + 1) samples, each pass started in
the steady state of its first sample). The floor's order 2 (every saved floor's) is computed without
scipy (:func:`butter2` here, :func:`filtfilt2` in the core): importing ``scipy.signal`` costs about 1 s
of CPU (scipy 1.17), a fifth of ``imu-learn calibrate``; other orders import it."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Callable, Dict, Iterator, Optional, Tuple

import numpy as np

from imu_learn.baselines.timing import resample
from imu_learn.core.filtering import filtfilt_section
from imu_learn.core.stamps import median_period_ns, sample_rate_hz

# The floor's parameters by name: the one home of the keys of its saved dict (a device profile's
# ``floor``, ``Traditional.to_dict``) and of their shapes.
ARRAYS: Tuple[Tuple[str, Tuple[int, ...]], ...] = (("M_g", (3, 3)), ("b_g", (3,)), ("G", (3, 3)), ("M_a", (3, 3)),
                                                   ("b_a", (3,)))
CUTOFFS = ("cutoff_gyro", "cutoff_acc")
ESTIMATES = tuple(k for k, _ in ARRAYS) + ("time_offset",)  # what a fit estimates (the cutoffs: chosen from a grid)
FLOOR_METHOD = "traditional+timing"
Fail = Callable[[str, str], Exception]


@dataclass
class TraditionalParams:
    """Fitted parameters (float64 arrays) and the chosen cutoffs [Hz] (None: no filter)."""

    M_g: np.ndarray
    b_g: np.ndarray
    G: np.ndarray
    M_a: np.ndarray
    b_a: np.ndarray
    cutoff_gyro: Optional[float] = None
    cutoff_acc: Optional[float] = None
    time_offset: float = 0.0  # [samples]: IMU resampled at t + time_offset·dt before the model

    @classmethod
    def identity(cls) -> TraditionalParams:
        return cls(np.eye(3), np.zeros(3), np.zeros((3, 3)), np.eye(3), np.zeros(3))

    @classmethod
    def unknown(cls) -> TraditionalParams:
        """Every estimate NaN, no cutoffs: the standard deviations where none could be given."""
        return cls(*(np.full(shape, np.nan) for _, shape in ARRAYS), time_offset=np.float64(np.nan))

    @classmethod
    def biases(cls, b_g: Any, b_a: Any) -> TraditionalParams:
        """Biases only: identity matrices, no g-sensitivity, no filter, no offset."""
        return replace(cls.identity(), b_g=np.asarray(b_g, dtype=np.float64), b_a=np.asarray(b_a, dtype=np.float64))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TraditionalParams:
        """From the method's saved dict (``Traditional.to_dict``; a device profile's ``floor``)."""
        a = lambda k: np.asarray(d[k], dtype=np.float64)  # noqa: E731
        return cls(*(a(k) for k, _ in ARRAYS), d.get(CUTOFFS[0]), d.get(CUTOFFS[1]), float(d.get("time_offset", 0.0)))

    def to_dict(self) -> Dict[str, Any]:
        """The saved form's entries (lists and floats; the order of ``Traditional.to_dict``, without
        its ``method`` and ``filter_order``)."""
        return {**{k: getattr(self, k).tolist() for k, _ in ARRAYS}, **{k: getattr(self, k) for k in CUTOFFS},
                "time_offset": self.time_offset}

    def estimate(self, name: str) -> np.ndarray:
        """One of :data:`ESTIMATES` as an array (the time offset 0-d)."""
        return np.asarray(getattr(self, name), dtype=np.float64)

    def without_lowpass(self) -> TraditionalParams:
        return replace(self, cutoff_gyro=None, cutoff_acc=None)

    @staticmethod
    def check_dict(d: Mapping[str, Any], fail: Fail) -> None:
        """Raise ``fail(key, what)`` for the first entry of a saved dict that :meth:`from_dict` cannot
        take: an array missing or not finite numbers of its shape, a cutoff not positive, a time
        offset not a finite number."""
        for k, shape in ARRAYS:
            try:
                a = np.asarray(d[k], dtype=np.float64)
            except KeyError:
                raise fail(k, "missing") from None
            except (TypeError, ValueError):
                raise fail(k, f"expected numbers of shape {shape}") from None
            if a.shape != shape:
                raise fail(k, f"expected numbers of shape {shape}, got shape {a.shape}")
            if not np.all(np.isfinite(a)):
                raise fail(k, f"holds NaN or infinite values (at {np.argwhere(~np.isfinite(a))[0].tolist()}); "
                              "expected finite numbers")
        for k in CUTOFFS:
            v = d.get(k)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0):
                raise fail(k, f"expected a positive cutoff [Hz] or null, got {v!r}")
        t = d.get("time_offset", 0.0)
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
            raise fail("time_offset", f"expected a finite number of samples, got {t!r}")


@dataclass(eq=False)
class Floor(Mapping):
    """A floor as one typed object: its parameters, the method that fitted them and the low-pass's
    order. It reads as its saved dict too (``floor["M_g"]``, ``floor.get(...)``, ``==`` a dict: the
    lists and floats of :meth:`to_dict`), the form a device profile's ``floor`` had before."""

    params: TraditionalParams
    method: str = FLOOR_METHOD
    filter_order: int = 2

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Floor:
        return cls(TraditionalParams.from_dict(d), d.get("method", FLOOR_METHOD), int(d.get("filter_order", 2)))

    @classmethod
    def of(cls, x: Any) -> Optional[Floor]:
        """``x`` as a Floor: a Floor, its parameters, or its saved dict; None or an empty dict: none."""
        if x is None or isinstance(x, Floor):
            return x
        if isinstance(x, TraditionalParams):
            return cls(x)
        if isinstance(x, Mapping):
            return cls.from_dict(x) if len(x) else None
        raise TypeError(f"a floor is a Floor, TraditionalParams or its saved dict, not {type(x).__name__}")

    @staticmethod
    def check_dict(d: Mapping[str, Any], fail: Fail, method: str = FLOOR_METHOD) -> None:
        """:meth:`TraditionalParams.check_dict` after the method (``method`` the one expected)."""
        if d.get("method") != method:
            raise fail("method", f"expected {method!r}, got {d.get('method')!r}")
        TraditionalParams.check_dict(d, fail)

    def to_dict(self) -> Dict[str, Any]:
        """The saved dict, in ``Traditional.to_dict``'s order."""
        p = self.params.to_dict()
        t = p.pop("time_offset")
        return {"method": self.method, **p, "filter_order": self.filter_order, "time_offset": t}

    def apply(self, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """:func:`apply` with this floor's parameters and filter order."""
        return apply(self.params, t_ns, gyro, acc, self.filter_order)

    def with_params(self, **changes: Any) -> Floor:
        return replace(self, params=replace(self.params, **changes))

    def without_lowpass(self) -> Floor:
        return replace(self, params=self.params.without_lowpass())

    # the saved dict's read-only view
    def __getitem__(self, key: str) -> Any:
        return self.to_dict()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.to_dict())

    def __len__(self) -> int:
        return len(self.to_dict())

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Mapping):
            return self.to_dict() == dict(other.items())
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]


def butter2(cutoff_hz: float, fs: float) -> np.ndarray:
    """``scipy.signal.butter(2, cutoff_hz, fs=fs, output="sos")`` in closed form (the bilinear
    transform with the cutoff prewarped, K = tan(π f_c / f_s)): one section (1, 6)."""
    k, s2 = math.tan(math.pi * cutoff_hz / fs), math.sqrt(2.0)
    norm = 1.0 / (1.0 + s2 * k + k * k)
    b0 = k * k * norm
    return np.array([[b0, 2.0 * b0, b0, 1.0, 2.0 * (k * k - 1.0) * norm, (1.0 - s2 * k + k * k) * norm]])


def filtfilt2(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``scipy.signal.sosfiltfilt(sos, x, axis=0)`` for one Butterworth low-pass section (:func:`butter2`)
    on x (N, C), N > 9: odd extension by 9 samples, a forward and a backward steady-state pass (the
    core's :func:`~imu_learn.core.filtering.filtfilt_section`). Agrees with scipy's to ~1e-14 of max |x|
    (tests/test_floor_numpy.py)."""
    return filtfilt_section(sos, x)


def lowpass(x: np.ndarray, fs: float, cutoff_hz: Optional[float], order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass of each column of x (N, C); ``None`` (or a cutoff at or above
    Nyquist, or a signal too short for the filter's padding) returns x unchanged. Order 2 in numpy
    (:func:`filtfilt2`), other orders by ``scipy.signal``."""
    x = np.asarray(x, dtype=np.float64)
    if cutoff_hz is None or cutoff_hz >= 0.5 * fs:
        return x.copy()
    sections = (order + 1) // 2
    if len(x) <= 3 * (2 * sections + 1):
        return x.copy()
    if order == 2:
        return filtfilt2(butter2(cutoff_hz, fs), x)
    from scipy.signal import butter, sosfiltfilt

    return sosfiltfilt(butter(order, cutoff_hz, btype="low", fs=fs, output="sos"), x, axis=0)


def apply(p: TraditionalParams, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
          order: int = 2) -> Tuple[np.ndarray, np.ndarray]:
    """Floor-calibrated (gyro, acc), each (N, 3) float64 and C-contiguous."""
    if p.time_offset != 0.0:
        per = median_period_ns(t_ns)
        gyro, acc = resample(t_ns, gyro, p.time_offset, per), resample(t_ns, acc, p.time_offset, per)
    fs = sample_rate_hz(t_ns)
    g_f = lowpass(gyro, fs, p.cutoff_gyro, order)
    ag_f = lowpass(acc, fs, p.cutoff_gyro, order)
    a_f = lowpass(acc, fs, p.cutoff_acc, order)
    g_out = (g_f - p.b_g) @ p.M_g.T - ag_f @ p.G.T
    a_out = (a_f - p.b_a) @ p.M_a.T
    return np.ascontiguousarray(g_out), np.ascontiguousarray(a_out)
