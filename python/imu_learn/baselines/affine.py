"""The affine floor applied to raw samples, without torch: the one home of what ``traditional`` and
``traditional+timing`` do at inference (:meth:`imu_learn.baselines.traditional.Traditional.refine`)
and of what a device profile applies (:meth:`imu_learn.calib.profile.Profile.apply`).

    gyro' = M_g (LP_g(gyro) - b_g) - G LP_g(acc)        acc' = M_a (LP_a(acc) - b_a)

after the time offset (gyro and acc resampled at t + time_offset samples, :func:`.timing.resample`).
LP is a zero-phase Butterworth low-pass of each axis (``None``: no filter)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Optional, Tuple

import numpy as np
from scipy.signal import butter, sosfiltfilt

from imu_learn.baselines.timing import resample
from imu_learn.core.stamps import median_period_ns, sample_rate_hz


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
    def from_dict(cls, d: Dict[str, Any]) -> TraditionalParams:
        """From the method's saved dict (``Traditional.to_dict``; a device profile's ``floor``)."""
        a = lambda k: np.asarray(d[k], dtype=np.float64)  # noqa: E731
        return cls(a("M_g"), a("b_g"), a("G"), a("M_a"), a("b_a"), d.get("cutoff_gyro"), d.get("cutoff_acc"),
                   float(d.get("time_offset", 0.0)))


def lowpass(x: np.ndarray, fs: float, cutoff_hz: Optional[float], order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass of each column of x (N, C); ``None`` (or a cutoff at or above
    Nyquist, or a signal too short for the filter's padding) returns x unchanged."""
    x = np.asarray(x, dtype=np.float64)
    if cutoff_hz is None or cutoff_hz >= 0.5 * fs:
        return x.copy()
    sos = butter(order, cutoff_hz, btype="low", fs=fs, output="sos")
    padlen = 3 * (2 * len(sos) + 1)
    if len(x) <= padlen:
        return x.copy()
    return sosfiltfilt(sos, x, axis=0)


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
