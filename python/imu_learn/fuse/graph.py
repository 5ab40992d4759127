"""The factor graph: navigation state (pose, velocity) and IMU bias at keyframes, GTSAM's
``CombinedImuFactor`` (bias random walk inside) between consecutive keyframes, aiding factors at
their keyframes, and a prior on the first state. Pose aiding in its own world
(:class:`~imu_learn.fuse.aiding.types.WorldPoses`) adds one state, that world's pose in the
navigation frame (key ``w0``): free (no prior of its own), never marginalised from the fixed-lag window.

Keyframes are the IMU samples of a fixed-rate grid (``keyframe_hz``) plus every sample an aiding
measurement is tied to. Each IMU sample k is held over [t_k, t_k+1] (zero-order hold, as
everywhere in imu_learn). iSAM2 is updated at each aiding epoch: the estimate of keyframe k as of
t_k (right after the update at its epoch, or the IMU prediction from the last update in between)
is the *causal* estimate (what a navigation system would deliver live); after the last keyframe, a
batch Levenberg-Marquardt pass over the whole graph, started from iSAM2's final estimate, gives
the *smoothed* one.

The causal estimate runs on GTSAM's ``IncrementalFixedLagSmoother`` (iSAM2 over the keyframes of the
last ``lag_s`` seconds; older ones are marginalised into a prior on the window), so each update costs
the same however long the recording: fusion is linear in its length (docs/scale.md). ``lag_s = inf``
keeps iSAM2 over the whole graph (each update's cost grows with the graph: quadratic overall), the
estimator the fusion tables were first written with.

:class:`IncrementalFusion` holds the graph and takes the IMU one sample at a time (the online mode,
:mod:`imu_learn.fuse.experiments.online`, streams through it); :func:`fuse` is a loop over a recording's samples
through it followed by the smoothing pass.

GTSAM's ``CombinedImuFactor`` takes its default (tangent-space, first-order) preintegration; over
a keyframe interval of 0.1 s (20 samples at 200 Hz) it differs from the exact manifold
preintegration by far less than the sensor noise (measured in tests/test_fuse.py).
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, Iterable, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np

from imu_learn.errors import InvalidInputError

from .aiding import epochs
from .aiding.types import WORLD
from .factors import held
from .settings import SETTLE_S, FusionSettings


@dataclass
class FusionResult:
    kf_idx: np.ndarray  # (K,) IMU sample index of each keyframe
    causal_p: np.ndarray  # (K, 3) each keyframe's position right after its own update (see causal_frame)
    causal_R: np.ndarray  # (K, 3, 3)
    smoothed_p: np.ndarray
    smoothed_R: np.ndarray
    smoothed_v: np.ndarray
    smoothed_bias: np.ndarray  # (K, 6) gyro, acc
    seconds: float = 0.0
    counts: Dict[str, int] = field(default_factory=dict)
    # how causal_p / causal_R are expressed: "navigation frame" (each as its update estimated it), or with
    # the aiding's own world (WorldPoses) "the aiding's world as estimated at each update, mapped into the
    # navigation frame by the final world" (:meth:`IncrementalFusion.smooth`)
    causal_frame: str = "navigation frame"


def keyframes(t_ns: np.ndarray, keyframe_hz: float, aiding: Seq) -> np.ndarray:
    idx = [epochs(t_ns, keyframe_hz), np.array([0, len(t_ns) - 1])]
    for a in aiding:
        idx += a.tied_samples()
    return np.unique(np.concatenate(idx).astype(np.int64))


@dataclass(frozen=True)
class CausalState:
    """What :meth:`IncrementalFusion.add_sample` returns for a sample: the navigation state as of the
    sample's stamp. ``keyframe``: the sample is a keyframe (its estimate is the one
    :attr:`FusionResult.causal_p` holds); ``updated``: iSAM2 was updated there (aiding arrived, or
    the stream ended). Between keyframes it is the IMU prediction from the last keyframe."""

    index: int
    t_ns: int
    keyframe: bool
    updated: bool
    nav: object  # gtsam.NavState

    @property
    def p(self) -> np.ndarray:
        return self.nav.position()

    @property
    def R(self) -> np.ndarray:
        return self.nav.attitude().matrix()

    @property
    def v(self) -> np.ndarray:
        return self.nav.velocity()


def lm_params():
    import gtsam

    lm = gtsam.LevenbergMarquardtParams()
    lm.setLinearSolverType("MULTIFRONTAL_QR")
    return lm


def window_lm_params():
    """:func:`lm_params` for the re-solve of the fixed-lag window: there the marginal prior and a single
    fix fit almost exactly (final error near 0), where LM's default tests (a decrease of 1e-5 relative
    or absolute) took 14-50 iterations to creep to it; a decrease under 1e-3 (in half the chi-square)
    ends it."""
    lm = lm_params()
    lm.setAbsoluteErrorTol(1e-3)
    return lm


def _aiding_by_sample(aiding: Seq) -> tuple:
    """The aiding's factors' ingredients by the IMU sample they are tied to: position fixes
    ``{s: [(p, lever, model)]}`` and relative poses ``{j: [(i, Pose3, model)]}`` (absolute poses
    there too, as ``(None, Pose3, model)``)."""
    fixes_at: Dict[int, List] = {}
    between_at: Dict[int, List] = {}
    for a in aiding:  # each aiding type hands its own (:mod:`.aiding.types`)
        if not hasattr(a, "factors_by_sample"):
            raise InvalidInputError(f"unknown aiding {type(a).__name__}")
        a.factors_by_sample(fixes_at, between_at)
    return fixes_at, between_at


_NO_LAG = 1e15  # [s]: a smoother lag no recording reaches


def isam2_params():
    """iSAM2's settings for :class:`IncrementalFusion` (why each: the comments)."""
    import gtsam

    isam_params = gtsam.ISAM2Params()
    # QR, not the default Cholesky: with datasheet bias random walks the IMU factors' bias blocks
    # are 1e10 times stiffer than a loose bias prior, and Cholesky reports such chains as
    # indeterminate (tests/test_fuse.py keeps a minimal case).
    isam_params.setFactorization("QR")
    # Gauss-Newton steps, with iSAM2 updated only where aiding arrives: between aiding epochs a
    # keyframe adds no information, so its estimate is the IMU prediction. Updating at every
    # keyframe instead made Gauss-Newton diverge with 0.1 Hz fixes (EuRoC V1_03: 286 km), and
    # Dogleg, which cured that, needs the whole Bayes tree for each step (cost growing with the
    # trajectory: 43 s on V1_01 with 1 Hz fixes, now 4 s). After a coast longer than
    # `resolve_after_s` the IMU-predicted linearisation point is far off and a few Gauss-Newton
    # steps leave the first fix's estimate metres to hundreds of metres from it (40 s coast:
    # 243-269 m); there the whole graph so far is re-solved by Levenberg-Marquardt and iSAM2
    # restarted from that solution (0.02-0.05 m; tests/test_fuse_aiding.py). With the fixed-lag
    # smoother the re-solve covers its window and the coast (IncrementalFusion._resolve_window).
    isam_params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams())
    # Relinearise any variable whose step exceeds 0.1 (rad, m, m/s), checked at every update: with
    # 0.01 a 10 Hz VO chain relinearised most of itself each time (V1_01: 29 s, now 11 s, same
    # RMSE); checking only every 10th update let 0.1 Hz fixes diverge.
    isam_params.setRelinearizeThreshold(0.1)
    isam_params.relinearizeSkip = 1
    return isam_params


