"""Dataset folders → recordings: which paths under a dataset root are recordings of which format."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from imu_learn.data.formats import FORMATS
from imu_learn.errors import InvalidInputError, NoRecordingsError

DATASETS = ("euroc", "tum-vi", "blackbird", "broad", "kaist", "fetch", "rosbag")

# What find_recordings searches for, in the words of the error for a folder without any.
LOOKED_FOR = {
    "euroc": "sequence folders holding mav0/ (mav0/imu0/data.csv)",
    "tum-vi": "sequence folders holding mav0/ (mav0/imu0/data.csv)",
    "blackbird": "folders holding data.hdf5",
    "broad": "*.mat trials",
    "kaist": "folders holding sensor_data/xsens_imu.csv",
    "fetch": "folders holding mav0/imu0/data.csv with the Fetch header (# timestamp, wx, wy, wz, ax, ay, az)",
    "rosbag": "ROS 1 .bag files and ROS 2 bag folders (holding metadata.yaml)",
}

# The ground-truth gap [s] a dataset's reference is known to need bridged, where the loader's 0.05 s
# (AlignOptions.max_gap_s) splits it: the default of `imu-learn labels` (--max-gap) and of
# `imu-learn groundtruth` (--max-gap-s) for that format. Fetch: its ~100 Hz motion capture drops frames
# (gaps up to 70 ms, 55-190 per recording longer than 50 ms, which leave 04_eight no 1 s segment and
# 08_origin 151 of 4585 samples); 0.1 s keeps every recording whole, the gaps bridged by interpolation
# (configs/fetch.toml).
MAX_GAP_S: Dict[str, float] = {"fetch": 0.1}


def dataset_max_gap_s(dataset: Optional[str]) -> Optional[float]:
    """The ground-truth gap [s] that ``dataset``'s reference needs (:data:`MAX_GAP_S`); None where the
    caller's own default holds."""
    return MAX_GAP_S.get(dataset) if dataset else None


def find_recordings(dataset: str, root: Path) -> List[Tuple[str, Path]]:
    """(name, path) of every recording of ``dataset`` under ``root``, sorted by name."""
    root = Path(root)
    if dataset not in DATASETS:
        raise InvalidInputError(f"unknown dataset {dataset!r}; known: {', '.join(DATASETS)}")
    if not root.exists():
        raise FileNotFoundError(2, "No such file or directory", str(root))
    found = FORMATS[dataset].find_recordings(root)
    recs = sorted((_name(p, root), p) for p in found)
    if not recs:
        raise NoRecordingsError(
            f"{root}: no {dataset} recordings found (looked for {LOOKED_FOR[dataset]} at any depth)", str(root)
        )
    return recs


def _name(path: Path, root: Path) -> str:
    rel = path.relative_to(root) if path != root else Path(path.name)
    stem = rel.with_suffix("") if rel.suffix in (".mat", ".bag") else rel
    return str(stem).replace(os.sep, "_") if str(stem) != "." else path.name



