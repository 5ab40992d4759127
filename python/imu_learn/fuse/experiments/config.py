"""The fusion experiment's configuration (``configs/fuse_*.toml``): recordings x IMU inputs x
aiding scenarios. Keys and value types are checked as for ``imu_learn.fit`` configs
(:func:`imu_learn.train.config.from_dict`); paths of recordings are relative to the data root
(the one data-root rule, :func:`imu_learn.data.config.resolve_data_root`: ``--data-root``, else the
environment variable ``IMU_LEARN_DATA``, else the config's ``data_root``)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional

from imu_learn.baselines.base import Method
from imu_learn.baselines.registry import REGISTRY, load_method_class
from imu_learn.data.config import resolve_data_root
from imu_learn.errors import ConfigError
from imu_learn.settings import from_dict, read_toml

from ..aiding.outages import OutageWindow, windows
from ..inputs import FACTOR_INPUTS, INPUTS
from ..settings import DEFAULT_LAG_S

KINDS = ("position", "relative_pose", "leica")
# The first state of every run: "data" (fuse/start/data.py: levelled from the accelerometer, heading from
# yaw hypotheses fitted to the first fixes, or a gauge for relative aiding; no ground truth at run time)
# or "groundtruth" (pose and velocity of the first sample from ground truth: the controlled setting,
# labelled as such in every table).
INITS = ("data", "groundtruth")
BIAS_PRIORS = ("zero", "startup")


@dataclass
class RecordingSpec:
    path: str = ""
    format: str = "auto"
    groundtruth: str = ""  # relative to the data root; empty: the layout's own
    max_gap_s: float = 0.05
    # ROS bags: the IMU and ground-truth topics (empty: the bag's only one), and the position or
    # pose topic the "leica" scenarios take their real fixes from, with the body-frame lever arm of
    # the point it measures (a bag does not carry it).
    imu_topic: str = ""
    groundtruth_topic: str = ""
    aiding_topic: str = ""
    aiding_lever: List[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # Per-recording models, where the global ones saw this recording in training (empty: the global)
    checkpoint: str = ""
    traditional: str = ""
    methods_dir: str = ""
    covariance_checkpoint: str = ""


@dataclass
class ScenarioSpec:
    """One aiding setting. ``position``: GNSS-like fixes simulated from ground truth;
    ``relative_pose``: VO-like relative poses simulated from ground truth; ``leica``: the
    recording's own Leica laser tracker (real; recordings without one are skipped).
    ``outages``: [start_s, duration_s] windows (from the recording's first sample) without aiding."""

    name: str = ""
    kind: str = "position"
    rate_hz: float = 1.0  # leica: 0 keeps every fix (20 Hz)
    sigma_m: float = 0.1  # position / leica
    sigma_rot_deg: float = 0.1  # relative_pose
    sigma_trans_m: float = 0.01  # relative_pose
    outages: List[List[float]] = field(default_factory=list)
    time_offset_s: float = 0.0  # leica: added to the fixes' stamps (experiments/leica_agreement.py measures it)
    # The bias prior's mean: "zero", or "startup": each input's constant bias fitted against ground
    # truth on its first startup_bias_s seconds (the initialisation the evaluation's "start-up bias
    # removed" protocol assumes an estimator has, e.g. from a static start).
    bias_prior: str = "zero"
    startup_bias_s: float = 10.0
    # Wheeled platforms: the non-holonomic constraint (fuse/factors/nhc.py: no sideways or vertical velocity of
    # the body frame) at every keyframe, with these sigmas [m/s]; 0 = off.
    nhc_sigma_mps: float = 0.0

    def outage_windows(self) -> List[OutageWindow]:
        return windows(self.outages)


@dataclass
class NoiseSpec:
    """``source = "sensor.yaml"``: the recording's ``mav0/imu0/sensor.yaml`` (else these values)."""

    source: str = "sensor.yaml"
    gyro_noise_density: float = 1.6968e-4
    acc_noise_density: float = 2.0e-3
    gyro_random_walk: float = 1.9393e-5
    acc_random_walk: float = 3.0e-3


@dataclass
class FuseConfig:
    name: str = "fuse"
    data_root: str = ""
    out_dir: str = "reports"
    # Noise seeds of the simulated aiding: each simulated setting runs once per seed and the tables
    # give mean +- std over them; real aiding (Leica) runs once.
    seeds: List[int] = field(default_factory=lambda: [0])
    gravity: float = 9.81
    keyframe_hz: float = 10.0
    # The causal estimate's fixed-lag window [s] (imu_learn.fuse.graph; inf: iSAM2 over the whole
    # graph, whose cost grows with the square of the recording's length).
    lag_s: float = DEFAULT_LAG_S
    init: str = "data"  # INITS
    # init = "data" with position fixes: the heading's alignment window ends at the first fix this far
    # [m] (horizontally) from the first fix (fuse/start/data.py; a ground robot in a small room needs less)
    align_travel_m: float = 2.0
    inputs: List[str] = field(default_factory=lambda: ["raw", "proposed"])
    checkpoint: str = "models/euroc_adis16448.pt"  # for "proposed" (relative to the working directory)
    # For "traditional": the calibration `imu-learn evaluate` fitted on the train split
    # (<report>/methods/traditional.json).
    traditional: str = "reports/euroc_paper/methods/traditional.json"
    # For any other method of `imu-learn evaluate` that outputs IMU samples (e.g.
    # "gyro-denoise", "airimu-style"): <methods_dir>/<name>.pt, as evaluate wrote it.
    methods_dir: str = ""
    # For the "+learned-cov" inputs: a refiner checkpoint with a covariance head (model.covariance),
    # e.g. fitted with optim.trainable = "covariance" on the "proposed" checkpoint.
    covariance_checkpoint: str = ""
    # For "tlio-style" (raw IMU plus learned displacement factors, fuse/factors/displacement.py; its model is
    # <methods_dir>/tlio-style.pt): one factor per network window ending every this many seconds.
    displacement_update_s: float = 1.0
    recordings: List[RecordingSpec] = field(default_factory=list)
    scenarios: List[ScenarioSpec] = field(default_factory=list)
    noise: NoiseSpec = field(default_factory=NoiseSpec)

    def root(self) -> Path:
        return Path(self.data_root or ".")


def imu_methods() -> List[str]:
    """Every input name: raw, proposed, and each ``imu_learn.evaluate`` method whose output is IMU
    samples (its class has its own ``refine``; End-to-End regresses poses and is not one)."""
    names = list(INPUTS) + list(FACTOR_INPUTS)  # the raw IMU plus learned displacement factors
    for name in REGISTRY:
        if name in names or name == "raw":
            continue
        factory = load_method_class(name)
        cls = factory if isinstance(factory, type) or factory is None else type(factory())
        if cls is not None and cls.refine is not Method.refine:
            names.append(name)
    return names


def validate(cfg: FuseConfig) -> FuseConfig:
    bad = [i for i in cfg.inputs if i not in INPUTS]
    if bad:
        known = imu_methods()
        bad = [i for i in bad if i not in known]
        if bad:
            raise ConfigError(f"inputs: unknown or not IMU-producing {bad} (known: {', '.join(known)})")
    if not cfg.recordings:
        raise ConfigError("recordings: none given ([[recordings]] path = ...)")
    if not cfg.scenarios:
        raise ConfigError("scenarios: none given ([[scenarios]] name = ..., kind = ...)")
    if not cfg.seeds or len(set(cfg.seeds)) != len(cfg.seeds):
        raise ConfigError(f"seeds: one or more distinct integers, got {cfg.seeds}")
    if not cfg.keyframe_hz > 0:
        raise ConfigError(f"keyframe_hz: must be > 0, got {cfg.keyframe_hz}")
    if cfg.init not in INITS:
        raise ConfigError(f"init: must be one of {', '.join(INITS)}, got {cfg.init!r}")
    if not cfg.align_travel_m > 0:
        raise ConfigError(f"align_travel_m: must be > 0, got {cfg.align_travel_m}")
    if not cfg.lag_s > 0:
        raise ConfigError(f"lag_s: must be > 0 (inf: the whole graph), got {cfg.lag_s}")
    if not cfg.displacement_update_s > 0:
        raise ConfigError(f"displacement_update_s: must be > 0, got {cfg.displacement_update_s}")
    names = [s.name for s in cfg.scenarios]
    if len(set(names)) != len(names) or not all(names):
        raise ConfigError(f"scenarios: names must be given and unique, got {names}")
    for s in cfg.scenarios:
        if s.kind not in KINDS:
            raise ConfigError(f"scenarios.{s.name}.kind: must be one of {', '.join(KINDS)}, got {s.kind!r}")
        if s.rate_hz < 0 or (s.kind != "leica" and s.rate_hz == 0):
            raise ConfigError(f"scenarios.{s.name}.rate_hz: must be > 0, got {s.rate_hz}")
        if not s.nhc_sigma_mps >= 0:
            raise ConfigError(f"scenarios.{s.name}.nhc_sigma_mps: must be >= 0 (0 = off), got {s.nhc_sigma_mps}")
        if s.bias_prior not in BIAS_PRIORS:
            raise ConfigError(f"scenarios.{s.name}.bias_prior: must be one of {', '.join(BIAS_PRIORS)}, got {s.bias_prior!r}")
        for o in s.outages:
            if len(o) != 2 or o[1] <= 0:
                raise ConfigError(f"scenarios.{s.name}.outages: each is [start_s, duration_s > 0], got {o}")
    return cfg


def load(path: Optional[Path], data_root: Optional[str] = None) -> FuseConfig:
    d = read_toml(Path(path)) if path else {}
    cfg = from_dict(FuseConfig, d)
    cfg.data_root = resolve_data_root(data_root, cfg.data_root)  # the one data-root rule
    return validate(cfg)