# GTSAM walks the batch pass's Bayes tree recursively (freeing it, at least), one stack frame per level;
# on the long chain of a 10 h recording (360,000 keyframes) that overflowed the main thread's 8 MiB
# stack (SIGSEGV, bench/bench_scale.py). The batch pass runs in a thread with this much stack per
# keyframe (at least 64 MiB); only the pages touched are ever resident.
STACK_PER_KEYFRAME = 1024


def deep_stack(fn: Callable, keyframes: int):
    """``fn()`` run in a thread whose stack fits GTSAM's recursion over ``keyframes`` keyframes; its
    result, or its exception raised here."""
    size = max(64 << 20, int(keyframes) * STACK_PER_KEYFRAME)
    size = (size + (1 << 20) - 1) & ~((1 << 20) - 1)  # whole MiB
    out: Dict[str, object] = {}

    def target() -> None:
        try:
            out["value"] = fn()
        except BaseException as e:  # noqa: BLE001 (re-raised in the caller's thread)
            out["error"] = e

    old = threading.stack_size(size)
    try:
        worker = threading.Thread(target=target, name="imu_learn-batch-smoothing")
        worker.start()
    finally:
        threading.stack_size(old)
    worker.join()
    if "error" in out:
        raise out["error"]
    return out["value"]


def fixed_lag_params():
    """iSAM2's settings inside the fixed-lag smoother: :func:`isam2_params`, and the slots of the
    factors it marginalises reused (else its factor list keeps an empty slot for each: 10,800 after
    15 min at 1 Hz fixes, against 125 live factors)."""
    params = isam2_params()
    params.findUnusedFactorSlots = True
    return params


