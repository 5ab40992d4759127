"""``model.start = "calibrate"`` (the default run): the device profile of the run's own training
split, which the refiner then trains on top of.

:func:`calibrate_split` runs ``imu-learn calibrate``'s fit (:func:`imu_learn.calib.run.calibrate`:
the floor, gravity, the noise of the still stretches, the plausibility checks and the held-back
block) on the split's training segments, the validation segments held back, and writes
``profile.json`` and ``imu.yaml`` into ``RUN/profile/``, each sensor's floor terms chosen on held-out
blocks (``calibrate --select``, :mod:`imu_learn.calib.select`: the simplest level that no simpler one
beats on a held-out block in any cell). The run then starts from that file exactly
as from ``--model.start PATH/profile.json`` (:func:`imu_learn.train.trainer.profile_start`), so the
untrained model is the profile's floor and selection against it (``optim.select_reference =
"start"``) keeps the profile where no epoch beats it. The test split is never seen.

A profile that fails the plausibility checks stops the run (exit 2, the check named), as calibrate
does: no refiner is trained on top of a floor that would harm the data.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, List

from imu_learn.baselines.base import FitSettings
from imu_learn.calib.run import CalibInputs, CalibOptions, calibrate
from imu_learn.data.splits import Split, recording_name
from imu_learn.data.types import Segment
from imu_learn.errors import ConfigError

PROFILE_DIR = "profile"  # RUN/profile/{profile.json, imu.yaml}


def _usable(segs: List[Segment], window: int) -> List[Segment]:
    return [s for s in segs if len(s) > window + 1]


def calibrate_split(split: Split, run_dir: Path, settings: FitSettings, device: str,
                    progress: Callable[[str], None] = lambda s: None) -> Path:
    """The profile of ``split``'s training segments (validation held back) at
    ``run_dir/profile/profile.json``; kept when it already exists (a resumed or repeated run)."""
    out = Path(run_dir) / PROFILE_DIR
    path = out / "profile.json"
    if path.exists():
        return path
    w = settings.window
    train, val = _usable(list(split.train), w), _usable(list(split.val), w)
    if not train:
        raise ConfigError(f"model.start = calibrate: no training segment longer than one window ({w} samples)")
    inp = CalibInputs(train, val, [recording_name(s.name) for s in train], [recording_name(s.name) for s in val],
                      [], settings, device,
                      [{"split": "the run's training split; validation held back",
                        "train": [s.name for s in train], "val": [s.name for s in val]}])
    calibrate(inp, out, CalibOptions(plot=False, select=True), progress)
    return path
