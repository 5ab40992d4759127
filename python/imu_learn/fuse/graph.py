"""The factor graph: navigation state (pose, velocity) and IMU bias at keyframes, GTSAM's
``CombinedImuFactor`` (bias random walk inside) between consecutive keyframes, aiding factors at
their keyframes, and a prior on the first state.

Keyframes are the IMU samples of a fixed-rate grid (``keyframe_hz``) plus every sample an aiding
measurement is tied to. Each IMU sample k is held over [t_k, t_k+1] (zero-order hold, as
everywhere in imu_learn). The graph is solved by iSAM2 one keyframe at a time: the estimate of
keyframe k right after its own update is the *causal* estimate (what a navigation system would
deliver live); after the last keyframe, a batch Levenberg-Marquardt pass over the whole graph,
started from iSAM2's final estimate, gives the *smoothed* one.

GTSAM's ``CombinedImuFactor`` takes its default (tangent-space, first-order) preintegration; over
a keyframe interval of 0.1 s (20 samples at 200 Hz) it differs from the exact manifold
preintegration by far less than the sensor noise (measured in tests/test_fuse.py).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Dict, List, Optional
from typing import Sequence as Seq

import numpy as np

from imu_learn.errors import InvalidInputError

from .aiding import PositionFixes, RelativePoses, epochs
from .noise import ImuNoise


@dataclass(frozen=True)
class PriorSigmas:
    """The first state's prior: pose and velocity from ground truth (tight), bias zero (loose)."""

    rot_rad: float = 1e-3
    pos_m: float = 1e-3
    vel_mps: float = 1e-2
    bias_gyro: float = 0.1  # rad/s: EuRoC's ADIS16448 starts with up to ~0.08 rad/s
    bias_acc: float = 0.5  # m/s^2


@dataclass
class FusionResult:
    kf_idx: np.ndarray  # (K,) IMU sample index of each keyframe
    causal_p: np.ndarray  # (K, 3) each keyframe's position right after its own update
    causal_R: np.ndarray  # (K, 3, 3)
    smoothed_p: np.ndarray
    smoothed_R: np.ndarray
    smoothed_v: np.ndarray
    smoothed_bias: np.ndarray  # (K, 6) gyro, acc
    seconds: float = 0.0
    counts: Dict[str, int] = field(default_factory=dict)


def keyframes(t_ns: np.ndarray, keyframe_hz: float, aiding: Seq) -> np.ndarray:
    idx = [epochs(t_ns, keyframe_hz), np.array([0, len(t_ns) - 1])]
    for a in aiding:
        if isinstance(a, PositionFixes):
            idx.append(a.idx)
        else:
            idx += [a.i, a.j]
    return np.unique(np.concatenate(idx).astype(np.int64))