class IncrementalFusion:
    """The factor graph built and solved one IMU sample at a time, as a navigation system would run
    it: :meth:`add_sample` integrates each sample into the current preintegration and, at a
    keyframe, adds the ``CombinedImuFactor`` from the previous keyframe and the aiding tied to it,
    and updates the causal solver when aiding arrived there (``iterations`` steps; after a coast
    longer than ``resolve_after_s`` a batch re-solve, see :func:`isam2_params`) or the stream ended; it
    returns the causal state (:class:`CausalState`). :meth:`smooth`, after the last sample, runs the
    batch Levenberg-Marquardt pass and gives the :class:`FusionResult` :func:`fuse` returns.

    Keyframe indices are precomputed from the stamps ``t_ns``: the stream knows the keyframe grid
    and the stamps of its aiding. Each aiding measurement is tied to its nearest IMU sample and is
    consumed when that sample arrives (a measurement stamped up to half a sample period after
    that sample is thereby used at it; a live system would use it at the next sample). The
    recording's last sample is a keyframe with an update: the end of the stream.

    Sample k is held over [t_k, t_k+1] (zero-order hold), so it is integrated when sample k+1
    arrives and its dt is known; the preintegration at keyframe sample s therefore holds exactly
    the samples from the previous keyframe up to s - 1.

    ``predict_between``: also return the IMU prediction at samples between keyframes (otherwise
    None there; :func:`fuse` skips it, its results do not depend on it).

    ``lag_s``: the causal solver is GTSAM's ``IncrementalFixedLagSmoother`` holding the keyframes of
    the last ``lag_s`` seconds (each update's cost bounded; tests/test_fuse_fixed_lag.py); ``inf``:
    iSAM2 over the whole graph, whose updates grow with it. Every factor is also kept for the
    smoothing pass, which starts from each keyframe's last estimate in the window."""

    def __init__(self, t_ns: np.ndarray, start_pose: tuple, aiding: Seq = (),
                 settings: FusionSettings = FusionSettings(), bias0: Optional[np.ndarray] = None,
                 predict_between: bool = True, extra_factors: Optional[Callable] = None) -> None:
        import gtsam
        from gtsam.symbol_shorthand import B, V, X

        self._gtsam, self._B, self._V, self._X = gtsam, B, V, X
        t_ns = np.asarray(t_ns, dtype=np.int64)
        if t_ns.ndim != 1 or len(t_ns) < 2:
            raise InvalidInputError(f"fusion needs N >= 2 sample stamps; got shape {t_ns.shape}")
        self._t_start = time.perf_counter()
        self.t_ns = t_ns
        self.stamps = t_ns.tolist()  # the samples' stamps [ns] as ints
        self._n_samples = len(t_ns)
        self.settings = settings
        self.iterations = int(settings.iterations)
        resolve_after_s = settings.resolve_after_s
        self.resolve_after_ns = int(round(resolve_after_s * 1e9)) if np.isfinite(resolve_after_s) else 2 ** 62
        self._last_update_ns = int(t_ns[0])
        self._anchored = False  # pending aiding ties a keyframe to the states before the last update
        self.predict_between = bool(predict_between)
        kf = keyframes(t_ns, settings.keyframe_hz, aiding)
        self.kf_idx = kf
        self._kf_list = [int(s) for s in kf]
        self._key_of = {int(s): k for k, s in enumerate(kf)}
        self._fixes_at, self._between_at = _aiding_by_sample(aiding)
        self._params = settings.noise.gtsam_params(settings.gravity)
        self.smoothing = settings.smoothing
        self._start_solver(settings.lag_s)
        self._kf_t = ((t_ns[kf] - t_ns[0]) * 1e-9).tolist()  # each keyframe's time [s]: the smoother's stamps
        self._full = gtsam.NonlinearFactorGraph()
        pose0, v0, b0 = self._start_with_prior(start_pose, settings.prior, bias0)

        K = len(kf)
        self.causal_p, self.causal_R = np.zeros((K, 3)), np.zeros((K, 3, 3))
        self._state, self._vel, self._bias = pose0, v0, b0
        self._nav = gtsam.NavState(pose0, self._vel)
        self._pim = None
        self.counts = {"imu_factors": 0, "position_factors": 0, "relative_pose_factors": 0, "isam2_updates": 0,
                       "resolves_after_coast": 0}
        if self.windowed:
            # Factors tied to a keyframe already marginalised (e.g. a relative pose reaching back further
            # than the lag): left out of the causal estimate (the batch smoothing pass has them).
            self.counts["factors_before_window"] = 0
        # Factors beyond the aiding (imu_learn.fuse.factors.ExtraFactors, e.g. learned displacements): called as
        # extra_factors(self, k, s) at keyframe k (sample s) before its update, it returns factors to
        # add there; they count as new information (iSAM2 updates at that keyframe).
        self._extra_factors = extra_factors
        self._world = None  # the key of the aiding's world (WorldPoses), once its first pose arrived
        self._world_now: Optional[np.ndarray] = None  # its causal estimate (4, 4) after the last update
        self.causal_world = np.full((K, 4, 4), np.nan)  # that estimate as of each keyframe
        if extra_factors is not None:
            self.counts["extra_factors"] = 0
        self.n = 0  # samples added so far
        self._k = 0  # the next keyframe's number
        self._next_kf = self._kf_list[0]
        self._prev = None  # (t_ns, gyro, acc, var) of the last sample, integrated when the next arrives

    def _start_solver(self, lag_s: float) -> None:
        """The causal solver: a fixed-lag smoother over the last ``lag_s`` seconds, or (``lag_s = inf``)
        iSAM2 over the whole graph."""
        gtsam = self._gtsam
        lag_s = float(lag_s)
        if not lag_s > 0:
            raise InvalidInputError(f"lag_s: the fixed-lag window must be > 0 s (inf: the whole graph), got {lag_s}")
        self.lag_s = lag_s
        self.windowed = bool(np.isfinite(lag_s))
        if self.windowed:
            self._isam = gtsam.IncrementalFixedLagSmoother(lag_s, fixed_lag_params())
            self._initial = gtsam.Values()  # every keyframe's latest estimate: the smoothing pass starts there
            # (start, until) [s]: keyframes from start on stay in the window until then (_lag_now): the
            # first SETTLE_S, then each coast
            self._hold = (0.0, SETTLE_S)
        else:
            self._isam = gtsam.ISAM2(isam2_params())

    def _start_with_prior(self, start_pose: tuple, prior, bias0: Optional[np.ndarray]) -> tuple:
        """The first keyframe's state (pose, velocity, bias) and its prior factors in a new pending graph."""
        gtsam, B, V, X = self._gtsam, self._B, self._V, self._X
        R0, p0, v0 = start_pose
        pose0 = gtsam.Pose3(gtsam.Rot3(np.asarray(R0)), np.asarray(p0, dtype=np.float64))
        v0 = np.asarray(v0, dtype=np.float64)
        bg0, ba0 = (np.zeros(3), np.zeros(3)) if bias0 is None else (np.asarray(bias0)[:3], np.asarray(bias0)[3:])
        b0 = gtsam.imuBias.ConstantBias(ba0, bg0)  # GTSAM's order: accelerometer, gyroscope
        self._graph = gtsam.NonlinearFactorGraph()
        self._values = gtsam.Values()
        self._true_at: Dict[int, object] = {}  # pending graph slot -> the Python factor held there
        self._graph.add(gtsam.PriorFactorPose3(X(0), pose0, prior.pose_noise(R0, gtsam)))
        self._graph.add(gtsam.PriorFactorVector(V(0), v0, gtsam.noiseModel.Isotropic.Sigma(3, prior.vel_mps)))
        self._graph.add(gtsam.PriorFactorConstantBias(B(0), b0, gtsam.noiseModel.Diagonal.Sigmas(prior.bias_sigmas())))
        self._values.insert(X(0), pose0)
        self._values.insert(V(0), v0)
        self._values.insert(B(0), b0)
        return pose0, v0, b0

    @property
    def done(self) -> bool:
        return self.n == len(self.t_ns)

    @property
    def bias(self) -> np.ndarray:
        """(6,) gyro then acc: the bias estimate the IMU prediction uses now (the last update's, or
        the prior's mean before the first)."""
        return np.r_[self._bias.gyroscope(), self._bias.accelerometer()]

    def _add_aiding(self, k: int, s: int) -> int:
        gtsam, X = self._gtsam, self._X
        graph = self._graph
        n = graph.size()
        for p, lever, model in self._fixes_at.get(s, ()):
            self._anchored = True
            if np.any(lever):
                graph.add(gtsam.GPSFactorArm(X(k), p, lever, model))
            else:
                graph.add(gtsam.GPSFactor(X(k), p, model))
            self.counts["position_factors"] += 1
        for i, rel, model in self._between_at.get(s, ()):
            # what ties this keyframe to the states before the last update (a coast's start): an absolute
            # pose, the aiding's world, a relative pose from a keyframe up to that update
            self._anchored |= i is None or i == WORLD or self.stamps[i] <= self._last_update_ns
            if i is None:  # an absolute pose (AbsolutePoses)
                graph.add(gtsam.PriorFactorPose3(X(k), rel, model))
                self.counts["pose_factors"] = self.counts.get("pose_factors", 0) + 1
                continue
            if i == WORLD:  # a pose in the aiding's own world, a free state (WorldPoses): X_k = T_WA Z
                if self._world is None:  # its first value from this keyframe's (IMU-predicted) pose
                    self._world = gtsam.symbol("w", 0)
                    self._values.insert(self._world, self._values.atPose3(X(k)).compose(rel.inverse()))
                causal, smoothed = model  # the smoothing pass takes the pose's own noise (WorldPoses)
                if smoothed is not causal:
                    self._true_at[graph.size()] = gtsam.BetweenFactorPose3(self._world, X(k), rel, smoothed)
                graph.add(gtsam.BetweenFactorPose3(self._world, X(k), rel, causal))
                self.counts["world_pose_factors"] = self.counts.get("world_pose_factors", 0) + 1
                continue
            graph.add(gtsam.BetweenFactorPose3(X(self._key_of[i]), X(k), rel, model))
            self.counts["relative_pose_factors"] += 1
        urgent = graph.size() - n
        if self._extra_factors is not None:
            extra = self._extra_factors(self, k, s)
            for f in extra:
                self._add_extra(f)
            # a hook's factors alone call for an update at most every ``update_every_s`` (its attribute)
            every_ns = int(round(getattr(self._extra_factors, "update_every_s", 0.0) * 1e9))
            if extra and self.stamps[s] - self._last_update_ns >= every_ns:
                urgent += len(extra)
        return urgent

    def _add_extra(self, f) -> None:
        """An extra factor into the pending graph; a Python one (``gtsam.CustomFactor``) on pending keys
        only held at the pending values (the IMU prediction) as a native ``LinearContainerFactor`` for
        the causal solver,
        whose every call of a Python factor would copy all the window's values, the Python factor
        itself kept for the smoothing pass (which relinearises it: :mod:`.factors.held`)."""
        gtsam = self._gtsam
        if isinstance(f, gtsam.CustomFactor) and all(self._values.exists(key) for key in f.keys()):
            self._true_at[self._graph.size()] = f
            f = gtsam.LinearContainerFactor(f.linearize(self._values), self._values)
        self._graph.add(f)
        self.counts["extra_factors"] += 1

    def add_sample(self, t_ns: int, gyro: np.ndarray, acc: np.ndarray,
                   var: Optional[np.ndarray] = None) -> Optional[CausalState]:
        """Take IMU sample number :attr:`n` (stamp ``t_ns`` [ns], gyro [rad/s] and acc [m/s^2] (3,)):
        integrate the previous sample, and at a keyframe add its factors and update iSAM2 where
        aiding arrived. Returns the causal state as of ``t_ns`` (None between keyframes without
        ``predict_between``).

        ``var`` (6,): this sample's own noise variances (discrete-time, gyro then acc, the
        convention of :mod:`imu_learn.nn.covariance`, e.g. a refiner's covariance head) in place of
        the datasheet's white noise; GTSAM's preintegration then propagates exactly these per-sample
        variances into each IMU factor's covariance (it reads the parameters at every sample). The
        bias random walk stays the datasheet's."""
        n = self.n
        t = int(t_ns)
        if n >= self._n_samples or t != self.stamps[n]:
            expected = "none (the stream has ended)" if n >= self._n_samples else str(self.stamps[n])
            raise InvalidInputError(f"sample {n}: stamp {t} ns, expected {expected}")
        gtsam = self._gtsam
        if n:
            t_prev, g_prev, a_prev, v_prev = self._prev
            dt = (t - t_prev) * 1e-9
            if v_prev is not None:
                # GTSAM takes continuous-time covariances and divides them by dt itself.
                self._params.setGyroscopeCovariance(np.diag(v_prev[:3] * dt))
                self._params.setAccelerometerCovariance(np.diag(v_prev[3:] * dt))
            self._pim.integrateMeasurement(a_prev, g_prev, dt)
        self._prev = (t, np.asarray(gyro, dtype=np.float64), np.asarray(acc, dtype=np.float64),
                      None if var is None else np.asarray(var, dtype=np.float64))
        self.n = n + 1
        if n != self._next_kf:
            if not self.predict_between:
                return None
            return CausalState(n, t, False, False, self._pim.predict(self._nav, self._bias))
        k = self._k
        updated = False
        if k == 0:
            self._add_aiding(0, 0)
        else:
            X, V, B = self._X, self._V, self._B
            pim = self._pim
            self._graph.add(gtsam.CombinedImuFactor(X(k - 1), V(k - 1), X(k), V(k), B(k - 1), B(k), pim))
            self.counts["imu_factors"] += 1
            pred = pim.predict(self._nav, self._bias)
            self._values.insert(X(k), pred.pose())
            self._values.insert(V(k), pred.velocity())
            self._values.insert(B(k), self._bias)
            aided = bool(self._add_aiding(k, n))
            if not aided and k < len(self._kf_list) - 1:
                # No new information: the estimate as of t_k is the IMU prediction (what a navigation
                # system outputs between aiding epochs); iSAM2 takes these factors with the next update.
                self._state, self._vel = pred.pose(), pred.velocity()
            else:  # (the last keyframe always: its factors join the graph; after a coast without aiding
                # at its end nothing is re-solved: there is nothing new; nor after aiding that ties nothing
                # to the states before the coast: relative poses among keyframes after it, which a
                # relative aiding's break leaves, move the coast's end by no measurement, and a
                # re-solve of the window from them moved EuRoC MH_04's causal track 4 m, 10 deg)
                self._update(t, resolve=aided and self._anchored)
                self._state = self._isam.calculateEstimatePose3(X(k))
                self._vel = self._isam.calculateEstimateVector(V(k))
                self._bias = self._isam.calculateEstimateConstantBias(B(k))
                if self._world is not None:
                    self._world_now = self._isam.calculateEstimatePose3(self._world).matrix()
                updated = True
        self.causal_p[k], self.causal_R[k] = self._state.translation(), self._state.rotation().matrix()
        if self._world_now is not None:
            self.causal_world[k] = self._world_now
        self._nav = gtsam.NavState(self._state, self._vel)
        self._k = k + 1
        if self._k < len(self._kf_list):
            self._next_kf = self._kf_list[self._k]
            self._pim = gtsam.PreintegratedCombinedMeasurements(self._params, self._bias)
        else:
            self._next_kf = -1
            self._pim = None
        return CausalState(n, t, True, updated, self._nav)

    def _update(self, t_ns: int, resolve: bool = True) -> None:
        """Hand the pending factors and values to the causal solver; after a coast longer than
        ``resolve_after_ns`` ended by new information (``resolve``) re-solve in batch (the whole graph,
        or with the fixed-lag smoother its window plus the coast: bounded, so fusion stays linear)."""
        gtsam = self._gtsam
        coast = resolve and t_ns - self._last_update_ns > self.resolve_after_ns
        if self.smoothing == "batch" or not self.windowed:  # the whole-graph path re-solves the whole graph
            for f in range(self._graph.size()):  # (the Python factors themselves, not as held)
                self._full.add(self._true_at.get(f, self._graph.at(f)))
        if self.windowed:
            self._update_window(coast, (t_ns - self.stamps[0]) * 1e-9, (self._last_update_ns - self.stamps[0]) * 1e-9)
        else:
            self._update_whole(coast)
        self.counts["isam2_updates"] += 1
        self.counts["resolves_after_coast"] += int(coast)
        self._graph = gtsam.NonlinearFactorGraph()
        self._values = gtsam.Values()
        self._true_at = {}
        self._last_update_ns = t_ns
        self._anchored = False

    def _update_whole(self, coast: bool) -> None:
        """iSAM2 over the whole graph; after a coast, Levenberg-Marquardt over all of it and iSAM2
        restarted from that solution."""
        gtsam = self._gtsam
        self._isam.update(self._graph, self._values)
        for _ in range(self.iterations - 1):
            self._isam.update()
        if coast:
            est = held.optimize(self._full, self._isam.calculateEstimate(), lm_params())
            self._isam = gtsam.ISAM2(self._isam.params())
            self._isam.update(self._full, est)

    def _update_window(self, coast: bool, t_s: float, last_s: float) -> None:
        """The fixed-lag smoother at time ``t_s`` (the previous update at ``last_s``): the new keyframes
        stamped with their times, factors reaching before the window left to the smoothing pass;
        after a coast the window and the coast are re-solved (:meth:`_resolve_window`) before anything
        of them is marginalised."""
        values = self._values
        stamps = {key: self._kf_t[self._gtsam.Symbol(key).index()] for key in values.keys()}
        if self._world is not None:  # the aiding's world is re-stamped at every update: never marginalised
            stamps[self._world] = t_s
        self._initial.insert(values)
        graph = self._inside_window(self._graph, set(stamps) | set(self._isam.timestamps()))
        if coast:  # (inside the first SETTLE_S the start stays held too)
            self._hold = (0.0, max(SETTLE_S, t_s + self.lag_s)) if t_s <= SETTLE_S else (last_s, t_s + self.lag_s)
        # after a coast, nothing leaves the window at the IMU prediction
        self._isam.setSmootherLag(_NO_LAG if coast else self._lag_now(t_s))
        self._isam.update(graph, values, stamps)
        for _ in range(self.iterations - 1):
            self._isam.update()
        if coast:
            self._resolve_window(self._lag_now(t_s))
        self._initial.insert_or_assign(self._isam.calculateEstimate())

    def _lag_now(self, t_s: float) -> float:
        """The window at time ``t_s``: ``lag_s``; in the first :data:`SETTLE_S`, everything so far; and
        until ``lag_s`` after the end of the last coast, from ``lag_s`` before its start: the coast's
        states, fixed by a single measurement at its end, are marginalised only once the aiding after
        it has relinearised them."""
        start, until = self._hold
        return self.lag_s if t_s > until else max(self.lag_s, t_s - start + self.lag_s)

    def _inside_window(self, graph, keys: set):
        """``graph``'s factors whose variables are all in ``keys`` (the window's and the new ones)."""
        kept = self._gtsam.NonlinearFactorGraph()
        for f in range(graph.size()):
            factor = graph.at(f)
            if all(k in keys for k in factor.keys()):
                kept.add(factor)
            else:
                self.counts["factors_before_window"] += 1
        return kept

    def _resolve_window(self, lag_s: float) -> None:
        """After a coast, as the whole-graph path does with the whole graph: Levenberg-Marquardt over
        the smoother's factors (the window, its marginal prior, the coast just added), started from
        iSAM2's step, and a new smoother started from that solution, so the states that now leave
        the window (``lag_s``) are marginalised at the re-solved estimate, not at the IMU prediction."""
        gtsam = self._gtsam
        old = self._isam
        window = gtsam.NonlinearFactorGraph()
        factors = old.getFactors()
        for f in range(factors.size()):
            factor = factors.at(f)
            if factor is not None:  # the slots of removed factors are empty
                window.add(factor)
        est = gtsam.LevenbergMarquardtOptimizer(window, old.calculateEstimate(), window_lm_params()).optimize()
        self._isam = gtsam.IncrementalFixedLagSmoother(lag_s, fixed_lag_params())
        self._isam.update(window, est, dict(old.timestamps()))

    def window_size(self) -> int:
        """Variables the causal solver holds now (the fixed-lag smoother's window, or the whole graph)."""
        return len(self._isam.timestamps()) if self.windowed else self._isam.calculateEstimate().size()

    def smooth(self, progress: Optional[Callable] = None) -> FusionResult:
        """After the last sample: the batch Levenberg-Marquardt pass over the whole graph, started
        from iSAM2's final estimate (with the fixed-lag smoother: each keyframe's last estimate in
        its window); the causal estimates beside the smoothed ones. With ``smoothing = "window"``
        no batch pass: the smoothed estimate is that last estimate (a fixed-lag smoother's output;
        with ``lag_s = inf``, iSAM2's final one). ``progress``: called after each of the batch
        pass's iterations (:func:`.factors.held.optimize`), e.g. a progress bar's update."""
        if not self.done:
            raise InvalidInputError(f"smooth() after the last sample: {self.n} of {len(self.t_ns)} added")
        X, V, B = self._X, self._V, self._B
        initial = self._initial if self.windowed else self._isam.calculateEstimate()
        if self.smoothing == "batch":
            full = self._full
            est = deep_stack(lambda: held.optimize(full, initial, lm_params(), progress),
                             len(self._kf_list))
        else:
            est = initial
        K = len(self._kf_list)
        smoothed_p, smoothed_R = np.zeros((K, 3)), np.zeros((K, 3, 3))
        smoothed_v, smoothed_b = np.zeros((K, 3)), np.zeros((K, 6))
        for k in range(K):
            pose = est.atPose3(X(k))
            smoothed_p[k], smoothed_R[k] = pose.translation(), pose.rotation().matrix()
            smoothed_v[k] = est.atVector(V(k))
            b = est.atConstantBias(B(k))
            smoothed_b[k] = np.r_[b.gyroscope(), b.accelerometer()]
        counts = {k: v for k, v in self.counts.items() if k != "isam2_updates"}
        causal_p, causal_R, frame = self.causal_p, self.causal_R, "navigation frame"
        if self._world is not None and est.exists(self._world):
            causal_p, causal_R = in_final_world(self.causal_p, self.causal_R, self.causal_world,
                                                est.atPose3(self._world).matrix())
            frame = ("the aiding's world as estimated at each update, mapped into the navigation frame by the "
                     "final world")
        return FusionResult(self.kf_idx, causal_p, causal_R, smoothed_p, smoothed_R, smoothed_v, smoothed_b,
                            time.perf_counter() - self._t_start, counts, frame)


