"""IMU preintegration and ground-truth labels (both computed in Rust)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Optional, Protocol
from typing import Sequence as Seq

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.errors import InvalidInputError

PAPER_FRACTIONS = (0.2, 0.4, 0.6, 0.8, 1.0)


class ImuArrays(Protocol):
    """What the core reads of IMU samples (:class:`imu_learn.data.types.ImuData` has them; the core
    sits below data and takes anything that does). Read-only members, so a frozen dataclass matches."""

    @property
    def t_ns(self) -> np.ndarray: ...

    @property
    def gyro(self) -> np.ndarray: ...

    @property
    def acc(self) -> np.ndarray: ...


class SegmentArrays(ImuArrays, Protocol):
    """What the core reads of a segment: IMU samples and ground truth on the same stamps
    (:class:`imu_learn.data.types.Segment` has them)."""

    @property
    def p(self) -> np.ndarray: ...

    @property
    def v(self) -> np.ndarray: ...

    @property
    def q_wxyz(self) -> np.ndarray: ...


@dataclass(frozen=True)
class Increments:
    """Rotation, velocity and position increments; ``dq_wxyz`` (..., 4), ``dv``/``dp`` (..., 3), ``dt`` (...) [s]."""

    dq_wxyz: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    dt: np.ndarray


@dataclass(frozen=True)
class WindowLabels(Increments):
    """Per-window increments, shape (windows, horizons, ...); ``starts`` (windows,), ``horizons`` (horizons,)."""

    starts: np.ndarray = None  # type: ignore[assignment]
    horizons: np.ndarray = None  # type: ignore[assignment]


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def preintegrate(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> Increments:
    """Cumulative Δq, Δβ, Δγ; row j covers [t_0, t_j] (row 0 is the identity).

    Sample i is held over [t_i, t_{i+1}) with the exact SO(3) exponential: the scheme of GTSAM's
    ``PreintegratedImuMeasurementsManifold`` with zero bias.
    """
    dq, dv, dp, dt = core.preintegrate(np.ascontiguousarray(t_ns, dtype=np.int64), _f64(gyro), _f64(acc))
    return Increments(dq, dv, dp, dt)


def window_labels(
    seq: SegmentArrays, window: int, stride: int = 1, fractions: Seq[float] = PAPER_FRACTIONS, gravity: float = 9.81
) -> WindowLabels:
    """Ground-truth Δq/Δβ/Δγ for every window (start step ``stride``) at ``fractions`` of ``window``."""
    for name, value in (("window", window), ("stride", stride)):
        if int(value) < 1:
            raise InvalidInputError(f"{name} must be at least 1 sample")  # the core's words for a window
    d = core.window_labels(
        np.ascontiguousarray(seq.t_ns, dtype=np.int64), _f64(seq.p), _f64(seq.v), _f64(seq.q_wxyz),
        int(window), int(stride), [float(f) for f in fractions], float(gravity),
    )
    return WindowLabels(**d)


def _indices(x: np.ndarray, name: str) -> np.ndarray:
    """Sample indices as a 1-d int64 or uint64 array, signedness kept: a negative index reaches the
    core as itself (and is rejected there, naming ``name``) instead of wrapping to 2^64 - 1."""
    a = np.asarray(x)
    if a.size == 0:
        return np.zeros(0, dtype=np.uint64)
    if a.ndim != 1 or not np.issubdtype(a.dtype, np.integer):
        raise InvalidInputError(f"{name} must be a 1-d sequence of integers, got {a.dtype} {a.shape}")
    return np.ascontiguousarray(a, dtype=np.uint64 if np.issubdtype(a.dtype, np.unsignedinteger) else np.int64)


def offset_rotation_angles(t_ns: np.ndarray, gyro: np.ndarray, labels: WindowLabels, tau: float,
                           period_ns: float) -> np.ndarray:
    """Rotation residual angles [rad] of ``labels``' windows (every window and horizon, flattened) with
    the gyro linearly interpolated at t + ``tau`` · ``period_ns`` (ends held) and integrated as
    :func:`integrate_windows` integrates: the timing floor's search cost in one core call
    (``timing.resample``, :func:`integrate_windows` and ``quat.rotation_angle`` in numpy are its oracle)."""
    return core.offset_rotation_angles(
        np.ascontiguousarray(t_ns, dtype=np.int64), _f64(gyro), _indices(labels.starts, "starts"),
        _indices(labels.horizons, "horizons"), _f64(np.reshape(labels.dq_wxyz, (-1, 4))), float(tau), float(period_ns),
    )


def rotation_window_sums(gyro: np.ndarray, acc_g: np.ndarray, dt: np.ndarray, theta: np.ndarray,
                         horizons: Seq[int], jacobian: bool) -> Dict[str, Optional[np.ndarray]]:
    """The floor's gyro model on B windows of W samples (the core's ``rotation_window_sums``): rates
    ω = M_g g − G a − M_g b_g at θ (21,) = (M_g − I, b_g, G) row-major, their products Q_k = Q_{k−1} ⊗
    Exp(ω_k dt_k); returns ``q_wxyz`` (B, H, 4), Q after the first h samples for h in ``horizons``,
    and with ``jacobian`` ``sums`` (B, H, 9, 7): Σ_{k<h} A_k ⊗ (g_k, a_k, 1) with A_k = R(Q_k) J_r(ω_k
    dt_k) dt_k (row-major 3×3), what the rotation residuals' exact Jacobian is built from (else None).
    gyro, acc_g (B, W, 3), dt (B, W) [s]."""
    return core.rotation_window_sums(_f64(gyro), _f64(acc_g), _f64(dt), _f64(theta),
                                     _indices(horizons, "horizons"), bool(jacobian))


def velocity_window_sums(rates: np.ndarray, acc: np.ndarray, dt: np.ndarray, horizons: Seq[int]) -> np.ndarray:
    """The sums the floor's accelerometer residuals are linear in (the core's ``velocity_window_sums``):
    (B, H, 9, 8), entry [b, h, 3r + i, F] = Σ_{k<h} R_k[r, i] dt_k c_k[F] with R_k the rotation held over
    sample k (R_0 = I, R_{k+1} = R_k Exp(ω_k dt_k) from ``rates``) and c_k = (a_k, 1, s_k a_k, s_k),
    s_k = t_{k+1} − ½ dt_k from the window's start. rates, acc (B, W, 3), dt (B, W) [s]."""
    return core.velocity_window_sums(_f64(rates), _f64(acc), _f64(dt), _indices(horizons, "horizons"))


def integrate_windows(seq: SegmentArrays, starts: np.ndarray, horizons: np.ndarray) -> WindowLabels:
    """IMU-side Δq/Δβ/Δγ for the given windows and horizons (same layout as :func:`window_labels`).

    Horizons must lie in 1..N-1 and each start leave room for the longest (N samples in ``seq``);
    no starts give an empty result. Anything else raises :class:`imu_learn.errors.InvalidInputError`
    naming the argument (``starts[i]`` / ``horizons[i]``), checked before anything is allocated.
    """
    d = core.integrate_windows(
        np.ascontiguousarray(seq.t_ns, dtype=np.int64), _f64(seq.gyro), _f64(seq.acc),
        _indices(starts, "starts"), _indices(horizons, "horizons"),
    )
    return WindowLabels(**d)
