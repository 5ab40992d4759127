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


# -- a bias that moves ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class MovingSettings:
    """:func:`moving_gravity_bias`: the bias piecewise linear between knots ``knot_s`` apart, its
    change between neighbouring knots a random walk of ``random_walk`` [rad/s/sqrt(s)] (a profile's
    ``gyroscope_random_walk``, floored at ``random_walk_floor``); ``gravity``: the window means as
    :class:`GravitySettings` (its ``prior_sigma`` on every knot); a still stretch enters as an
    absolute measurement of every axis at its mid time with its white-noise standard error and
    ``rest_sigma`` [rad/s] per axis added (the bias at rest is not the bias while moving).
    ``prior_std`` optionally a prior on the knots' average."""

    knot_s: float = 30.0
    random_walk: float = 3.4e-4  # rad/s/sqrt(s) (EuRoC's ADIS16448 profile's, an upper bound)
    random_walk_floor: float = 2e-5
    rest_sigma: Tuple[float, float, float] = (0.003, 0.003, 0.003)
    # the window means' spread 0.15 m/s^2 (chosen on EuRoC's training flights by the time average's RMS
    # error against their moving bias, among 0.5 and 0.15: docs/experiments/bias_prior.md)
    gravity: GravitySettings = GravitySettings(window_sigma=0.15)
    # per axis [rad/s], a prior on the knots' average (the device's moving-bias spread measured on its
    # training recordings, a profile's bias_prior); None: none (``gravity.prior_sigma`` on each knot only)
    prior_std: Optional[Tuple[float, float, float]] = None