def in_final_world(p: np.ndarray, R: np.ndarray, worlds: np.ndarray, final: np.ndarray
                   ) -> Tuple[np.ndarray, np.ndarray]:
    """Causal poses ``(p, R)`` (K, 3), (K, 3, 3) in the navigation frame, each taken into the aiding's world
    through the world's causal estimate as of its keyframe (``worlds`` (K, 4, 4), NaN before the first:
    those take the first estimate), then into the navigation frame through ``final`` (4, 4): one rigid
    map of the aiding's world, so the world's causal re-estimates (its tilt as the accelerometer tells it
    over the run) no longer move the poses already output. The relative geometry of each pose to the
    aiding is the causal solver's, as it was at that pose's update."""
    have = ~np.isnan(worlds[:, 0, 0])
    if not have.any():
        return p, R
    idx = np.maximum.accumulate(np.where(have, np.arange(len(have)), -1))
    idx[idx < 0] = int(np.argmax(have))
    M = np.einsum("ij,kjl->kil", final, np.linalg.inv(worlds[idx]))  # final · W_k⁻¹
    return np.einsum("kij,kj->ki", M[:, :3, :3], p) + M[:, :3, 3], np.einsum("kij,kjl->kil", M[:, :3, :3], R)


# One sample as the graph takes it: (sample index, gyro [rad/s] (3,), acc [m/s^2] (3,), its noise variances
# (6,) [gyro (rad/s)^2, acc (m/s^2)^2] or None for the datasheet's); more fields may follow (feed passes
# the item on as it is).
Sample = Tuple[int, np.ndarray, np.ndarray, Optional[np.ndarray]]


