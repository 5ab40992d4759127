"""Learned displacement factors (TLIO-style) in the fusion graph: the fusion input ``tlio-style``
is the raw IMU (``CombinedImuFactor`` between keyframes, as for ``raw``) plus one relative-position
factor per completed network window, from the ``tlio-style`` method of ``imu_learn.evaluate``
(:mod:`imu_learn.baselines.tlio`), fused with the scenario's aiding as every other input.

TLIO (Liu et al., RA-L 2020) fuses its network's displacements in a stochastic-cloning EKF; ours
is the factor graph of :mod:`imu_learn.fuse.graph` (iSAM2 causal, batch LM smoothed), so the measurement model is
the same but the estimator is not.

Factor (:func:`displacement_factor`, a ``gtsam.CustomFactor`` on the poses X(i), X(j) of the
keyframes at the window's ends)::

    e = (p_j - p_i) - d̂        world frame,  covariance  Σ = R_γ diag(σ̂²) R_γᵀ

with d̂ = R_γ d̂_local and σ̂² the network's displacement and diagonal variances in the local
gravity-aligned frame R_γ = R_z(yaw of the window's last sample). Jacobians (analytic; GTSAM's
Pose3 retract moves the position by R δp for a tangent δp): ∂e/∂ξ_i = [0, -R_i],
∂e/∂ξ_j = [0, R_j] (rotation part zero: the factor constrains positions only).

Bookkeeping (:class:`DisplacementFactors`, the graph's ``extra_factors`` hook, called at every
keyframe before its iSAM2 update):

- the network input is each window sample's raw IMU rotated by the graph's **causal** orientation
  estimate at that sample: the causal estimate at the keyframe before it (``causal_R``) propagated
  with the gyro minus the bias estimate the graph holds for that interval, which is the rotation
  part of the IMU prediction a live system has between keyframes; only samples before the current
  keyframe are read. (The network was trained on raw IMU with ground-truth orientation; in the
  evaluation it is given ground-truth orientation, here the graph's own estimate.)
- windows end on keyframes of the ``update_s`` grid (default every 1 s, so consecutive windows do
  not overlap and their errors, which the graph takes as independent, do not share IMU samples;
  TLIO itself updates at 20 Hz with overlapping windows, ``update_s = 0.2`` gives the nearest our
  10 Hz keyframes allow). A window ending at keyframe j starts at the keyframe nearest to
  t_j - window: its length is the samples between the two keyframes (W, or a sample off where
  stamps jitter: the network takes any length); a window more than ``tolerance`` samples off W, or
  reaching before the first sample, is skipped (counted).
- a factor is new information, so the graph updates iSAM2 at its keyframe (as at an aiding epoch).
"""
from __future__ import annotations

from typing import Callable, List, Tuple

import numpy as np

from ..aiding import epochs

# (world-frame IMU samples (L, 6), orientation of the last sample (3, 3)) -> (d̂ (3,), Σ (3, 3)), world frame
Regressor = Callable[[np.ndarray, np.ndarray], Tuple[np.ndarray, np.ndarray]]


def displacement_error(R_i: np.ndarray, p_i: np.ndarray, R_j: np.ndarray, p_j: np.ndarray,
                       d: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(e (3,), ∂e/∂ξ_i (3, 6), ∂e/∂ξ_j (3, 6)) of e = (p_j - p_i) - d, ξ = [δθ, δp] of GTSAM's Pose3."""
    e = np.asarray(p_j, dtype=np.float64) - np.asarray(p_i, dtype=np.float64) - np.asarray(d, dtype=np.float64)
    H_i = np.zeros((3, 6))
    H_j = np.zeros((3, 6))
    H_i[:, 3:] = -np.asarray(R_i)
    H_j[:, 3:] = np.asarray(R_j)
    return e, H_i, H_j


def displacement_factor(key_i: int, key_j: int, d: np.ndarray, cov: np.ndarray):
    """The relative-position factor between Pose3 keys ``key_i`` and ``key_j`` (module docstring)."""
    import gtsam

    d = np.asarray(d, dtype=np.float64).copy()
    model = gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, dtype=np.float64))

    def error(this, values, H):
        a, b = values.atPose3(this.keys()[0]), values.atPose3(this.keys()[1])
        e, H_i, H_j = displacement_error(a.rotation().matrix(), a.translation(), b.rotation().matrix(),
                                         b.translation(), d)
        if H is not None:
            H[0] = H_i
            H[1] = H_j
        return e

    return gtsam.CustomFactor(model, [int(key_i), int(key_j)], error)