@dataclass
class MovingBias:
    """A bias that moves (module doc of :func:`moving_gravity_bias`): ``knots_t_ns`` (J,), ``knots``
    (J, 3) [rad/s] and their covariance ``cov`` (3J, 3J) (knot-major); :meth:`at` the per-sample bias
    and its standard deviation; ``mean`` / ``mean_cov`` the time average over the recording."""

    knots_t_ns: np.ndarray
    knots: np.ndarray
    cov: np.ndarray
    mean: np.ndarray
    mean_cov: np.ndarray
    stills: int
    chunks: int
    windows: int
    settings: MovingSettings

    def weights(self, t_ns: np.ndarray) -> np.ndarray:
        return hat_weights(np.asarray(t_ns, dtype=np.int64), self.knots_t_ns)

    def at(self, t_ns: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """((N, 3) bias [rad/s], (N, 3) its standard deviation) at ``t_ns``."""
        W = self.weights(t_ns)  # (N, J)
        b = W @ self.knots
        J = len(self.knots)
        C = self.cov.reshape(J, 3, J, 3)
        var = np.stack([np.einsum("nj,jk,nk->n", W, C[:, a, :, a], W) for a in range(3)], -1)
        return b, np.sqrt(np.maximum(var, 0.0))

    def to_dict(self) -> Dict[str, object]:
        s = self.settings
        return {"gyro_bias_rad_s": [float(v) for v in self.mean],
                "gyro_bias_deg_s": [float(v) for v in np.rad2deg(self.mean)],
                "mean_std_rad_s": [float(v) for v in np.sqrt(np.diag(self.mean_cov))],
                "knots_t_s": [round(float(v - self.knots_t_ns[0]) * 1e-9, 3) for v in self.knots_t_ns],
                "knots_rad_s": [[float(v) for v in k] for k in self.knots],
                "knots_std_rad_s": [[float(v) for v in np.sqrt(np.diag(self.cov).reshape(-1, 3)[j])]
                                    for j in range(len(self.knots))],
                "stills": self.stills, "chunks": self.chunks, "windows": self.windows,
                "observable": "gravity consistency across gravity over time, every still stretch on every axis at "
                              "its time; the axis along gravity between stills follows the random walk",
                "settings": {"knot_s": s.knot_s, "random_walk_rad_s_sqrt_s": s.random_walk,
                             "rest_sigma_rad_s": list(s.rest_sigma), "window_s": s.gravity.window_s,
                             "chunk_s": s.gravity.chunk_s, "window_sigma_m_s2": s.gravity.window_sigma,
                             "prior_sigma_rad_s": s.gravity.prior_sigma}}


def hat_weights(t_ns: np.ndarray, knots_t_ns: np.ndarray) -> np.ndarray:
    """(N, J) piecewise-linear interpolation weights of the knots (constant beyond the ends)."""
    k = np.asarray(knots_t_ns, dtype=np.float64)
    t = np.clip(np.asarray(t_ns, dtype=np.float64), k[0], k[-1])
    W = np.zeros((len(t), len(k)))
    if len(k) == 1:
        W[:, 0] = 1.0
        return W
    j = np.clip(np.searchsorted(k, t, side="right") - 1, 0, len(k) - 2)
    f = (t - k[j]) / (k[j + 1] - k[j])
    W[np.arange(len(t)), j] = 1.0 - f
    W[np.arange(len(t)), j + 1] = f
    return W


def _rotations(t: np.ndarray, gyro: np.ndarray) -> np.ndarray:
    """(N, 3, 3) R_m of each sample (the chunk's integrated frame, from its first sample)."""
    q = preintegrate(t, gyro, np.zeros_like(gyro)).dq_wxyz
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def _moving_rows(t: np.ndarray, gyro: np.ndarray, acc: np.ndarray, W: np.ndarray,
                 window_s: float) -> Tuple[np.ndarray, np.ndarray]:
    """(window means of the specific force (K, 3), d m_k / d knot j's bias before [G]x: (K, J, 3, 3))
    over one chunk; W (N, J) the knots' weights (only the knots the chunk touches)."""
    edges = np.searchsorted(t, t[0] + (np.arange(int((t[-1] - t[0]) * 1e-9 / window_s + 1e-9) + 1) * window_s * 1e9)
                            .astype(np.int64))
    edges = edges[edges < len(t)]
    if len(edges) < 2:
        return np.zeros((0, 3)), np.zeros((0, W.shape[1], 3, 3))
    inc = preintegrate(t, gyro, acc)
    T = inc.dt[edges[1:]] - inc.dt[edges[:-1]]
    m = (inc.dv[edges[1:]] - inc.dv[edges[:-1]]) / T[:, None]
    R = _rotations(t, gyro)
    dt = np.r_[np.diff(t) * 1e-9, 0.0]
    out = np.zeros((len(T), W.shape[1], 3, 3))
    for j in range(W.shape[1]):
        wj = W[:, j] * dt
        if not np.any(wj):
            continue
        C = np.concatenate([np.zeros((1, 3, 3)), np.cumsum(R * wj[:, None, None], 0)[:-1]])  # int_0^t R h_j
        P = np.concatenate([np.zeros((1, 3, 3)), np.cumsum(C * dt[:, None, None], 0)[:-1]])
        out[:, j] = (P[edges[1:]] - P[edges[:-1]]) / T[:, None, None]
    return m, out


def moving_prior_information(J: int, span_s: float, s: MovingSettings) -> np.ndarray:
    """(3J, 3J) the information of the priors alone over J knots spread over ``span_s``: each knot's
    (``prior_std``, else ``gravity.prior_sigma``) and the random walk between neighbours."""
    q = max(float(s.random_walk), float(s.random_walk_floor))
    D = np.kron(np.eye(J - 1, J, 1) - np.eye(J - 1, J), np.eye(3))
    H = np.eye(3 * J) / s.gravity.prior_sigma ** 2 + D.T @ D / (q * q * span_s / (J - 1))
    if s.prior_std is not None:  # on the knots' average (the recording's level), not on each knot
        M = np.kron(np.full((1, J), 1.0 / J), np.eye(3))
        H = H + M.T @ np.diag(1.0 / np.asarray(s.prior_std, dtype=np.float64) ** 2) @ M
    return H


def moving_gravity_bias(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
                        stills: List[Tuple[int, np.ndarray, np.ndarray]] = (),
                        settings: MovingSettings = MovingSettings()) -> Optional[MovingBias]:
    """A bias that moves, without ground truth: gravity consistency (:func:`gravity_bias`'s window
    means, each chunk its own gravity) with the bias piecewise linear in time (knots ``knot_s``
    apart, an increment on the input's), a random walk between neighbouring knots and ``stills``
    (each (mid time [ns], mean gyro (3,), its standard error (3,))) as absolute measurements of every
    axis. Gauss-Newton (the gyro re-integrated with the per-sample estimate). None: neither a chunk of
    ``min_windows`` windows nor a still stretch."""
    s, gs = settings, settings.gravity
    t = np.asarray(t_ns, dtype=np.int64)
    gyro, acc = np.asarray(gyro, dtype=np.float64), np.asarray(acc, dtype=np.float64)
    if len(t) < 4:
        return None
    parts = [(a, b) for a, b in chunks(t, gs) if (t[b - 1] - t[a]) * 1e-9 >= gs.min_windows * gs.window_s]
    if not parts and not stills:
        return None
    span = (t[-1] - t[0]) * 1e-9
    J = max(2, int(round(span / s.knot_s)) + 1)
    kt = np.linspace(float(t[0]), float(t[-1]), J).astype(np.int64)
    H0, r0 = moving_prior_information(J, span, s), np.zeros(3 * J)
    for tm, mean, se in stills:
        w = hat_weights(np.array([tm]), kt)[0]
        Hm = np.kron(w[:, None], np.eye(3))  # (3J, 3)
        var = np.asarray(se, dtype=np.float64) ** 2 + np.asarray(s.rest_sigma, dtype=np.float64) ** 2
        H0 += Hm @ np.diag(1.0 / var) @ Hm.T
        r0 += Hm @ (np.asarray(mean, dtype=np.float64) / var)
    Wall = hat_weights(t, kt)
    x = np.linalg.solve(H0, r0)  # the stills and the priors alone
    windows = 0
    for _ in range(max(1, gs.iters) + 1):
        b_t = Wall @ x.reshape(J, 3)
        H, r = H0.copy(), r0.copy()
        windows = 0
        for a, c in parts:
            touch = np.flatnonzero(np.any(Wall[a:c] > 0, axis=0))
            m, A = _moving_rows(t[a:c], gyro[a:c] - b_t[a:c], acc[a:c], Wall[a:c][:, touch], gs.window_s)
            if len(m) < 2:
                continue
            windows += len(m)
            G = m.mean(0)
            Jm = -np.einsum("il,kjlc->kijc", _skew(G), A).reshape(len(m), 3, -1)  # (K, 3, 3*len(touch))
            Jc, mc = Jm - Jm.mean(0), m - m.mean(0)
            cols = (3 * touch[:, None] + np.arange(3)).ravel()
            w = 1.0 / gs.window_sigma ** 2
            xl = x[cols]
            # the model is linear in the increment about the bias already subtracted: m = G - J (x - x_used)
            H[np.ix_(cols, cols)] += w * np.einsum("kia,kib->ab", Jc, Jc)
            r[cols] += w * (np.einsum("kia,ki->a", Jc, mc) + np.einsum("kia,kib,b->a", Jc, Jc, xl))
        x_new = np.linalg.solve(H, r)
        done = np.max(np.abs(x_new - x)) < 1e-7
        x = x_new
        if done:
            break
    cov = np.linalg.inv(H)
    knots = x.reshape(J, 3)
    M = np.kron(Wall.mean(0)[None, :], np.eye(3))  # (3, 3J): the time average
    return MovingBias(kt, knots, cov, M @ x, M @ cov @ M.T, len(stills), len(parts), windows, s)