def feed(fusion: IncrementalFusion, samples: Iterable[Sample],
         on_state: Optional[Callable[[Sample, Optional[CausalState]], None]] = None) -> None:
    """The loop over :meth:`IncrementalFusion.add_sample`: every sample of ``samples`` (in order: sample
    indices 0, 1, ... of the fusion's stamps), and ``on_state(sample, state)`` after each."""
    stamps = fusion.stamps
    for item in samples:
        state = fusion.add_sample(stamps[item[0]], item[1], item[2], item[3])
        if on_state is not None:
            on_state(item, state)


def samples_of(gyro: np.ndarray, acc: np.ndarray, var: Optional[np.ndarray] = None) -> Iterable[Sample]:
    """The rows of ``gyro``, ``acc`` (N, 3) and ``var`` (N, 6, or None) as :data:`Sample` items."""
    if var is None:
        return ((s, gyro[s], acc[s], None) for s in range(len(gyro)))
    return ((s, gyro[s], acc[s], var[s]) for s in range(len(gyro)))


def fuse(t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, start_pose: tuple, aiding: Seq = (),
         settings: FusionSettings = FusionSettings(), bias0: Optional[np.ndarray] = None,
         var: Optional[np.ndarray] = None, extra_factors: Optional[Callable] = None) -> FusionResult:
    """Fuse IMU samples (N, 3) with ``aiding`` (:class:`PositionFixes`, :class:`RelativePoses`, ...)
    under ``settings``. ``start_pose`` = (R0 (3, 3), p0 (3,), v0 (3,)) of sample 0 (the prior's mean);
    ``bias0`` (6,) gyro then accelerometer, the bias prior's mean (zero when None); ``var`` (N, 6):
    per-sample noise variances instead of the datasheet's white noise
    (:meth:`IncrementalFusion.add_sample`); ``extra_factors``: the graph's hook for factors beyond the
    aiding (:mod:`imu_learn.fuse.factors`). The recording streamed through
    :class:`IncrementalFusion` sample by sample (:func:`feed`), then smoothed."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    if len(t_ns) < 2 or gyro.shape != (len(t_ns), 3) or acc.shape != gyro.shape:
        raise InvalidInputError(f"fuse needs N >= 2 samples with gyro and acc (N, 3); got {gyro.shape}, {acc.shape}")
    t_start = time.perf_counter()
    inc = IncrementalFusion(t_ns, start_pose, aiding, settings, bias0, predict_between=False,
                            extra_factors=extra_factors)
    if var is not None and np.shape(var) != (len(t_ns), 6):
        raise InvalidInputError(f"fuse: var must be (N, 6) = ({len(t_ns)}, 6), got {np.shape(var)}")
    feed(inc, samples_of(gyro, acc, var))
    res = inc.smooth()
    res.seconds = time.perf_counter() - t_start
    return res
