"""The non-holonomic constraint in the batch solver: the NHC factor held at a linearisation point
(imu_learn.fuse.factors.held) against the Python factor, numerical derivatives and its closed form;
the held solve against Levenberg-Marquardt on the true graph; and a synthetic wheeled drive whose
outage drift the NHC still cuts."""
from __future__ import annotations

import math

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from gtsam.symbol_shorthand import V, X  # noqa: E402

from imu_learn.fuse import graph as graph_mod  # noqa: E402
from imu_learn.fuse.aiding import PositionFixes  # noqa: E402
from imu_learn.fuse.factors import held, nhc  # noqa: E402
from imu_learn.fuse.noise import ImuNoise  # noqa: E402
from imu_learn.fuse.settings import FusionSettings  # noqa: E402

SIGMAS = np.array([0.2, 0.5])


def random_state(rng):
    return gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(0, 1, 3)), rng.normal(0, 5, 3)), rng.normal(0, 8, 3)


def values_of(pose, v):
    vals = gtsam.Values()
    vals.insert(X(0), pose)
    vals.insert(V(0), v)
    return vals


def retracted(pose, v, d):
    """The state moved by ``d`` (9,) in GTSAM's tangent spaces (pose: rotation, translation; velocity)."""
    return pose.retract(d[:6]), v + d[6:]


def test_held_factor_is_the_nhc_factor_at_its_point_and_to_first_order_near_it():
    rng = np.random.default_rng(30)
    settings = nhc.NhcSettings(*SIGMAS, lever=(0.3, -0.1, 0.65))
    for _ in range(10):
        pose, v = random_state(rng)
        omega = rng.normal(0, 0.5, 3)
        f = nhc.nhc_factor(X(0), V(0), settings, omega=omega)
        at = values_of(pose, v)
        h = gtsam.LinearContainerFactor(f.linearize(at), at)
        # closed form: u = R^T v + omega x lever, rows y, z; Jacobians [R^T v]_x and R^T (rows y, z)
        R = pose.rotation().matrix()
        e = (R.T @ v + np.cross(omega, settings.lever))[1:]
        H = np.hstack([nhc.skew(R.T @ v)[1:], np.zeros((2, 3)), R.T[1:]])
        np.testing.assert_allclose(f.unwhitenedError(at), e, atol=1e-12)
        np.testing.assert_allclose(h.error(at), 0.5 * np.sum((e / SIGMAS) ** 2), rtol=1e-12)
        for lin in (f.linearize(at), h.linearize(at)):
            A, b = lin.jacobian()
            np.testing.assert_allclose(A, H / SIGMAS[:, None], atol=1e-9)
            np.testing.assert_allclose(b, -e / SIGMAS, atol=1e-9)
        # numerical derivatives of the Python factor through GTSAM's retraction
        num = np.zeros((2, 9))
        for i in range(9):
            d = np.zeros(9)
            d[i] = 1e-6
            num[:, i] = (f.unwhitenedError(values_of(*retracted(pose, v, d))) - e) / 1e-6
        np.testing.assert_allclose(num, H, atol=2e-4 * max(1.0, np.abs(H).max()))
        # away from its point the held factor is the first-order expansion: error within O(|d|^2)
        for scale in (1e-2, 1e-3):
            d = rng.normal(0, scale, 9)
            near = values_of(*retracted(pose, v, d))
            e_true = f.unwhitenedError(near)
            e_lin = e + H @ d
            assert np.linalg.norm(e_true - e_lin) < 10 * (np.linalg.norm(v) + 1) * scale ** 2
            np.testing.assert_allclose(h.error(near), 0.5 * np.sum((e_lin / SIGMAS) ** 2), rtol=1e-6)
            # and held again at the new point it is the factor there
            h2 = gtsam.LinearContainerFactor(f.linearize(near), near)
            np.testing.assert_allclose(h2.error(near), f.error(near), rtol=1e-12)


