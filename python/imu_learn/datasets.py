"""Dataset folders → recordings: which paths under a dataset root are recordings of which format."""
from __future__ import annotations

import os
from pathlib import Path
from typing import List, Tuple

from imu_learn.errors import InvalidInputError

DATASETS = ("euroc", "tum-vi", "blackbird", "broad", "kaist")


def find_recordings(dataset: str, root: Path) -> List[Tuple[str, Path]]:
    """(name, path) of every recording of ``dataset`` under ``root``, sorted by name."""
    root = Path(root)
    if dataset not in DATASETS:
        raise InvalidInputError(f"unknown dataset {dataset!r}; known: {', '.join(DATASETS)}")
    if not root.exists():
        raise FileNotFoundError(2, "No such file or directory", str(root))
    if dataset in ("euroc", "tum-vi"):
        found = [p.parent for p in root.rglob("mav0") if p.is_dir()]
    elif dataset == "blackbird":
        found = [p.parent for p in root.rglob("data.hdf5")]
    elif dataset == "broad":
        found = list(root.rglob("*.mat"))
    else:
        found = [p.parent.parent for p in root.rglob("sensor_data/xsens_imu.csv")]
    recs = sorted((_name(p, root), p) for p in found)
    if not recs:
        raise InvalidInputError(f"{root}: no {dataset} recordings found")
    return recs


def _name(path: Path, root: Path) -> str:
    rel = path.relative_to(root) if path != root else Path(path.name)
    stem = rel.with_suffix("") if rel.suffix == ".mat" else rel
    return str(stem).replace(os.sep, "_") if str(stem) != "." else path.name



