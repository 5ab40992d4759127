"""Which recordings a run reads and how they are windowed: ``[data]`` of a run config. No torch."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import List, Optional

from imu_learn.core.batches import AugmentConfig, BatchConfig
from imu_learn.core.integration import PAPER_FRACTIONS
from imu_learn.settings import DATA_ROOT_ENV


def resolve_data_root(command_line: Optional[str] = None, config: Optional[str] = None) -> str:
    """The one data-root rule of every config (training, evaluate, fusion) and of ``imu-learn labels``:
    the command line's ``--data-root``, else the environment variable ``IMU_LEARN_DATA`` (when set and
    not empty), else the config's ``data_root``; "" when none is set."""
    return command_line or os.environ.get(DATA_ROOT_ENV, "") or config or ""


@dataclass
class RootConfig:
    """Where recordings are. ``path`` is a dataset folder (every recording under it is found, as
    ``just labels`` finds them) or one recording (an ASL folder, a Blackbird folder, a ``.mat``).
    ``format``: euroc, tum-vi, blackbird, broad, kaist, fetch, rosbag (``imu_topic`` / ``groundtruth_topic``)
    or csv-columns (a user's CSV: ``columns`` and the units, with its ``groundtruth``). ``groundtruth``: a separate TUM/ASL file,
    only for a ``path`` that is a single recording. Relative paths are taken from
    ``data.data_root`` when one is set, else from the working directory, else from the repository
    root."""

    path: str = ""
    format: str = "euroc"
    groundtruth: str = ""
    # Ground-truth stamps further apart than this split a recording (AlignOptions.max_gap_s);
    # raise it for sparse ground truth, e.g. 0.06 for EuRoC's 20 Hz ASL state files. Unset: the
    # format's own where its reference needs one (data.datasets.MAX_GAP_S: Fetch 0.1 s), else 0.05.
    max_gap_s: Optional[float] = None
    # Added to the ground truth's stamps (AlignOptions.gt_time_offset_s) where its clock is measured
    # to be off the IMU's (imu-learn groundtruth: a ground truth late by tau gets -tau).
    gt_time_offset_s: float = 0.0
    # format = "rosbag": the IMU and ground-truth topics (empty: each bag's only one).
    imu_topic: str = ""
    groundtruth_topic: str = ""
    # format = "csv-columns": a user's CSV (one recording, ``groundtruth`` its reference), read as the
    # commands' --columns / --time-unit / --gyro-unit / --acc-unit read it (docs/refine.md)
    columns: str = ""
    time_unit: str = "ns"
    gyro_unit: str = "rad/s"
    acc_unit: str = "m/s2"


@dataclass
class SplitConfig:
    """Sequence names per split. A name may carry a time block ``NAME[a:b]`` with fractions
    0 <= a < b <= 1 of the recording's duration; blocks of one recording in different splits must
    not overlap (checked). A name without a block is the whole recording."""

    train: List[str] = field(default_factory=lambda: ["MH_01_easy[0:0.8]"])
    val: List[str] = field(default_factory=lambda: ["MH_01_easy[0.8:1]"])
    test: List[str] = field(default_factory=lambda: ["V1_01_easy"])


def _default_roots() -> List[RootConfig]:
    # V1_01 against the ASL full state (EuRoC's ground truth, IMU frame, 20 Hz): its
    # groundtruth_pose.tum is ~5.5 deg off the IMU frame (README, "EuRoC ground truth").
    v1 = "datasets/euroc/V1_01_easy"
    return [RootConfig("datasets/euroc/MH_01_easy", "euroc"),
            RootConfig(v1, "euroc", f"{v1}/groundtruth_state_20hz.csv", max_gap_s=0.06)]


def _default_augment() -> AugmentConfig:
    # EuRoC's ADIS16448 datasheet-level noise (sensor.yaml) and biases a few times the device's.
    return AugmentConfig(
        gyro_noise_density=1.7e-4,
        acc_noise_density=2.0e-3,
        gyro_bias_max=0.02,
        acc_bias_max=0.2,
        gyro_bias_walk=1.9e-5,
        acc_bias_walk=3.0e-3,
    )


@dataclass
class DataConfig:
    # Folder that relative data.roots[i].path / .groundtruth are taken from (see
    # splits.resolve_data_path). Set by, highest first: --data-root DIR, the environment
    # variable IMU_LEARN_DATA (read by build_config), this value in the config file. Empty: paths
    # are taken from the working directory, else the repository root (the shipped crops).
    data_root: str = ""
    roots: List[RootConfig] = field(default_factory=_default_roots)
    split: SplitConfig = field(default_factory=SplitConfig)
    window: int = 200  # IMU samples per training window (1 s at 200 Hz)
    batch_size: int = 32  # paper: 32
    fractions: List[float] = field(default_factory=lambda: list(PAPER_FRACTIONS))  # paper: 20..100 %
    gravity: float = 9.81
    val_stride: int = 20  # start step of the fixed validation windows [samples]
    eval_stride: int = 10  # start step of the relative-pose-error windows on the test split
    startup_bias_s: float = 10.0  # seconds fitted by fit_startup_bias for the final table
    # Horizons [IMU samples] of the final held-out table (the paper's Table II uses 10). TUM-VI adds
    # 5 s and 20 s (1000, 4000 at 200 Hz): over short horizons its mocap orientation noise dominates.
    eval_horizons: List[int] = field(default_factory=lambda: [10, 200])
    augment: AugmentConfig = field(default_factory=_default_augment)
    # The device's own constant bias in the training and validation recordings: "keep" (the paper:
    # the labels then ask the model to remove it, so it learns the bias of the training flights) or
    # "remove" (one constant gyro and accelerometer bias per segment, fitted against its ground
    # truth over the whole segment, is subtracted before training: the model learns what is left,
    # and a bias at run time is the estimator's job, as the paper's footnote asks). Test sequences
    # are never changed.
    train_bias: str = "keep"
    # A label cache folder (``imu-learn labels <dataset> --out DIR``, e.g. "cache/euroc"; relative to
    # the working directory): the split's recordings are read from it, aligned, instead of parsing and
    # aligning the raw files. A recording it lacks, or whose source files or alignment settings
    # (format, ground-truth file, max_gap_s, gt_time_offset_s, topics) changed since it was cached, is
    # rebuilt into it, with a warning naming it. Empty: read the raw files.
    cache: str = ""

    def batch_config(self) -> BatchConfig:
        return BatchConfig(self.window, self.batch_size, tuple(self.fractions), self.gravity, self.augment)
