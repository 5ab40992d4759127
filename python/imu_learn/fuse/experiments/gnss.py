"""GNSS/IMU navigation of a real recording with simulated GNSS outages, no ground truth at run time:
rtklibexplorer/GNSS_IMU's experiment (its loosely coupled EKF is the peer) on our factor graph.

``imu-learn fuse --config configs/fuse_gnss_drive.toml --data-root DIR``: a config with
``kind = "gnss-outages"`` is routed here by :mod:`imu_learn.cli.fuse` (:func:`load_config`,
:func:`apply_override` for ``--set``, :func:`experiment`, :func:`write_results`); this module
only logs.

Initialisation from the data alone: roll and pitch levelled from the accelerometer's mean over a
still start (``level_s`` seconds, checked still against the fixes' speed), carried to the start by
the gyro; the graph starts at the first fixed (Q = 1) epoch faster than ``yaw_min_speed_mps`` (yaw:
the body x-axis turned onto that epoch's velocity heading; position and velocity: that epoch);
bias prior zero (or ``bias_prior = "still"``: the still start's mean gyro, and the accelerometer's
excess over normal gravity along the specific force; with ``still_se_k`` the gyro part held to that
many standard errors of the still mean). ``start_at = "still"`` starts the graph at the still start
instead (levelled there, turned by the heading the track gives, zero velocity; every fix from the
first on), so the still start and the first metres of motion tell tilt, a horizontal accelerometer
bias and the gyro bias apart before the first outage; an outage before the heading's epoch is
refused (its scores would use later fixes). ``prior_yaw_deg`` holds the start's heading apart from
its tilt (a hand-held device does not point where it walks). Timing from the data, outside the
outages, no truth: ``delay_from = "fixes"`` measures the IMU's time offset (:mod:`imu_learn.fuse.start.delay`,
the specific force's norm against the fixes' second differences) in place of ``delay_s``;
``velocity_lag_from = "pos"`` measures how far the ``.pos`` velocities lag its positions
(:func:`imu_learn.fuse.factors.velocity.velocity_lag`) and ties each velocity to that instant. The fixes (RTKLIB
``.pos``, :mod:`imu_learn.fuse.aiding.rtklib`) enter with their own sigmas and lever arm; the outage
schedule is the peer's: ``duration_s`` outages every ``period_s`` from ``first_s`` after the first
GNSS epoch, each ending at least ``end_margin_s`` before its last. Every epoch inside an outage
is withheld; its fixed ones (Q = 1) are the truth. Scores, per outage: RMS, maximum and end
horizontal error of the antenna, live (the causal estimate at each withheld epoch's IMU sample, IMU
prediction from the last update) and smoothed (the batch solution, carried from the keyframe before
by the IMU with its smoothed bias); and the RMS at the used fixed epochs outside outages. Variants:
``raw`` and, for a wheeled vehicle, ``raw+nhc`` (:mod:`imu_learn.fuse.factors.nhc`).
Writes ``<out_dir>/results.json`` and ``<out_dir>/table.md`` (atomically).
"""
from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.data.config import resolve_data_root
from imu_learn.data.formats.gnss_imu import mounting_rotation, read_imu_log
from imu_learn.errors import ConfigError, InvalidInputError
from imu_learn.settings import from_dict, merge, nest, read_toml
from imu_learn.util.atomic import atomic_write_text

from ..aiding import GnssFixes, OutageWindow
from ..aiding.rtklib import RtkSolution, fixes_on_imu, normal_gravity, read_pos
from ..factors import chain
from ..factors.nhc import NhcSettings, calibrate_lever, nhc_callback
from ..factors.velocity import velocity_callback, velocity_lag
from ..graph import IncrementalFusion, feed, samples_of
from ..noise import ImuNoise
from ..output import write_json
from ..score import error_stats
from ..settings import FusionSettings, PriorSigmas
from ..start.delay import imu_delay
from ..start.track import GnssStartSettings, gnss_start

log = logging.getLogger(__name__)
VARIANTS = ("raw", "raw+nhc")
KIND = "gnss-outages"  # a fuse config's ``kind`` for this experiment
OMEGA_EARTH = 7.292115e-5  # rad/s
MIN_BIAS_SIGMA = 1e-6  # rad/s: the least gyro bias prior sigma (a still start of identical rows has none)