def _exp_so3(phi: np.ndarray) -> np.ndarray:
    """Rodrigues, (M, 3) -> (M, 3, 3)."""
    th = np.linalg.norm(phi, axis=-1)[:, None, None]
    K = np.zeros((len(phi), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -phi[:, 2], phi[:, 1], -phi[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = phi[:, 2], -phi[:, 1], phi[:, 0]
    small = th < 1e-8
    a = np.where(small, 1.0, np.sin(th) / np.where(small, 1.0, th))
    b = np.where(small, 0.5, (1.0 - np.cos(th)) / np.where(small, 1.0, th * th))
    return np.eye(3)[None] + a * K + b * (K @ K)


class DisplacementFactors:
    """The ``extra_factors`` hook of :class:`~imu_learn.fuse.graph.IncrementalFusion`: call it with
    (fusion, keyframe number k, its sample s); it returns the displacement factors that end at k.

    ``regress``: (world-frame IMU window (L, 6), orientation of its last sample (3, 3)) -> (d̂, Σ) in
    the world frame (:meth:`imu_learn.baselines.tlio.TlioStyle.regress_window`); ``window``: the
    network's window W [samples]; ``gyro``, ``acc`` (N, 3): the IMU samples streamed into the graph
    (sample i is read only once the keyframe after it is reached)."""

    def __init__(self, regress: Regressor, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, window: int,
                 update_s: float = 1.0, tolerance: int = 2) -> None:
        self.regress = regress
        self.t_ns = np.asarray(t_ns, dtype=np.int64)
        self.gyro = np.asarray(gyro, dtype=np.float64)
        self.acc = np.asarray(acc, dtype=np.float64)
        self.window = int(window)
        self.tolerance = int(tolerance)
        N = len(self.t_ns)
        period_ns = float(np.median(np.diff(self.t_ns)))
        self.window_ns = self.window * period_ns
        self.ends = set(int(s) for s in epochs(self.t_ns, 1.0 / float(update_s)))
        self.R = np.full((N, 3, 3), np.nan)  # causal orientation of each sample, filled keyframe by keyframe
        self.world = np.full((N, 6), np.nan)  # raw IMU rotated by it
        self.count = 0
        self.skipped = 0
        self.windows: List[Tuple[int, int]] = []  # (start sample, end sample) of each factor

    def _propagate(self, fusion, k0: int) -> None:
        """Orientation of samples kf[k0] .. kf[k0+1]-1: keyframe k0's causal estimate, then the gyro
        minus the bias the graph predicted this interval with."""
        a, b = int(fusion.kf_idx[k0]), int(fusion.kf_idx[k0 + 1])
        R0 = np.asarray(fusion.causal_R[k0], dtype=np.float64)
        bg = fusion.bias[:3]  # the interval's bias estimate
        dt = np.diff(self.t_ns[a:b + 1]) * 1e-9
        inc = _exp_so3((self.gyro[a:b - 1] - bg) * dt[:b - 1 - a, None]) if b - a > 1 else np.zeros((0, 3, 3))
        R = self.R
        R[a] = R0
        for m in range(b - 1 - a):
            R[a + m + 1] = R[a + m] @ inc[m]
        self.world[a:b, :3] = np.einsum("nij,nj->ni", R[a:b], self.gyro[a:b])
        self.world[a:b, 3:] = np.einsum("nij,nj->ni", R[a:b], self.acc[a:b])

    def __call__(self, fusion, k: int, s: int) -> list:
        if k == 0:
            return []
        self._propagate(fusion, k - 1)
        if s not in self.ends:
            return []
        kf = np.asarray(fusion.kf_idx)
        t_start = self.t_ns[s] - self.window_ns
        i = int(np.argmin(np.abs(self.t_ns[kf[:k]] - t_start)))  # the start keyframe nearest t_j - window
        a = int(kf[i])
        if abs((s - a) - self.window) > self.tolerance or np.isnan(self.world[a:s]).any():
            self.skipped += 1
            return []
        d, cov = self.regress(self.world[a:s], self.R[s - 1])
        from gtsam.symbol_shorthand import X

        self.count += 1
        self.windows.append((a, s))
        return [displacement_factor(X(i), X(k), d, cov)]


def displacement_factors_for(model, seq_t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
                             update_s: float = 1.0) -> DisplacementFactors:
    """The hook for a fitted :class:`~imu_learn.baselines.tlio.TlioStyle` or
    :class:`~imu_learn.baselines.zero_displacement.ZeroDisplacement` ``model``."""
    return DisplacementFactors(model.regress_window, seq_t_ns, gyro, acc, model.window, update_s)
