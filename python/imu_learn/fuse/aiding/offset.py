"""The aiding's time offset against the IMU, from the data: the lag that best matches the aiding's
angular-rate magnitude with the gyro's (the cross-correlation of |ω| that ``imu-learn calibrate``
runs on a reference, :func:`imu_learn.calib.reference.fit_lag`; a magnitude does not depend on the
frame, so the camera's poses need no extrinsic for it), refined to a fraction of the grid by a
parabola through the peak. The offset is applied to the aiding's stamps (``t - lag``: the aiding
stamp ``t`` is the motion the IMU sees at ``t - lag``) only where the peak's correlation says the
two are the same motion (``min_correlation``), the peak is not at the search's edge, and the lag is
at least one IMU sample (``min_shift_s``): a smaller one moves no row to another sample, and the
estimate has a bias of its own of about half a sample (where a gyro sample stands for the rate over
the interval before or after its stamp). Otherwise the stamps are left as read and the summary
says why."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Optional

import numpy as np

from imu_learn.calib.reference import _rates_on_grid, fit_lag
from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import ReferenceFrameError

# the search: +-1 s, calibrate's (FrameOptions.max_lag_s; a camera on the IMU's clock is within a few ms, a
# clock set by hand or a logging delay far more: a VO 0.2 s late was at the +-0.2 s edge, fused unmoved, exit 0)
MAX_LAG_S = 1.0
GRID_S = 0.001  # the correlation grid [s]
MIN_CORRELATION = 0.6


@dataclass(frozen=True)
class AidingOffset:
    """``lag_s``: the IMU at t matches the aiding stamped t + lag_s; ``correlation`` of the |ω| peak;
    ``applied``: whether the aiding's stamps were moved by it; ``why``: what decided that."""

    lag_s: Optional[float]
    correlation: Optional[float]
    applied: bool
    why: str

    def to_dict(self) -> Dict[str, object]:
        return {"lag_s": None if self.lag_s is None else round(self.lag_s, 5),
                "correlation": None if self.correlation is None else round(self.correlation, 3),
                "applied": self.applied, "why": self.why}


def estimate_offset(imu_t_ns: np.ndarray, gyro: np.ndarray, t_ns: np.ndarray, q_xyzw: np.ndarray,
                    max_lag_s: float = MAX_LAG_S, min_correlation: float = MIN_CORRELATION,
                    min_shift_s: float = 0.0) -> AidingOffset:
    """The aiding–IMU time offset from the aiding's rotations ``q_xyzw`` (N, 4) at ``t_ns`` and the gyro
    (module docstring). Never raises for a poor match: the result says it was not applied."""
    ref = GroundTruth(np.asarray(t_ns, dtype=np.int64), np.zeros((len(t_ns), 3)),
                      np.asarray(q_xyzw, dtype=np.float64)[:, [3, 0, 1, 2]])
    imu = ImuData(np.asarray(imu_t_ns, dtype=np.int64), np.asarray(gyro, dtype=np.float64), np.zeros_like(gyro))
    try:
        lag, corr, edge = fit_lag(imu, ref, max_lag_s, GRID_S)
    except ReferenceFrameError as e:
        return AidingOffset(None, None, False, f"not estimated: {' '.join(str(e).split())}")
    if edge:
        return AidingOffset(lag, corr, False, f"at the search's edge (+-{max_lag_s:g} s): not applied")
    if not corr >= min_correlation:
        return AidingOffset(lag, corr, False, f"|w| correlation {corr:.2f} < {min_correlation:g}: not applied")
    lag = lag + _subgrid(imu, ref, lag, max_lag_s)
    if abs(lag) < min_shift_s:
        return AidingOffset(lag, corr, False, f"|w| cross-correlation, peak {corr:.2f}; within one IMU sample "
                                              f"({1e3 * min_shift_s:.3g} ms): not applied")
    return AidingOffset(lag, corr, True, f"|w| cross-correlation, peak {corr:.2f}")


def _subgrid(imu: ImuData, ref: GroundTruth, lag: float, max_lag_s: float) -> float:
    """The parabola's vertex through the correlation at ``lag`` and one grid step either side [s]."""
    vals = []
    for d in (-GRID_S, 0.0, GRID_S):
        shifted = GroundTruth(ref.t_ns - int(round((lag + d) * 1e9)), ref.p, ref.q_wxyz)
        vals.append(_corr_at_zero(imu, shifted))
    a, b, c = vals
    den = a - 2 * b + c
    if not (np.isfinite(den) and den < 0):
        return 0.0
    return float(np.clip(0.5 * (a - c) / den, -0.5, 0.5) * GRID_S)


def _corr_at_zero(imu: ImuData, ref: GroundTruth) -> float:
    """The normalised correlation of the |ω| signals at zero lag (the grid of :func:`fit_lag`)."""
    t_i, t_r = imu.t_ns * 1e-9, ref.t_ns * 1e-9
    t0, t1 = max(t_i[0], t_r[0]), min(t_i[-1], t_r[-1])
    grid = np.arange(t0, t1, GRID_S)
    k = max(1, int(round(float(np.median(np.diff(t_r))) / GRID_S)))
    box = np.ones(k) / k
    wi = np.convolve(np.interp(grid, t_i, np.linalg.norm(imu.gyro, axis=1)), box, "same")
    wr = np.convolve(_rates_on_grid(t_r, ref.q_wxyz, grid), box, "same")
    return float(np.corrcoef(wi, wr)[0, 1])
