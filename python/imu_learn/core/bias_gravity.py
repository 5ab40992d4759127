"""A recording's gyro bias from gravity consistency: the bias that keeps the long-term mean specific
force pointing one way in the gyro's integrated frame (numpy; no ground truth, no learning).

**The idea.** The accelerometer always measures the specific force f = R^T (a - g_vec), whatever
pushes the device (a hand, wheels, rotors' thrust and drag). Rotated into the frame the gyro
integrates (R_m, from the recording chunk's first sample), f averaged over a long window (``window_s``,
tens of seconds) is the upward gravity G plus the window's mean acceleration (its velocity change over
its length: small for a device that comes back to rest or moves at walking speed). A constant gyro bias
error b turns the integrated frame by phi(t) = int_0^t R_m(s) b ds = A(t) b, so the window means drift:
m_k = G + a_k - [G]x mean_k(A) b. Least squares over the windows of every chunk (``chunk_s``: the
integration restarts there, each chunk its own G) for (G_c, b), Gauss-Newton (the gyro re-integrated
with the estimate, ``iters`` times). ``imu_learn.core.integration.preintegrate`` gives both sums:
the window's velocity increment is int R_m f, and with a unit "accelerometer" along each axis the
position increment is int A.

**What is observable.** [G]x removes every rotation error about gravity: only the two world-frame
components perpendicular to gravity (roll and pitch rates) are seen. They map to body axes as the
device turns: a device that keeps one attitude leaves the body axis along gravity unobserved (yaw
about gravity), one that turns through several attitudes exposes all three. The weak directions are
held at zero by a prior (``prior_sigma`` rad/s: the estimate is an increment on what the input's bias
already is, e.g. after a profile's floor), and :class:`GravityBias` reports each direction's standard
deviation (the information's eigen-directions, in the body frame) so a reader sees what was
observed. The window means' spread around the model, ``window_sigma`` [m/s^2], weighs the data
against that prior.

**Where it does not hold.** On an input whose bias is far above the prior (the raw IMU of a
device with 0.08 rad/s, before its floor) the linearisation fails: use it after a profile's floor or
a model. A window whose mean acceleration is not small (a car accelerating for
tens of seconds, a lift) biases the estimate; the earth's rotation (7.3e-5 rad/s) is read as bias
(its horizontal part). The identity f = a - g holds on a quadrotor too (thrust and drag are what the
accelerometer measures), so the estimator is not excluded there by physics; what differs is that a
quadrotor's accelerometer points along its thrust axis at every instant, so the tilt cannot be read
from one window of body-frame samples: only the integrated-frame average carries gravity
(docs/refine.md measures it on EuRoC's flights).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from imu_learn.core.integration import preintegrate
from imu_learn.core.stamps import median_period_ns


@dataclass(frozen=True)
class GravitySettings:
    """Window means over ``window_s``, the integration restarted every ``chunk_s`` (at a gap in the
    stamps longer than ``max_gap_s`` too); chunks with fewer than ``min_windows`` windows are dropped;
    ``window_sigma`` [m/s^2] the window means' spread, ``prior_sigma`` [rad/s] the prior on the
    increment; ``iters`` Gauss-Newton steps; a direction with a standard deviation above
    ``observed_below`` [rad/s] is reported as not observed."""

    window_s: float = 10.0
    chunk_s: float = 120.0
    min_windows: int = 3
    window_sigma: float = 0.5  # m/s^2 (chosen on the training recordings: docs/refine.md)
    prior_sigma: float = 0.01  # rad/s
    iters: int = 3
    max_gap_s: float = 0.1
    observed_below: float = 0.005  # rad/s: half the prior's sigma (the data, not the prior, set it)


@dataclass
class GravityBias:
    """The estimate (module doc): ``gyro_bias`` [rad/s] (3,), the increment on the input's bias, None
    without a chunk of ``min_windows`` windows; ``directions`` (3, 3) body-frame eigen-directions
    (rows) of the information with ``direction_std`` [rad/s] each; ``gravity_body`` the mean
    accelerometer direction (body frame); ``residual_rms`` [m/s^2] the window means' misfit."""

    gyro_bias: Optional[np.ndarray]
    gyro_bias_std: Optional[np.ndarray]
    directions: Optional[np.ndarray]
    direction_std: Optional[np.ndarray]
    gravity_body: Optional[np.ndarray]
    residual_rms: Optional[float]
    chunks: int
    windows: int
    used_s: float
    settings: GravitySettings

    def to_dict(self) -> Dict[str, object]:
        """Plain values for a summary (rad/s, with deg/s beside the bias)."""
        def vec(x: Optional[np.ndarray]) -> Optional[List[float]]:
            return None if x is None else [float(v) for v in np.ravel(x)]

        s = self.settings
        observed = None if self.direction_std is None else [bool(v <= s.observed_below) for v in self.direction_std]
        return {
            "gyro_bias_rad_s": vec(self.gyro_bias),
            "gyro_bias_deg_s": vec(None if self.gyro_bias is None else np.rad2deg(self.gyro_bias)),
            "gyro_bias_std_rad_s": vec(self.gyro_bias_std),
            "directions_body": None if self.directions is None else [vec(d) for d in self.directions],
            "direction_std_rad_s": vec(self.direction_std),
            "direction_observed": observed,
            "gravity_direction_body": vec(self.gravity_body),
            "residual_rms_m_s2": self.residual_rms,
            "observable": "only rotation rates perpendicular to gravity (roll/pitch in the world frame); the "
                          "rate about gravity (yaw) is not; body axes as the device turns (direction_std)",
            "chunks": self.chunks, "windows": self.windows, "used_s": round(self.used_s, 3),
            "settings": {"window_s": s.window_s, "chunk_s": s.chunk_s, "min_windows": s.min_windows,
                         "window_sigma_m_s2": s.window_sigma, "prior_sigma_rad_s": s.prior_sigma,
                         "iters": s.iters, "observed_below_rad_s": s.observed_below},
        }


