"""A fair, fully vectorised numpy reference for the core's preintegration, labels and batches.

No per-sample Python loop anywhere: rotations are accumulated by a Hillis–Steele (doubling)
prefix scan over quaternion products, O(log N) vectorised steps; velocities and positions are
exclusive prefix sums; labels and batches are fancy indexing over all windows at once.

Conventions as in the core: quaternions Hamilton w,x,y,z, body -> world; world z up,
g = [0, 0, -gravity]. Sample i is held over [t_i, t_{i+1}); row j of a preintegration covers
[t_0, t_j] (row 0 the identity), per sample

    dp += dv*dt + 1/2*R*a*dt^2;   dv += R*a*dt;   R <- R*Exp(w*dt)

which is GTSAM's ``PreintegratedImuMeasurementsManifold`` with zero bias.

The oracle of the Rust core: tests/test_numpy_reference.py checks it against GTSAM and a plain
loop, bench/bench_core.py times the core against it. numpy only: it imports nothing else from
imu_learn, so it shares no code (and no mistake) with what it checks.
"""
from __future__ import annotations

from typing import Dict, Optional, Sequence, Tuple

import numpy as np

PAPER_FRACTIONS = (0.2, 0.4, 0.6, 0.8, 1.0)


# --------------------------------------------------------------------------------------------
# SO(3) with quaternions (w, x, y, z), vectorised over leading axes
# --------------------------------------------------------------------------------------------


def so3_exp(phi: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) -> unit quaternions (..., 4) wxyz (exact, Taylor near zero)."""
    phi = np.asarray(phi, dtype=np.float64)
    th2 = np.einsum("...i,...i->...", phi, phi)
    th = np.sqrt(th2)
    small = th < 1e-4
    safe = np.where(small, 1.0, th)
    # sin(th/2)/th; Taylor to th^4 below 1e-4 rad (error < 1e-20).
    k = np.where(small, 0.5 - th2 / 48.0 + th2 * th2 / 3840.0, np.sin(0.5 * safe) / safe)
    out = np.empty(phi.shape[:-1] + (4,))
    out[..., 0] = np.cos(0.5 * th)
    out[..., 1:] = phi * k[..., None]
    return out


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a*b of (..., 4) wxyz quaternions (broadcasting)."""
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = aw * bw - ax * bx - ay * by - az * bz
    out[..., 1] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 2] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 3] = aw * bz + ax * by - ay * bx + az * bw
    return out