@dataclass
class NoiseCfg:
    gyro_noise_density: float = 1e-3  # rad/s/sqrt(Hz)
    acc_noise_density: float = 1e-2  # m/s^2/sqrt(Hz)
    gyro_random_walk: float = 1e-4  # rad/s^2/sqrt(Hz)
    acc_random_walk: float = 1e-3  # m/s^3/sqrt(Hz)
    source: str = "config"


@dataclass(frozen=True)
class NhcCfg(NhcSettings):
    """The ``[nhc]`` table: :class:`~imu_learn.fuse.factors.nhc.NhcSettings`, and where its lever comes
    from: ``lever_from = "config"``, ``lever`` as given; ``"raw"``, fitted on the ``raw`` variant's
    smoothed estimate (which used only the fixes outside the outages) by
    :func:`imu_learn.fuse.factors.nhc.calibrate_lever`."""

    max_yaw_rate_dps: float = 1e9
    lever_from: str = "config"


@dataclass
class OutageCfg:
    first_s: float = 40.0
    duration_s: float = 15.0
    period_s: float = 45.0
    end_margin_s: float = 30.0


@dataclass
class PeerCfg:
    """The peer's figures (mean over its outages, or per outage), quoted from the issue, for the table."""

    label: str = ""
    live_rms_m: List[float] = field(default_factory=list)
    live_max_m: List[float] = field(default_factory=list)
    live_end_m: List[float] = field(default_factory=list)
    smoothed_rms_m: List[float] = field(default_factory=list)
    smoothed_max_m: List[float] = field(default_factory=list)
    outside_rms_m: float = float("nan")
    per_outage: bool = False