def chain_graph(rng, n: int = 30, dt: float = 0.1):
    """A wheeled chain: poses and world velocities, a loose prior on each, relative poses between
    them (BetweenFactorPose3 from a curving drive) and an NHC factor at each; a perturbed start."""
    g, truth, initial = gtsam.NonlinearFactorGraph(), gtsam.Values(), gtsam.Values()
    settings = nhc.NhcSettings(0.1, 0.1, lever=(-0.2, 0.0, 0.9))
    psi, p, prev = 0.3, np.zeros(3), None
    for k in range(n):
        rate = 0.3 * math.sin(0.2 * k)
        R = gtsam.Rot3.Ypr(psi, 0.02 * math.sin(0.3 * k), 0.01)
        pose = gtsam.Pose3(R, p)
        v = R.matrix() @ np.array([10.0, 0.0, 0.0]) - R.matrix() @ np.cross([0, 0, rate], settings.lever)
        truth.insert(X(k), pose)
        truth.insert(V(k), v)
        initial.insert(X(k), pose.retract(rng.normal(0, [0.05] * 3 + [0.5] * 3)))
        initial.insert(V(k), v + rng.normal(0, 0.5, 3))
        g.add(gtsam.PriorFactorPose3(X(k), pose, gtsam.noiseModel.Isotropic.Sigma(6, 1.0)))
        g.add(gtsam.PriorFactorVector(V(k), v, gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
        g.add(nhc.nhc_factor(X(k), V(k), settings, omega=np.array([0.0, 0.0, rate])))
        if k:
            g.add(gtsam.BetweenFactorPose3(X(k - 1), X(k), prev.between(pose), gtsam.noiseModel.Isotropic.Sigma(6, 0.01)))
        prev = pose
        psi += rate * dt
        p = p + v * dt
    return g, truth, initial


def test_held_solve_is_levenberg_marquardt_on_the_true_graph():
    rng = np.random.default_rng(7)
    g, _truth, initial = chain_graph(rng)
    params = graph_mod.lm_params()
    assert len(held.python_factor_slots(g)) == 30
    ref = gtsam.LevenbergMarquardtOptimizer(g, initial, params).optimize()
    got = held.optimize(g, initial, params)
    assert g.error(got) == pytest.approx(g.error(ref), rel=1e-6, abs=1e-9)
    for k in range(30):
        assert got.atPose3(X(k)).equals(ref.atPose3(X(k)), 1e-6)
        np.testing.assert_allclose(got.atVector(V(k)), ref.atVector(V(k)), atol=1e-6)
    # a graph without Python factors: LM itself, bit for bit
    native = gtsam.NonlinearFactorGraph()
    for i in range(g.size()):
        if i not in held.python_factor_slots(g):
            native.add(g.at(i))
    a = held.optimize(native, initial, params)
    b = gtsam.LevenbergMarquardtOptimizer(native, initial, params).optimize()
    assert a.atPose3(X(29)).equals(b.atPose3(X(29)), 0.0)


def test_held_solve_shortens_a_misleading_step_then_falls_back_to_the_true_graph(monkeypatch):
    rng = np.random.default_rng(8)
    g, _truth, initial = chain_graph(rng, n=10)
    params = graph_mod.lm_params()
    ref = gtsam.LevenbergMarquardtOptimizer(g, initial, params).optimize()
    # held factors that pull far the wrong way (offset by 1000 sigmas): LM on them raises the true error
    calls = []
    real = held.held_graph

    def misleading(graph, slots, values):
        calls.append(len(slots))
        out = gtsam.NonlinearFactorGraph()
        for i in range(graph.size()):
            f = graph.at(i)
            if i in slots:
                A, b = f.linearize(values).jacobian()
                keys = f.keys()
                lin = gtsam.JacobianFactor(keys[0], A[:, :6], keys[1], A[:, 6:], b + 1000.0, gtsam.noiseModel.Unit.Create(2))
                out.add(gtsam.LinearContainerFactor(lin, values))
            else:
                out.add(f)
        return out

    monkeypatch.setattr(held, "held_graph", misleading)
    # each misleading step shortened until the true error drops, relinearised there: it still descends
    got = held.optimize(g, initial, params)
    assert 1 < len(calls) <= params.getMaxIterations()
    assert g.error(got) < g.error(initial)
    # no shortened step lowering the true error: one held iteration, then LM on the true graph
    calls.clear()
    tried = []
    monkeypatch.setattr(held, "MAX_HALVINGS", 0)
    real_lm = held.levenberg_marquardt
    monkeypatch.setattr(held, "levenberg_marquardt", lambda gr, *a: tried.append(gr is g) or real_lm(gr, *a))
    got = held.optimize(g, initial, params)
    assert calls == [10] and tried == [True]  # (the held step is lm_iteration's)
    assert g.error(got) == pytest.approx(g.error(ref), rel=1e-6, abs=1e-9)
    assert real is not misleading


def test_held_solve_reports_progress_and_matches_without_it():
    rng = np.random.default_rng(9)
    g, _truth, initial = chain_graph(rng, n=12)
    params = graph_mod.lm_params()
    ticks = []
    a = held.optimize(g, initial, params, progress=ticks.append)
    b = held.optimize(g, initial, params)
    assert len(ticks) >= 2 and any(t is not None for t in ticks)  # LM iterations and relinearisations
    assert g.error(a) == pytest.approx(g.error(b), rel=1e-9, abs=1e-12)


# --- a synthetic wheeled drive through the graph ----------------------------------------------------

G = 9.81
FS = 100


def wheeled_drive(seconds: float = 70.0):
    """A level car (body x forward, z up) at 10 m/s weaving (yaw rate 0.1 sin(0.3 t) rad/s); its IMU
    exact except a sideways accelerometer bias of 0.1 m/s^2 from ``OUTAGE[0]`` on (the kind of
    error only the NHC sees while the fixes are out); fixes at 5 Hz. Returns (t_ns, gyro, acc,
    positions, start pose)."""
    sub = 10
    tt = np.arange(int(seconds * FS * sub)) / (FS * sub)
    rate = 0.1 * np.sin(0.3 * tt)
    psi = np.concatenate([[0.0], np.cumsum((rate[1:] + rate[:-1]) / 2) / (FS * sub)])
    vel = 10.0 * np.stack([np.cos(psi), np.sin(psi), np.zeros_like(tt)], axis=1)
    pos = np.concatenate([np.zeros((1, 3)), np.cumsum((vel[1:] + vel[:-1]) / 2, axis=0) / (FS * sub)])
    i = np.arange(0, len(tt), sub)
    acc = np.stack([np.zeros(len(i)), 10.0 * rate[i], np.full(len(i), G)], axis=1)
    acc[tt[i] >= OUTAGE[0], 1] += 0.1
    gyro = np.stack([np.zeros(len(i)), np.zeros(len(i)), rate[i]], axis=1)
    t_ns = np.round(tt[i] * 1e9).astype(np.int64)
    return t_ns, gyro, acc, pos[i], (np.eye(3), pos[0], vel[0])


OUTAGE = (40.0, 60.0)  # [s]


def run_drive(with_nhc: bool, solve=None):
    t_ns, gyro, acc, p_true, start = wheeled_drive()
    t = t_ns * 1e-9
    idx = np.flatnonzero((np.arange(len(t)) % (FS // 5) == 0) & ((t < OUTAGE[0]) | (t > OUTAGE[1])))
    fixes = PositionFixes(idx=idx, p=p_true[idx], sigma_m=0.02, lever=np.zeros(3), label="fix")
    noise = ImuNoise(gyro_noise_density=1e-4, acc_noise_density=1e-3, gyro_random_walk=1e-5, acc_random_walk=1e-4)
    settings = FusionSettings(noise=noise, gravity=G, keyframe_hz=5.0)
    hook = nhc.nhc_callback(nhc.NhcSettings(0.1, 0.1), gyro) if with_nhc else None
    res = graph_mod.fuse(t_ns, gyro, acc, start, [fixes], settings, extra_factors=hook)
    end = int(np.searchsorted(res.kf_idx, idx[np.searchsorted(t[idx], OUTAGE[1])]))  # the first fix after it
    truth = p_true[res.kf_idx]
    return res, np.linalg.norm(res.causal_p[end - 1] - truth[end - 1]), \
        np.sqrt(np.mean(np.sum((res.smoothed_p - truth) ** 2, axis=1)))


def test_nhc_cuts_the_outage_drift_of_a_wheeled_drive(monkeypatch):
    _res, live_raw, smooth_raw = run_drive(False)
    res, live_nhc, smooth_nhc = run_drive(True)
    # 20 s of a 0.1 m/s^2 sideways bias: ~20 m unaided, the NHC holds the sideways velocity
    assert live_raw > 5.0, live_raw
    assert live_nhc < 0.3 * live_raw, (live_nhc, live_raw)  # 3.5 m against 19 m
    assert smooth_nhc < smooth_raw, (smooth_nhc, smooth_raw)
    # the held solve gives the smoothed estimate LM gives on the true graph
    monkeypatch.setattr(held, "optimize",
                        lambda g, init, params, progress=None: gtsam.LevenbergMarquardtOptimizer(g, init, params).optimize())
    ref, _live, _smooth = run_drive(True)
    np.testing.assert_allclose(res.smoothed_p, ref.smoothed_p, atol=1e-4)
    np.testing.assert_allclose(res.causal_p, ref.causal_p, atol=0.0)