def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion)."""
    out = np.array(q, dtype=np.float64, copy=True)
    out[..., 1:] *= -1.0
    return out


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q) v for unit quaternions q (..., 4) and vectors v (..., 3), broadcasting.

    v' = v + 2w (u x v) + 2 u x (u x v), u the vector part.
    """
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) wxyz -> (..., 3, 3) rotation matrices."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def quat_prefix_scan(q: np.ndarray, method: str = "doubling", block: int = 16) -> np.ndarray:
    """Inclusive prefix products along axis -2: out[..., i, :] = q_0 q_1 ... q_i.

    ``"doubling"``: Hillis–Steele scan, ceil(log2 N) vectorised steps, each multiplying every
    element by the partial product ending d places before it (earlier factors on the left);
    O(N log N) work.
    ``"blocked"``: work-efficient two-level scan: the N factors as (N/block, block); a loop over
    the ``block`` positions (vectorised across all blocks) scans within blocks, a doubling scan
    runs over the block totals, and one product applies each block's prefix. O(N) work; the
    Python loop has ``block`` iterations whatever N is.
    """
    if method == "doubling":
        out = np.array(q, dtype=np.float64, copy=True)
        n = out.shape[-2]
        d = 1
        while d < n:
            out[..., d:, :] = quat_mul(out[..., :-d, :], out[..., d:, :])
            d *= 2
        return out
    if method != "blocked":
        raise ValueError(f"unknown scan method {method!r}")
    q = np.asarray(q, dtype=np.float64)
    lead, n = q.shape[:-2], q.shape[-2]
    m = -(-n // block)
    pad = np.zeros(lead + (m * block, 4))
    pad[..., 0] = 1.0
    pad[..., :n, :] = q
    x = pad.reshape(lead + (m, block, 4))
    for i in range(1, block):
        x[..., i, :] = quat_mul(x[..., i - 1, :], x[..., i, :])
    if m > 1:
        totals = quat_prefix_scan(x[..., :, -1, :], "doubling")  # (..., m, 4)
        x[..., 1:, :, :] = quat_mul(totals[..., :-1, None, :], x[..., 1:, :, :])
    return pad[..., :n, :]


# --------------------------------------------------------------------------------------------
# Preintegration
# --------------------------------------------------------------------------------------------


def _exclusive_cumsum(x: np.ndarray, axis: int = -2) -> np.ndarray:
    """Prefix sums with a leading zero row: out has one more entry than x along ``axis``."""
    x = np.moveaxis(x, axis, 0)
    out = np.zeros((x.shape[0] + 1,) + x.shape[1:])
    np.cumsum(x, axis=0, out=out[1:])
    return np.moveaxis(out, 0, axis)


def preintegrate_dt(
    hold: np.ndarray, gyro: np.ndarray, acc: np.ndarray, scan: str = "doubling"
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Samples (..., n, 3) held ``hold`` (..., n) seconds -> rows (..., n+1, ...) (dq, dv, dp).

    Row j covers samples 0..j-1; row 0 is the identity. Batched over leading axes. ``scan``: the
    rotation prefix scan, see :func:`quat_prefix_scan`.
    """
    hold = np.asarray(hold, dtype=np.float64)
    dts = hold[..., None]
    steps = so3_exp(np.asarray(gyro, dtype=np.float64) * dts)
    lead = steps.shape[:-2]
    dq = np.empty(lead + (steps.shape[-2] + 1, 4))
    dq[..., 0, :] = (1.0, 0.0, 0.0, 0.0)
    dq[..., 1:, :] = quat_prefix_scan(steps, scan)
    a_nav = quat_rotate(dq[..., :-1, :], np.asarray(acc, dtype=np.float64))  # R_i a_i
    dv = _exclusive_cumsum(a_nav * dts)
    dp = _exclusive_cumsum(dv[..., :-1, :] * dts + a_nav * (0.5 * dts * dts))
    return dq, dv, dp


def preintegrate(
    t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, scan: str = "doubling"
) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cumulative (dq_wxyz, dv, dp, dt) on stamps t_ns; row j covers [t_0, t_j] with samples 0..j-1.

    Same semantics as ``imu_learn.preintegrate``: N stamps give N rows; the last sample enters no
    row; row dt is taken from the integer stamps. ``scan``: "doubling" (Hillis–Steele) or
    "blocked" (work-efficient two-level), see :func:`quat_prefix_scan`.
    """
    t_ns = np.asarray(t_ns, dtype=np.int64)
    n = len(t_ns)
    if n == 0:
        return np.zeros((0, 4)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    hold = np.diff(t_ns).astype(np.float64) * 1e-9
    dq, dv, dp = preintegrate_dt(hold, np.asarray(gyro)[: n - 1], np.asarray(acc)[: n - 1], scan)
    dt = (t_ns - t_ns[0]).astype(np.float64) * 1e-9
    return dq, dv, dp, dt


def preintegrate_loop(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray):
    """The same scheme as a plain sequential loop (the definition the scan is tested against)."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    n = len(t_ns)
    dq = np.zeros((n, 4))
    dv = np.zeros((n, 3))
    dp = np.zeros((n, 3))
    q = np.array([1.0, 0.0, 0.0, 0.0])
    v = np.zeros(3)
    p = np.zeros(3)
    if n:
        dq[0] = q
    for i in range(n - 1):
        h = (t_ns[i + 1] - t_ns[i]) * 1e-9
        a = quat_rotate(q, acc[i])
        p = p + v * h + a * (0.5 * h * h)
        v = v + a * h
        q = quat_mul(q, so3_exp(gyro[i] * h))
        dq[i + 1], dv[i + 1], dp[i + 1] = q, v, p
    return dq, dv, dp, (t_ns - (t_ns[0] if n else 0)) * 1e-9


# --------------------------------------------------------------------------------------------
# Ground-truth labels
# --------------------------------------------------------------------------------------------


def horizons(window: int, fractions: Sequence[float]) -> np.ndarray:
    """round(f * window) clamped to [1, window]; rounds half away from zero like Rust's f64::round."""
    f = np.asarray(fractions, dtype=np.float64)
    if window < 1 or f.size == 0 or np.any(~((f > 0) & (f <= 1))):
        raise ValueError(f"bad window {window} or fractions {fractions}")
    return np.clip(np.floor(f * window + 0.5), 1, window).astype(np.int64)


def labels_at(
    t_ns: np.ndarray, p: np.ndarray, v: np.ndarray, q_wxyz: np.ndarray,
    starts: np.ndarray, hs: np.ndarray, gravity: float,
) -> Dict[str, np.ndarray]:
    """Increments from state k to k+n for every start k (W,) and horizon n (H,) -> (W, H, ...)."""
    k = np.asarray(starts, dtype=np.int64)
    j = k[:, None] + np.asarray(hs, dtype=np.int64)[None, :]
    dt = (t_ns[j] - t_ns[k][:, None]).astype(np.float64) * 1e-9  # (W, H)
    qk_inv = quat_conj(q_wxyz[k])[:, None, :]  # (W, 1, 4)
    vk = v[k][:, None, :]
    g = np.array([0.0, 0.0, -gravity])
    dtc = dt[..., None]
    dv = quat_rotate(qk_inv, v[j] - vk - g * dtc)
    dp = quat_rotate(qk_inv, p[j] - p[k][:, None, :] - vk * dtc - g * (0.5 * dtc * dtc))
    return {"dq_wxyz": quat_mul(qk_inv, q_wxyz[j]), "dv": dv, "dp": dp, "dt": dt}


def window_labels(
    t_ns: np.ndarray, p: np.ndarray, v: np.ndarray, q_wxyz: np.ndarray,
    window: int, stride: int = 1, fractions: Sequence[float] = PAPER_FRACTIONS, gravity: float = 9.81,
) -> Dict[str, np.ndarray]:
    """Same dict as the core's window_labels: starts (W,), horizons (H,), dq_wxyz (W,H,4), dv, dp, dt."""
    if stride < 1:
        raise ValueError("stride must be at least 1")
    hs = horizons(window, fractions)
    n = len(t_ns)
    starts = np.arange(0, n - window, stride, dtype=np.int64) if n > window else np.zeros(0, np.int64)
    d = labels_at(np.asarray(t_ns, np.int64), p, v, q_wxyz, starts, hs, gravity)
    d["starts"] = starts.astype(np.uint64)
    d["horizons"] = hs.astype(np.uint64)
    return d


# --------------------------------------------------------------------------------------------
# Augmented batches
# --------------------------------------------------------------------------------------------


class SequenceSet:
    """Sequences concatenated once (like the core's SequenceSet) so a batch is pure gathers.

    ``seqs``: objects with t_ns, gyro, acc, p, v, q_wxyz (``imu_learn.Segment``) or tuples in
    that order.
    """

    def __init__(self, seqs) -> None:
        parts = [s if isinstance(s, tuple) else (s.t_ns, s.gyro, s.acc, s.p, s.v, s.q_wxyz) for s in seqs]
        if not parts:
            raise ValueError("no sequences")
        self.lens = np.array([len(x[0]) for x in parts], dtype=np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(self.lens)[:-1]]).astype(np.int64)
        self.t_ns = np.concatenate([np.asarray(x[0], np.int64) for x in parts])
        self.imu = np.concatenate([np.hstack([x[1], x[2]]) for x in parts]).astype(np.float64)
        self.p, self.v, self.q_wxyz = (np.concatenate([np.asarray(x[c], np.float64) for x in parts]) for c in (3, 4, 5))

    def __len__(self) -> int:
        return len(self.lens)

    def make_batch(
        self, window: int, batch_size: int, fractions: Sequence[float] = PAPER_FRACTIONS, gravity: float = 9.81,
        seed: int = 0, gyro_noise_density: float = 0.0, acc_noise_density: float = 0.0,
        gyro_bias_max: float = 0.0, acc_bias_max: float = 0.0, gyro_bias_walk: float = 0.0,
        acc_bias_walk: float = 0.0,
    ) -> Dict[str, np.ndarray]:
        """The core's make_batch, vectorised (its own random stream: numpy's PCG64)."""
        w, b = int(window), int(batch_size)
        hs = horizons(w, fractions)
        valid = np.maximum(self.lens - w, 0)
        cum = np.concatenate([[0], np.cumsum(valid)])
        total = int(cum[-1])
        if total == 0 or b < 1:
            raise ValueError("no window fits or batch_size < 1")
        rng = np.random.default_rng(seed)
        # Sequence chosen in proportion to its valid windows, then a uniform start within it.
        u = rng.integers(0, total, size=b)
        s = np.searchsorted(cum, u, side="right") - 1
        start = u - cum[s]
        g0 = self.offsets[s] + start  # global index of each window's first sample
        idx = g0[:, None] + np.arange(w + 1)[None, :]  # (B, W+1) states k..k+W
        t = self.t_ns[idx]
        dt = np.diff(t, axis=1).astype(np.float64) * 1e-9  # (B, W)
        imu = self.imu[idx[:, :w]]  # (B, W, 6), a fresh copy
        bmax = np.array([gyro_bias_max] * 3 + [acc_bias_max] * 3)
        dens = np.array([gyro_noise_density] * 3 + [acc_noise_density] * 3)
        walk = np.array([gyro_bias_walk] * 3 + [acc_bias_walk] * 3)
        bias = np.broadcast_to(((2.0 * rng.random((b, 1, 6)) - 1.0) * bmax), (b, w, 6))
        sqrt_dt = np.sqrt(dt)[..., None]
        if np.any(walk > 0):
            steps = walk * sqrt_dt * rng.standard_normal((b, w, 6))
            bias = bias + _exclusive_cumsum(steps, axis=1)[:, :w]
        else:
            bias = np.ascontiguousarray(bias)
        imu += bias
        if np.any(dens > 0):
            imu += dens / sqrt_dt * rng.standard_normal((b, w, 6))
        lab = labels_at(self.t_ns, self.p, self.v, self.q_wxyz, g0, hs, gravity)
        return {
            "imu": imu, "dt": dt, "dq_wxyz": lab["dq_wxyz"], "dv": lab["dv"], "dp": lab["dp"],
            "label_dt": lab["dt"], "bias": bias, "seq_index": s.astype(np.uint32),
            "start": start.astype(np.uint64), "horizons": hs.astype(np.uint64),
        }


def make_batch(
    seqs, window: int, batch_size: int, fractions: Sequence[float] = PAPER_FRACTIONS, gravity: float = 9.81,
    seed: int = 0, gyro_noise_density: float = 0.0, acc_noise_density: float = 0.0,
    gyro_bias_max: float = 0.0, acc_bias_max: float = 0.0, gyro_bias_walk: float = 0.0, acc_bias_walk: float = 0.0,
    sequence_set: Optional[SequenceSet] = None,
) -> Dict[str, np.ndarray]:
    """One augmented batch (layout of the core's SequenceSet.make_batch). Pass ``sequence_set`` to
    reuse concatenated data across calls, as the core's BatchSampler holds its sequences once."""
    ss = sequence_set if sequence_set is not None else SequenceSet(seqs)
    return ss.make_batch(
        window, batch_size, fractions, gravity, seed, gyro_noise_density, acc_noise_density,
        gyro_bias_max, acc_bias_max, gyro_bias_walk, acc_bias_walk,
    )


# --------------------------------------------------------------------------------------------
# The calibration floor's window sums (the oracle of the core's rotsums.rs)
# --------------------------------------------------------------------------------------------


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) with [v]x u = v x u."""
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2)


def _horizon_rows(x: np.ndarray, horizons: Sequence[int]) -> np.ndarray:
    """Σ_{k<h} x[:, k] for every h: the inclusive cumulative sum along axis 1 at rows h − 1."""
    return np.cumsum(x, axis=1)[:, [int(h) - 1 for h in horizons]]


def rotation_window_sums(gyro: np.ndarray, acc_g: np.ndarray, dt: np.ndarray, theta: np.ndarray,
                         horizons: Sequence[int]) -> Tuple[np.ndarray, np.ndarray]:
    """(Q at the horizons (B, H, 4), S (B, H, 9, 7)) of the floor's gyro model θ = (M − I, b, G) on
    windows gyro, acc_g (B, W, 3), dt (B, W): ω = M (g − b) − G a, Q_k = Q_{k−1} Exp(ω_k dt_k), and
    S_h = Σ_{k<h} A_k ⊗ (g_k, a_k, 1) with A_k = R(Q_k) J_r(ω_k dt_k) dt_k (row-major), J_r = I − c1 [φ]x
    + c2 [φ]x², c1 = (1 − cos θ)/θ², c2 = (θ − sin θ)/θ³ in closed form (a series only below 1e-2 rad)."""
    M = np.eye(3) + theta[:9].reshape(3, 3)
    phi = ((gyro - theta[9:12]) @ M.T - acc_g @ theta[12:21].reshape(3, 3).T) * dt[..., None]
    Q = quat_prefix_scan(so3_exp(phi))
    th2 = np.einsum("...i,...i->...", phi, phi)
    th = np.sqrt(th2)
    c1 = 0.5 * np.sinc(th / (2.0 * np.pi)) ** 2  # 2 sin²(θ/2)/θ²
    safe = np.where(th < 1e-2, 1.0, th)
    c2 = np.where(th < 1e-2, 1 / 6 - th2 / 120 + th2 * th2 / 5040, (safe - np.sin(safe)) / safe**3)
    K = _skew(phi)
    Jr = np.eye(3) - c1[..., None, None] * K + c2[..., None, None] * (K @ K)
    A = (quat_to_matrix(Q) @ Jr) * dt[..., None, None]
    f = np.concatenate((gyro, acc_g, np.ones(dt.shape + (1,))), axis=-1)
    B, W = dt.shape
    S = _horizon_rows(A.reshape(B, W, 9, 1) * f[:, :, None, :], horizons)
    return Q[:, [int(h) - 1 for h in horizons]], S


def velocity_window_sums(rates: np.ndarray, acc: np.ndarray, dt: np.ndarray, horizons: Sequence[int]) -> np.ndarray:
    """S (B, H, 9, 8) = Σ_{k<h} R_k dt_k ⊗ (a_k, 1, s_k a_k, s_k) with R_k the rotation held over sample k
    (R_0 = I, R_{k+1} = R_k Exp(ω_k dt_k)), s_k = t_{k+1} − ½ dt_k from the window's start."""
    B, W = dt.shape
    Q = quat_prefix_scan(so3_exp(rates * dt[..., None]))
    held = np.concatenate((np.broadcast_to([1.0, 0.0, 0.0, 0.0], (B, 1, 4)), Q[:, :-1]), axis=1)
    Rm = quat_to_matrix(held) * dt[..., None, None]
    s = (np.cumsum(dt, axis=1) - 0.5 * dt)[..., None]
    c = np.concatenate((acc, np.ones_like(s), s * acc, s), axis=-1)
    return _horizon_rows(Rm.reshape(B, W, 9, 1) * c[:, :, None, :], horizons)


# --------------------------------------------------------------------------------------------
# Loading without the compiled module (bench --only-reference)
# --------------------------------------------------------------------------------------------


def read_asl_imu_numpy(path) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ASL IMU CSV (``#timestamp [ns],w..,a..`` header) -> (t_ns int64, gyro, acc)."""
    t = np.loadtxt(path, delimiter=",", comments="#", usecols=0, dtype=np.int64)
    x = np.loadtxt(path, delimiter=",", comments="#", usecols=range(1, 7), dtype=np.float64)
    return t, np.ascontiguousarray(x[:, :3]), np.ascontiguousarray(x[:, 3:])


def align_tum_numpy(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, tum_path) -> tuple:
    """Rough numpy stand-in for the core's alignment: TUM poses interpolated onto IMU stamps (lerp
    + normalise for q, central differences for v), IMU clipped to the ground-truth span. Gives
    plausible inputs for timing the reference; it is not the core's alignment.

    Returns one tuple (t_ns, gyro, acc, p, v, q_wxyz), the layout SequenceSet takes."""
    d = np.loadtxt(tum_path, comments="#")
    gt_t = np.round(d[:, 0] * 1e9).astype(np.int64)
    inside = (t_ns >= gt_t[0]) & (t_ns <= gt_t[-1])
    ts = t_ns[inside]
    x = (ts - gt_t[0]).astype(np.float64)
    xp = (gt_t - gt_t[0]).astype(np.float64)
    p = np.stack([np.interp(x, xp, d[:, 1 + c]) for c in range(3)], axis=1)
    qg = d[:, [7, 4, 5, 6]]  # TUM is x y z w
    sign = np.ones(len(qg))
    sign[1:] = np.cumprod(np.where(np.einsum("ij,ij->i", qg[1:], qg[:-1]) < 0, -1.0, 1.0))
    qg = qg * sign[:, None]  # one hemisphere, so lerp between neighbours is short-way
    q = np.stack([np.interp(x, xp, qg[:, c]) for c in range(4)], axis=1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    v = np.gradient(p, ts.astype(np.float64) * 1e-9, axis=0)
    return (ts, np.ascontiguousarray(gyro[inside]), np.ascontiguousarray(acc[inside]), p, v, q)