@dataclass
class GnssRunConfig:
    kind: str = KIND  # what routes a config here (imu-learn fuse --config)
    name: str = "fuse_gnss"
    data_root: str = ""
    out_dir: str = "reports/fuse_gnss"
    imu: str = ""
    tag: str = ""
    pos: str = ""
    wheeled: bool = True
    mounting_rpy_deg: List[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    delay_s: float = 0.0
    # "fixes": the IMU's time offset measured from the data (fuse/start/delay.py: the specific force's
    # norm against the fixes' second differences outside the outages), replacing delay_s
    delay_from: str = "config"
    lever_gnss_m: List[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    qualities: List[int] = field(default_factory=lambda: [1, 2])
    float_gain: float = 2.0
    sigma_floor_m: float = 0.0
    # > 0: the fixes' velocity columns as velocity factors with this sigma [m/s] (times float_gain
    # for float epochs), as the peer's EKF uses them; the antenna's rotation-induced velocity
    # (omega x lever, ~cm/s with these lever arms) is neglected. 0: positions only.
    velocity_sigma_mps: float = 0.0
    # when the velocities belong [s]: at t_epoch - velocity_lag_s; velocity_lag_from = "pos": that lag
    # measured from the .pos alone (fuse/factors/velocity.py: velocity_lag), "config": velocity_lag_s
    velocity_lag_s: float = 0.0
    velocity_lag_from: str = "config"
    level_s: float = 10.0
    still_max_speed_mps: float = 0.1
    yaw_min_speed_mps: float = 1.0
    start_at: str = "track"  # or "still" (:class:`~imu_learn.fuse.start.track.GnssStartSettings`)
    bias_prior: str = "zero"
    keyframe_hz: float = 10.0
    lag_s: float = 10.0
    resolve_after_s: float = 2.0
    earth_rate: bool = True
    prior_rot_deg: float = 2.0
    # the start's heading [deg] apart from its tilt; 0: prior_rot_deg about every axis
    prior_yaw_deg: float = 0.0
    prior_pos_m: float = 0.05
    prior_vel_mps: float = 0.1
    prior_bias_gyro: float = 0.01
    # bias_prior = "still" and > 0: the gyro bias prior's sigma is this many standard errors of the
    # still start's mean gyro (its largest axis), not prior_bias_gyro
    still_se_k: float = 0.0
    prior_bias_acc: float = 0.3
    variants: List[str] = field(default_factory=lambda: ["raw"])
    noise: NoiseCfg = field(default_factory=NoiseCfg)
    nhc: NhcCfg = field(default_factory=NhcCfg)
    outages: OutageCfg = field(default_factory=OutageCfg)
    peer: PeerCfg = field(default_factory=PeerCfg)

    def root(self) -> Path:
        return Path(self.data_root or ".")


def load_config(path: Path, data_root: Optional[str] = None) -> GnssRunConfig:
    cfg = from_dict(GnssRunConfig, read_toml(Path(path)))
    cfg.data_root = resolve_data_root(data_root, cfg.data_root)  # the one data-root rule
    if cfg.kind != KIND:
        raise ConfigError(f"{path}: kind: {KIND!r} for this experiment, got {cfg.kind!r}")
    check(cfg, path)
    return cfg


def check(cfg: GnssRunConfig, path: object = "config") -> None:
    """The config's values checked (after overrides too)."""
    bad = [v for v in cfg.variants if v not in VARIANTS]
    if bad or not cfg.variants:
        raise ConfigError(f"{path}: variants: each one of {', '.join(VARIANTS)}, got {cfg.variants}")
    if "raw+nhc" in cfg.variants and not cfg.wheeled:
        raise ConfigError(f"{path}: variants: raw+nhc needs wheeled = true (NHC holds for wheeled vehicles only)")
    if cfg.nhc.lever_from not in ("config", "raw"):
        raise ConfigError(f"{path}: nhc.lever_from: 'config' or 'raw', got {cfg.nhc.lever_from!r}")
    if cfg.nhc.lever_from == "raw" and "raw+nhc" in cfg.variants and cfg.variants[0] != "raw":
        raise ConfigError(f"{path}: nhc.lever_from = 'raw' needs variants to start with 'raw'")
    if cfg.delay_from not in ("config", "fixes"):
        raise ConfigError(f"{path}: delay_from: 'config' or 'fixes', got {cfg.delay_from!r}")
    if cfg.velocity_lag_from not in ("config", "pos"):
        raise ConfigError(f"{path}: velocity_lag_from: 'config' or 'pos', got {cfg.velocity_lag_from!r}")
    if not (math.isfinite(cfg.velocity_lag_s) and cfg.velocity_lag_s >= 0):
        raise ConfigError(f"{path}: velocity_lag_s: a time >= 0 s, got {cfg.velocity_lag_s!r}")
    if cfg.start_at not in ("track", "still"):
        raise ConfigError(f"{path}: start_at: 'track' or 'still', got {cfg.start_at!r}")
    if cfg.bias_prior not in ("zero", "still"):
        raise ConfigError(f"{path}: bias_prior: 'zero' or 'still', got {cfg.bias_prior!r}")
    if not cfg.imu or not cfg.pos:
        raise ConfigError(f"{path}: imu and pos (paths relative to the data root) are required")


@dataclass(frozen=True)
class EarthImuNoise(ImuNoise):
    """:class:`ImuNoise` with the Earth's rate (ENU, rad/s) given to GTSAM as ``omegaCoriolis``."""

    omega_earth: Tuple[float, float, float] = (0.0, 0.0, 0.0)

    def gtsam_params(self, gravity: float):
        p = super().gtsam_params(gravity)
        p.setOmegaCoriolis(np.asarray(self.omega_earth, dtype=np.float64))
        return p


def outage_windows(sol: RtkSolution, o: OutageCfg) -> List[OutageWindow]:
    """The peer's schedule, in seconds from the first epoch: from ``first_s``, every ``period_s``, each
    ending by the last epoch - ``end_margin_s`` (the peer's ``end_coast``)."""
    t0, t_last = int(sol.t_ns[0]), int(sol.t_ns[-1])
    out = []
    s = o.first_s
    while t0 + s * 1e9 + o.duration_s * 1e9 <= t_last - o.end_margin_s * 1e9:
        out.append(OutageWindow(s, o.duration_s))
        s += o.period_s
    return out


def _carry(params, nav, bias, gyro, acc, t_ns, a: int, b: int):
    """``nav`` at sample ``a`` carried by the IMU (bias ``bias``) to sample ``b`` >= a."""
    import gtsam

    if b == a:
        return nav
    pim = gtsam.PreintegratedCombinedMeasurements(params, bias)
    for i in range(a, b):
        pim.integrateMeasurement(acc[i], gyro[i], (int(t_ns[i + 1]) - int(t_ns[i])) * 1e-9)
    return pim.predict(nav, bias)


@dataclass
class Drive:
    """What every variant fuses: the IMU from the start sample on (``t``, ``gyro``, ``acc``), the fixes
    used (outside the outages) and their solution ``sol``, the ``start`` (:func:`gnss_start`), the noise
    model and gravity."""

    t: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray
    fixes: GnssFixes
    sol: RtkSolution
    start: Dict[str, object]
    noise: ImuNoise
    gravity: float
    velocity_lag_s: float = 0.0  # the velocities belong to t_epoch - this [s] (fuse/factors/velocity.py)


def run_variant(cfg: GnssRunConfig, variant: str, drive: Drive, eval_idx: np.ndarray, diag_idx: Sequence[int] = (),
                nhc_lever: Optional[np.ndarray] = None) -> Dict[str, object]:
    """Fuse the drive and return the antenna's live and smoothed ENU position at the samples
    ``eval_idx`` (indices into ``drive.t``), the live and smoothed attitude and velocity at the samples
    ``diag_idx`` (the outage starts), and the run's counts and time."""
    import gtsam

    t, gyro, acc, fixes, sol = drive.t, drive.gyro, drive.acc, drive.fixes, drive.sol
    start, noise, gravity = drive.start, drive.noise, drive.gravity

    still = cfg.bias_prior == "still"
    # from a still start the gyro bias is its mean there, known to its standard error
    bias_gyro = (max(cfg.still_se_k * float(np.max(start["gyro_still_se"])), MIN_BIAS_SIGMA)
                 if still and cfg.still_se_k > 0 else cfg.prior_bias_gyro)
    prior = PriorSigmas(math.radians(cfg.prior_rot_deg), cfg.prior_pos_m, cfg.prior_vel_mps, bias_gyro,
                        cfg.prior_bias_acc, math.radians(cfg.prior_yaw_deg) if cfg.prior_yaw_deg > 0 else None)
    bias0 = np.r_[start["gyro_still"], start["acc_bias_still"]] if still else None
    callbacks = []
    if cfg.velocity_sigma_mps > 0:
        callbacks.append(velocity_callback(fixes, sol, cfg.velocity_sigma_mps, cfg.float_gain, drive.velocity_lag_s))
    if variant == "raw+nhc":
        lever_nhc = tuple(cfg.nhc.lever) if nhc_lever is None else tuple(float(x) for x in nhc_lever)
        callbacks.append(nhc_callback(replace(cfg.nhc, lever=lever_nhc), gyro))
    extra = chain(*callbacks)
    t0 = time.perf_counter()
    settings = FusionSettings(noise, gravity, cfg.keyframe_hz, prior, resolve_after_s=cfg.resolve_after_s,
                              lag_s=cfg.lag_s)
    inc = IncrementalFusion(t, (start["R0"], start["p0"], start["v0"]), [fixes], settings, bias0, predict_between=True,
                            extra_factors=extra)
    want = set(int(i) for i in eval_idx)
    live: Dict[int, np.ndarray] = {}
    diag = set(int(i) for i in diag_idx)
    live_nav: Dict[int, tuple] = {}
    lever = np.asarray(cfg.lever_gnss_m, dtype=np.float64)

    def observe(sample, st) -> None:
        s = sample[0]
        if s in want:
            live[s] = st.p + st.R @ lever
        if s in diag:  # with the bias the live prediction uses
            live_nav[s] = (st.R.copy(), st.v.copy(), inc.bias)

    feed(inc, samples_of(gyro, acc), observe)
    res = inc.smooth()
    seconds = time.perf_counter() - t0
    params = noise.gtsam_params(gravity)
    kf = res.kf_idx
    smoothed, smoothed_nav = {}, {}
    for s in want | diag:
        k = int(np.searchsorted(kf, s, side="right")) - 1
        pose = gtsam.Pose3(gtsam.Rot3(res.smoothed_R[k]), res.smoothed_p[k])
        b = res.smoothed_bias[k]
        nav = _carry(params, gtsam.NavState(pose, res.smoothed_v[k]), gtsam.imuBias.ConstantBias(b[3:], b[:3]),
                     gyro, acc, t, int(kf[k]), s)
        smoothed[s] = nav.position() + nav.attitude().matrix() @ lever
        smoothed_nav[s] = (nav.attitude().matrix(), nav.velocity(), np.asarray(b, dtype=np.float64))
    return {"live": live, "smoothed": smoothed, "live_nav": live_nav, "smoothed_nav": smoothed_nav, "result": res, "seconds": seconds, "counts": dict(res.counts),
            "bias_end": res.smoothed_bias[-1].tolist(), "keyframes": int(len(kf))}


def start_error(live: tuple, smoothed: tuple, f_mean: np.ndarray, duration_s: float) -> Dict[str, float]:
    """What the live state at an outage's start gets wrong, taking the smoothed state there as the
    reference (each ``(R, v, bias (6,) gyro then acc)``): tilt and yaw [deg] (world-frame rotation
    from smoothed to live), horizontal velocity [m/s], the horizontal error of the specific force
    ``f_mean`` (body, the samples just before) resolved in the world with each state's attitude
    and accelerometer bias [m/s^2] (tilt and bias together), and the drift over the outage these
    alone give: ``|da| t^2 / 2`` and ``|dv| t`` [m]."""
    (R_l, v_l, b_l), (R_s, v_s, b_s) = live, smoothed
    rv = Rotation.from_matrix(R_l @ R_s.T).as_rotvec()
    dv = float(np.linalg.norm((np.asarray(v_l) - np.asarray(v_s))[:2]))
    da = float(np.linalg.norm((R_l @ (f_mean - b_l[3:]) - R_s @ (f_mean - b_s[3:]))[:2]))
    return {"tilt_deg": math.degrees(float(np.hypot(rv[0], rv[1]))), "yaw_deg": math.degrees(float(rv[2])),
            "dv_mps": dv, "da_mps2": da, "drift_acc_m": 0.5 * da * duration_s ** 2, "drift_vel_m": dv * duration_s}


def experiment(cfg: GnssRunConfig) -> Dict[str, object]:
    root = cfg.root()
    imu_path = root / cfg.imu
    M = mounting_rotation(cfg.mounting_rpy_deg)
    sol = read_pos(root / cfg.pos)
    gravity = normal_gravity(sol.origin_llh[0], sol.origin_llh[2])
    tag = (root / cfg.tag) if cfg.tag else None
    delay: Dict[str, object] = {"delay_s": cfg.delay_s, "from": "config"}
    if cfg.delay_from == "fixes":
        # from the data (no attitude, no truth), on the fixed epochs outside the outages
        raw_log = read_imu_log(imu_path, tag, M, 0.0)
        outside = np.ones(len(sol.t_ns), bool)
        for w in outage_windows(sol, cfg.outages):
            a, b = w.bounds_ns(int(sol.t_ns[0]))
            outside &= ~((sol.t_ns >= a) & (sol.t_ns < b))
        est = imu_delay(raw_log.imu.t_ns, raw_log.imu.acc, sol, gravity, use=outside)
        delay = {"from": "fixes", **asdict(est)}
        log.info("%s: the IMU's time offset from the fixes %+.3f s (specific-force norm residual %.3f m/s^2, %.3f at "
                 "0 s; %d epochs); the config's delay_s %+.3f s not used", cfg.name, est.delay_s, est.rms_mps2,
                 est.rms_at_zero_mps2, est.epochs, cfg.delay_s)
    imu_log = read_imu_log(imu_path, tag, M, float(delay["delay_s"]))
    lat = math.radians(sol.origin_llh[0])
    noise = EarthImuNoise(cfg.noise.gyro_noise_density, cfg.noise.acc_noise_density, cfg.noise.gyro_random_walk,
                          cfg.noise.acc_random_walk, source=cfg.noise.source,
                          omega_earth=(0.0, OMEGA_EARTH * math.cos(lat), OMEGA_EARTH * math.sin(lat))
                          if cfg.earth_rate else (0.0, 0.0, 0.0))
    start = gnss_start(imu_log.imu, sol, gravity, GnssStartSettings(cfg.level_s, cfg.still_max_speed_mps,
                                                                    cfg.yaw_min_speed_mps, tuple(cfg.lever_gnss_m),
                                                                    cfg.start_at))
    s0 = int(start["s0"])
    t, gyro, acc = imu_log.imu.t_ns[s0:], imu_log.imu.gyro[s0:], imu_log.imu.acc[s0:]
    windows = [w.bounds_ns(int(sol.t_ns[0])) for w in outage_windows(sol, cfg.outages)]  # [start, end) ns
    vel_lag: Dict[str, object] = {"lag_s": cfg.velocity_lag_s, "from": "config"}
    if cfg.velocity_lag_from == "pos" and cfg.velocity_sigma_mps > 0:
        # from the .pos alone (its fixed positions' own differences; no IMU, no truth), on the epochs
        # outside the outages; a velocity ahead of its epoch (< 0) is not used (it would need later keyframes)
        outside = np.ones(len(sol.t_ns), bool)
        for a, b in windows:
            outside &= ~((sol.t_ns >= a) & (sol.t_ns < b))
        lag = velocity_lag(sol, use=outside)
        vel_lag = {"from": "pos", **asdict(lag), "lag_s": max(lag.lag_s, 0.0), "measured_s": lag.lag_s}
        log.info("%s: the velocities lag the positions by %.3f s (horizontal RMS against the positions' central "
                 "differences %.3f -> %.3f m/s over %d epochs)", cfg.name, lag.lag_s, lag.rms_before_mps,
                 lag.rms_after_mps, lag.epochs)
    if windows and (windows[0][0] - int(sol.t_ns[0])) * 1e-9 < start["heading_s_after_first_epoch"]:
        raise InvalidInputError(f"{cfg.name}: the first outage starts before the start's heading is known "
                                f"({start['heading_s_after_first_epoch']:.2f} s): its scores would use later fixes")
    all_fixes = fixes_on_imu(sol, t, cfg.lever_gnss_m, cfg.qualities, cfg.float_gain, sigma_floor_m=cfg.sigma_floor_m)
    truth_all = fixes_on_imu(sol, t, cfg.lever_gnss_m, (1,), sigma_floor_m=cfg.sigma_floor_m)
    ts_fix = t[all_fixes.idx]
    in_out = np.zeros(len(ts_fix), bool)
    for a, b in windows:
        in_out |= (ts_fix >= a) & (ts_fix < b)
    fixes = all_fixes.select(~in_out, dropped_outage=int(in_out.sum()))
    ts_truth = t[truth_all.idx]
    which = np.full(len(ts_truth), -1)
    for w, (a, b) in enumerate(windows):
        which[(ts_truth >= a) & (ts_truth < b)] = w
    eval_idx = truth_all.idx
    diag_idx = [int(min(np.searchsorted(t, a), len(t) - 1)) for a, _b in windows]
    log.info("%s: start %.2f s after the first epoch, %d outages, %d fixes used, %d withheld", cfg.name,
             start["start_s_after_first_epoch"], len(windows), len(fixes), int(in_out.sum()))
    runs = {}
    nhc_lever, nhc_fit, raw_res = None, None, None
    for variant in cfg.variants:
        if variant == "raw+nhc" and cfg.nhc.lever_from == "raw":
            if raw_res is None:
                raise ConfigError("nhc.lever_from = 'raw' needs the 'raw' variant to run first")
            half = max(1, int(round(0.1 * imu_log.rate_hz)))
            w = np.array([gyro[max(s - half, 0):s + half].mean(axis=0) for s in raw_res.kf_idx]) \
                - raw_res.smoothed_bias[:, :3]
            try:
                nhc_lever, resid, used = calibrate_lever(raw_res.smoothed_R, raw_res.smoothed_v, w)
                nhc_fit = {"lever_m": nhc_lever.tolist(), "lateral_residual_std_mps": resid, "keyframes": used}
                log.info("%s: NHC lever from the raw smoothed estimate %s m (lateral residual %.3f m/s)", cfg.name,
                         np.round(nhc_lever, 3).tolist(), resid)
            except InvalidInputError as e:  # e.g. a straight drive: keep the config's lever
                nhc_lever, nhc_fit = None, {"lever_m": list(cfg.nhc.lever), "fallback": str(e)}
                log.warning("%s: %s; NHC lever from the config %s", cfg.name, e, cfg.nhc.lever)
        r = run_variant(cfg, variant, Drive(t, gyro, acc, fixes, sol, start, noise, gravity, float(vel_lag["lag_s"])),
                        eval_idx, diag_idx,
                        nhc_lever if variant == "raw+nhc" else None)
        if variant == "raw":
            raw_res = r["result"]
        out: Dict[str, object] = {"seconds": r["seconds"], "counts": r["counts"], "keyframes": r["keyframes"],
                                  "bias_end_gyro_acc": r["bias_end"],
                                  "nhc_lever_fit": nhc_fit if variant == "raw+nhc" else None,
                                  "at_outage_start": [start_error(r["live_nav"][s], r["smoothed_nav"][s],
                                                                  acc[max(s - 100, 0):s + 1].mean(axis=0),
                                                                  cfg.outages.duration_s) for s in diag_idx]}
        for kind in ("live", "smoothed"):
            est = np.array([r[kind][int(s)] for s in eval_idx])
            herr = np.linalg.norm(est[:, :2] - truth_all.p[:, :2], axis=1)
            per = [dict(error_stats(herr[which == w]), start_s=(a - int(sol.t_ns[0])) * 1e-9)
                   for w, (a, _b) in enumerate(windows)]
            outside = herr[which < 0]
            out[kind] = {"outages": per,
                         "mean": {k: float(np.nanmean([p[k] for p in per])) for k in ("rms_m", "max_m", "end_m")},
                         "worst_end_m": float(np.nanmax([p["end_m"] for p in per])),
                         "outside_rms_m": float(np.sqrt(np.mean(outside ** 2))) if len(outside) else float("nan")}
        runs[variant] = out
        log.info("%s %s: live mean end %.2f m, smoothed mean rms %.2f m, %.1f s", cfg.name, variant,
                 out["live"]["mean"]["end_m"], out["smoothed"]["mean"]["rms_m"], r["seconds"])
    return {"name": cfg.name, "config": asdict(cfg), "gravity": gravity, "origin_llh": list(sol.origin_llh),
            "imu": {"path": cfg.imu, "rate_hz": imu_log.rate_hz, "samples": len(imu_log.imu.t_ns),
                    "skipped_lines": list(imu_log.skipped_lines), "clock_scale": imu_log.clock_scale},
            "gnss": {"path": cfg.pos, "epochs": len(sol), "q_counts": {int(q): int((sol.q == q).sum())
                                                                      for q in np.unique(sol.q)},
                     "fixes_used": len(fixes), "withheld": int(in_out.sum()), "truth_in_outages": int((which >= 0).sum())},
            "velocity_lag": vel_lag, "imu_delay": delay,
            "start": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in start.items()},
            "outages_s": [((a - int(sol.t_ns[0])) * 1e-9, (b - a) * 1e-9) for a, b in windows],
            "runs": runs}


def _f(x: float) -> str:
    return "-" if x is None or not np.isfinite(x) else f"{x:.2f}"


def table(res: Dict[str, object], cfg: GnssRunConfig) -> str:
    """The markdown table: ours (each variant) beside the peer's figures."""
    pr = cfg.peer
    lines = [f"# {res['name']}: GNSS/IMU with {len(res['outages_s'])} simulated 15 s outages", "",
             "Horizontal error of the antenna against the withheld fixed (Q = 1) RTK epochs [m]. Live: the causal "
             "estimate; smoothed: our batch solution / the peer's backward rewrite. No ground truth at run time.", ""]
    per_outage = pr.per_outage
    hdr = "| estimator | outage | live RMS | live max | live end | smoothed RMS | smoothed max | outside outages RMS (live / smoothed) |"
    lines += [hdr, "|---|---|---|---|---|---|---|---|"]
    for variant, r in res["runs"].items():
        rows = ([(f"{i + 1}", r["live"]["outages"][i], r["smoothed"]["outages"][i]) for i in range(len(res["outages_s"]))]
                if per_outage else [])
        rows.append(("mean", r["live"]["mean"], r["smoothed"]["mean"]))
        for name, lv, sm in rows:
            out = f"{_f(r['live']['outside_rms_m'])} / {_f(r['smoothed']['outside_rms_m'])}" if name == "mean" else ""
            lines.append(f"| ours {variant} | {name} | {_f(lv['rms_m'])} | {_f(lv['max_m'])} | {_f(lv['end_m'])} | "
                         f"{_f(sm['rms_m'])} | {_f(sm['max_m'])} | {out} |")
        lines.append(f"| ours {variant} | worst end | | | {_f(r['live']['worst_end_m'])} | | | |")
    if pr.live_rms_m:
        names = [str(i + 1) for i in range(len(pr.live_rms_m))] if per_outage else ["mean"]
        for i, name in enumerate(names):
            out = _f(pr.outside_rms_m) if i == len(names) - 1 else ""
            lines.append(f"| peer ({pr.label}) | {name} | {_f(pr.live_rms_m[i])} | {_f(pr.live_max_m[i])} | "
                         f"{_f(pr.live_end_m[i])} | {_f(pr.smoothed_rms_m[i])} | {_f(pr.smoothed_max_m[i])} | {out} |")
        lines += ["", "Goals: live error at the outage end at most half the peer's; smoothed at most the peer's.", ""]
        for variant, r in res["runs"].items():
            if per_outage:
                ends = [o["end_m"] for o in r["live"]["outages"]]
                sms = [o["rms_m"] for o in r["smoothed"]["outages"]]
            else:
                ends, sms = [r["live"]["mean"]["end_m"]], [r["smoothed"]["mean"]["rms_m"]]
            ok_end = all(e <= 0.5 * p for e, p in zip(ends, pr.live_end_m))
            ok_sm = all(e <= p for e, p in zip(sms, pr.smoothed_rms_m))
            lines.append(f"- {variant}: end <= half the peer's: {'met' if ok_end else 'missed'}; smoothed RMS <= the "
                         f"peer's: {'met' if ok_sm else 'missed'}")
    lines += ["", "What the live state gets wrong at each outage start (against the smoothed state there): tilt, "
              "yaw, horizontal velocity dv, the horizontal specific-force error da (attitude and accelerometer bias "
              "together), and the drift over the outage that da (|da| t^2 / 2) and dv (|dv| t) alone give.", "",
              "| estimator | outage | tilt [deg] | yaw [deg] | dv [m/s] | da [m/s^2] | drift from da [m] | drift from dv [m] | live end [m] |",
              "|---|---|---|---|---|---|---|---|---|"]
    for variant, r in res["runs"].items():
        for i, (d, o) in enumerate(zip(r["at_outage_start"], r["live"]["outages"])):
            lines.append(f"| ours {variant} | {i + 1} | {d['tilt_deg']:.2f} | {d['yaw_deg']:.2f} | {d['dv_mps']:.3f} | "
                         f"{d['da_mps2']:.3f} | {_f(d['drift_acc_m'])} | {_f(d['drift_vel_m'])} | {_f(o['end_m'])} |")
    st = res["start"]
    lines += ["", f"Start: {st['start_s_after_first_epoch']:.2f} s after the first GNSS epoch ({st.get('start_at', 'track')}; "
              f"heading from the epoch at {st.get('heading_s_after_first_epoch', st['start_s_after_first_epoch']):.2f} s, "
              f"{st['speed_mps']:.2f} m/s); IMU {res['imu']['rate_hz']:.1f} Hz; outages (start s, length s) "
              f"{[(round(a, 2), round(b, 2)) for a, b in res['outages_s']]}; "
              + "; ".join(f"{v}: {r['seconds']:.0f} s" for v, r in res["runs"].items()), ""]
    return "\n".join(lines)


def apply_override(cfg: GnssRunConfig, item: str) -> None:
    """``KEY=JSON`` (``nhc.sigma_lat=0.05``, ``lever_gnss_m=[0,0.05,0]``) applied to ``cfg``, checked
    as the config file's keys are."""
    key, sep, text = item.partition("=")
    if not sep:
        raise ConfigError(f"--set {item!r}: expected KEY=VALUE")
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        value = text
    key = key.strip()
    new = from_dict(GnssRunConfig, merge(asdict(cfg), nest({key: value})))
    top = key.split(".")[0]
    setattr(cfg, top, getattr(new, top))


def write_results(res: Dict[str, object], cfg: GnssRunConfig, out: Path) -> Tuple[Path, Path]:
    """``out``/results.json and ``out``/table.md, atomically; returns their paths."""
    out = Path(out)
    write_json(out / "results.json", res)
    atomic_write_text(out / "table.md", table(res, cfg))
    return out / "results.json", out / "table.md"


def summary_lines(res: Dict[str, object], cfg: GnssRunConfig) -> List[str]:
    """One line per variant: the live and smoothed means over the outages (what the CLI prints)."""
    lines = []
    for v, r in res["runs"].items():
        lv, sm = r["live"]["mean"], r["smoothed"]["mean"]
        lines.append(f"{cfg.name} {v}: live mean RMS/max/end {_f(lv['rms_m'])}/{_f(lv['max_m'])}/{_f(lv['end_m'])} m, "
                     f"smoothed RMS/max {_f(sm['rms_m'])}/{_f(sm['max_m'])} m, outside "
                     f"{_f(r['live']['outside_rms_m'])} m ({r['seconds']:.0f} s)")
    return lines