def chunks(t_ns: np.ndarray, s: GravitySettings) -> List[Tuple[int, int]]:
    """[i0, i1) ranges of at most ``chunk_s``, cut at gaps longer than ``max_gap_s``."""
    t = np.asarray(t_ns, dtype=np.int64)
    cuts = np.r_[0, np.flatnonzero(np.diff(t) > s.max_gap_s * 1e9) + 1, len(t)]
    out = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        while b - a > 1:
            e = int(np.searchsorted(t, t[a] + int(s.chunk_s * 1e9), side="right"))
            e = min(max(e, a + 2), b)
            out.append((int(a), e))
            a = e
    return out


def _skew(v: np.ndarray) -> np.ndarray:
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def chunk_rows(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
               window_s: float) -> Tuple[np.ndarray, np.ndarray]:
    """(window means of the specific force in the chunk's integrated frame (K, 3), the window means of
    A(t) = int R_m (K, 3, 3)) over consecutive windows of ``window_s`` from the chunk's start."""
    t = np.asarray(t_ns, dtype=np.int64)
    edges = np.searchsorted(t, t[0] + (np.arange(int((t[-1] - t[0]) * 1e-9 / window_s + 1e-9) + 1) * window_s * 1e9)
                            .astype(np.int64))
    edges = edges[edges < len(t)]
    if len(edges) < 2:
        return np.zeros((0, 3)), np.zeros((0, 3, 3))
    inc = preintegrate(t, gyro, acc)
    cols = [preintegrate(t, gyro, np.tile(np.eye(3)[i], (len(t), 1))).dp for i in range(3)]
    P = np.stack(cols, -1)  # (N, 3, 3): int_0^t A(s) ds, column i for the unit axis i
    T = inc.dt[edges[1:]] - inc.dt[edges[:-1]]
    m = (inc.dv[edges[1:]] - inc.dv[edges[:-1]]) / T[:, None]
    A = (P[edges[1:]] - P[edges[:-1]]) / T[:, None, None]
    return m, A


def _solve(rows: List[Tuple[np.ndarray, np.ndarray]], prior_at: np.ndarray,
           s: GravitySettings) -> Tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """One Gauss-Newton step over every chunk's (m, A): (the bias step, the b-block's data
    information with the chunks' gravities marginalised, the posterior covariance, the misfit RMS)."""
    H_b = np.zeros((3, 3))
    r_b = np.zeros(3)
    for m, A in rows:
        G = m.mean(0)
        J = -np.einsum("ij,kjl->kil", _skew(G), A)  # (K, 3, 3): d m_k / d b
        # G_c marginalised: centre the rows and the data within the chunk
        Jc, mc = J - J.mean(0), m - m.mean(0)
        H_b += np.einsum("kij,kil->jl", Jc, Jc)
        r_b += np.einsum("kij,ki->j", Jc, mc)
    w = 1.0 / s.window_sigma ** 2
    H = w * H_b + np.eye(3) / s.prior_sigma ** 2
    step = np.linalg.solve(H, w * r_b - prior_at / s.prior_sigma ** 2)
    misfit = []
    for m, A in rows:
        G = m.mean(0)
        J = -np.einsum("ij,kjl->kil", _skew(G), A)
        Jc, mc = J - J.mean(0), m - m.mean(0)
        misfit.append(mc - Jc @ step)
    res = np.concatenate(misfit)
    return step, H_b, np.linalg.inv(H), float(np.sqrt(np.mean(res ** 2)))


def gravity_bias(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
                 settings: GravitySettings = GravitySettings()) -> GravityBias:
    """The constant gyro bias (an increment on the input's) that keeps gravity's direction consistent
    in the integrated frame (module doc)."""
    s = settings
    t = np.asarray(t_ns, dtype=np.int64)
    gyro, acc = np.asarray(gyro, dtype=np.float64), np.asarray(acc, dtype=np.float64)
    parts = []
    for a, b in chunks(t, s):
        if (t[b - 1] - t[a]) * 1e-9 >= s.min_windows * s.window_s:
            parts.append((a, b))
    if not parts or len(t) < 4:
        return GravityBias(None, None, None, None, None, None, 0, 0, 0.0, s)
    b_est = np.zeros(3)
    for _ in range(max(1, s.iters)):
        rows = [chunk_rows(t[a:c], gyro[a:c] - b_est, acc[a:c], s.window_s) for a, c in parts]
        step, H_b, cov, misfit = _solve(rows, b_est, s)
        b_est = b_est + step
    rows = [chunk_rows(t[a:c], gyro[a:c] - b_est, acc[a:c], s.window_s) for a, c in parts]
    _, H_b, cov, misfit = _solve(rows, b_est, s)
    lam, vec = np.linalg.eigh(H_b / s.window_sigma ** 2 + np.eye(3) / s.prior_sigma ** 2)
    g_body = acc.mean(0)
    period = median_period_ns(t) * 1e-9
    return GravityBias(
        gyro_bias=b_est, gyro_bias_std=np.sqrt(np.diag(cov)), directions=vec.T, direction_std=1.0 / np.sqrt(lam),
        gravity_body=g_body / max(np.linalg.norm(g_body), 1e-12), residual_rms=misfit, chunks=len(parts),
        windows=int(sum(len(r[0]) for r in rows)), used_s=sum((c - a) * period for a, c in parts), settings=s)