def fuse(
    t_ns: np.ndarray,
    gyro: np.ndarray,
    acc: np.ndarray,
    start_pose: tuple,
    aiding: Seq = (),
    noise: ImuNoise = ImuNoise(),
    gravity: float = 9.81,
    keyframe_hz: float = 10.0,
    prior: PriorSigmas = PriorSigmas(),
    bias0: Optional[np.ndarray] = None,
) -> FusionResult:
    """Fuse IMU samples (N, 3) with ``aiding`` (:class:`PositionFixes`, :class:`RelativePoses`).
    ``start_pose`` = (R0 (3, 3), p0 (3,), v0 (3,)) of sample 0 (from ground truth: the prior);
    ``bias0`` (6,) gyro then accelerometer, the bias prior's mean (zero when None)."""
    import gtsam
    from gtsam.symbol_shorthand import B, V, X

    t_ns = np.asarray(t_ns, dtype=np.int64)
    if len(t_ns) < 2 or gyro.shape != (len(t_ns), 3) or acc.shape != gyro.shape:
        raise InvalidInputError(f"fuse needs N >= 2 samples with gyro and acc (N, 3); got {gyro.shape}, {acc.shape}")
    t_start = time.perf_counter()
    kf = keyframes(t_ns, keyframe_hz, aiding)
    key_of = {int(s): k for k, s in enumerate(kf)}
    fixes_at: Dict[int, List] = {}
    between_at: Dict[int, List] = {}
    for a in aiding:
        if isinstance(a, PositionFixes):
            model = gtsam.noiseModel.Isotropic.Sigma(3, a.sigma_m)
            for s, p in zip(a.idx, a.p):
                fixes_at.setdefault(int(s), []).append((p, a.lever, model))
        elif isinstance(a, RelativePoses):
            model = gtsam.noiseModel.Diagonal.Sigmas(np.r_[[a.sigma_rot_rad] * 3, [a.sigma_trans_m] * 3])
            for i, j, R, t in zip(a.i, a.j, a.R_ij, a.t_ij):
                between_at.setdefault(int(j), []).append((int(i), gtsam.Pose3(gtsam.Rot3(R), t), model))
        else:
            raise InvalidInputError(f"unknown aiding {type(a).__name__}")

    params = noise.gtsam_params(gravity)
    isam_params = gtsam.ISAM2Params()
    # QR, not the default Cholesky: with datasheet bias random walks the IMU factors' bias blocks
    # are 1e10 times stiffer than a loose bias prior, and Cholesky reports such chains as
    # indeterminate (tests/test_fuse.py keeps a minimal case).
    isam_params.setFactorization("QR")
    # Dogleg, not Gauss-Newton: with sparse fixes (0.1 Hz) the IMU-predicted linearisation point is
    # poor and Gauss-Newton steps overshoot (EuRoC V1_03: causal RMSE 286 km or an indeterminate
    # system; with Dogleg 31 m, and 2.7 m with the start-up bias prior).
    isam_params.setOptimizationParams(gtsam.ISAM2DoglegParams())
    isam_params.setRelinearizeThreshold(0.01)
    isam_params.relinearizeSkip = 1
    isam = gtsam.ISAM2(isam_params)
    full = gtsam.NonlinearFactorGraph()

    R0, p0, v0 = start_pose
    pose0 = gtsam.Pose3(gtsam.Rot3(np.asarray(R0)), np.asarray(p0, dtype=np.float64))
    bg0, ba0 = (np.zeros(3), np.zeros(3)) if bias0 is None else (np.asarray(bias0)[:3], np.asarray(bias0)[3:])
    b0 = gtsam.imuBias.ConstantBias(ba0, bg0)  # GTSAM's order: accelerometer, gyroscope
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    graph.add(gtsam.PriorFactorPose3(X(0), pose0, gtsam.noiseModel.Diagonal.Sigmas(
        np.r_[[prior.rot_rad] * 3, [prior.pos_m] * 3])))
    graph.add(gtsam.PriorFactorVector(V(0), np.asarray(v0, dtype=np.float64),
                                      gtsam.noiseModel.Isotropic.Sigma(3, prior.vel_mps)))
    graph.add(gtsam.PriorFactorConstantBias(B(0), b0, gtsam.noiseModel.Diagonal.Sigmas(
        np.r_[[prior.bias_acc] * 3, [prior.bias_gyro] * 3])))
    values.insert(X(0), pose0)
    values.insert(V(0), np.asarray(v0, dtype=np.float64))
    values.insert(B(0), b0)

    K = len(kf)
    causal_p, causal_R = np.zeros((K, 3)), np.zeros((K, 3, 3))
    causal_p[0], causal_R[0] = pose0.translation(), pose0.rotation().matrix()
    state, vel, bias = pose0, np.asarray(v0, dtype=np.float64), b0
    dt_s = np.diff(t_ns) * 1e-9
    counts = {"imu_factors": 0, "position_factors": 0, "relative_pose_factors": 0}

    def add_aiding(k: int, s: int) -> None:
        for p, lever, model in fixes_at.get(s, ()):
            if np.any(lever):
                graph.add(gtsam.GPSFactorArm(X(k), p, lever, model))
            else:
                graph.add(gtsam.GPSFactor(X(k), p, model))
            counts["position_factors"] += 1
        for i, rel, model in between_at.get(s, ()):
            graph.add(gtsam.BetweenFactorPose3(X(key_of[i]), X(k), rel, model))
            counts["relative_pose_factors"] += 1

    add_aiding(0, 0)
    for k in range(1, K):
        pim = gtsam.PreintegratedCombinedMeasurements(params, bias)
        for s in range(int(kf[k - 1]), int(kf[k])):
            pim.integrateMeasurement(acc[s], gyro[s], dt_s[s])
        graph.add(gtsam.CombinedImuFactor(X(k - 1), V(k - 1), X(k), V(k), B(k - 1), B(k), pim))
        counts["imu_factors"] += 1
        pred = pim.predict(gtsam.NavState(state, vel), bias)
        values.insert(X(k), pred.pose())
        values.insert(V(k), pred.velocity())
        values.insert(B(k), bias)
        add_aiding(k, int(kf[k]))
        isam.update(graph, values)
        for f in range(graph.size()):
            full.add(graph.at(f))
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        state = isam.calculateEstimatePose3(X(k))
        vel = isam.calculateEstimateVector(V(k))
        bias = isam.calculateEstimateConstantBias(B(k))
        causal_p[k], causal_R[k] = state.translation(), state.rotation().matrix()
    if K == 1:
        isam.update(graph, values)

    lm = gtsam.LevenbergMarquardtParams()
    lm.setLinearSolverType("MULTIFRONTAL_QR")
    est = gtsam.LevenbergMarquardtOptimizer(full, isam.calculateEstimate(), lm).optimize()
    smoothed_p, smoothed_R = np.zeros((K, 3)), np.zeros((K, 3, 3))
    smoothed_v, smoothed_b = np.zeros((K, 3)), np.zeros((K, 6))
    for k in range(K):
        pose = est.atPose3(X(k))
        smoothed_p[k], smoothed_R[k] = pose.translation(), pose.rotation().matrix()
        smoothed_v[k] = est.atVector(V(k))
        b = est.atConstantBias(B(k))
        smoothed_b[k] = np.r_[b.gyroscope(), b.accelerometer()]
    return FusionResult(kf, causal_p, causal_R, smoothed_p, smoothed_R, smoothed_v, smoothed_b,
                        time.perf_counter() - t_start, counts)
