"""Dataset formats: each module turns one layout on disk into ``ImuData`` + ``GroundTruth``.

The strict parsing of text formats happens in the Rust core; the modules here only find the files
of a layout and, for binary containers (HDF5, MAT), read arrays with h5py / scipy and hand them to
the same Rust alignment path.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Dict, Optional, Tuple

from imu_learn.errors import InvalidInputError
from imu_learn.types import GroundTruth, ImuData

from . import asl, blackbird, broad, kaist

Reader = Callable[..., Tuple[ImuData, GroundTruth]]

READERS: Dict[str, Reader] = {
    "euroc": asl.read_recording,
    "tum-vi": asl.read_recording,
    "asl": asl.read_recording,
    "blackbird": blackbird.read_recording,
    "broad": broad.read_recording,
    "kaist": kaist.read_recording,
}


def detect_format(path: Path) -> str:
    """Guess a recording's format from its layout."""
    if path.suffix == ".mat":
        return "broad"
    if (path / "data.hdf5").exists():
        return "blackbird"
    if (path / "sensor_data" / "xsens_imu.csv").exists():
        return "kaist"
    if (path / "mav0").is_dir() or path.name == "mav0" or path.suffix == ".csv":
        return "asl"
    raise InvalidInputError(
        f"{path}: cannot tell the dataset format from its layout; pass format= one of {sorted(READERS)}"
    )


def read_recording(
    path: Path, format: str = "auto", groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
) -> Tuple[ImuData, GroundTruth]:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    fmt = detect_format(path) if format == "auto" else format
    if fmt not in READERS:
        raise InvalidInputError(f"unknown format {format!r}; known: {sorted(READERS)} or 'auto'")
    return READERS[fmt](path, groundtruth=groundtruth, allow_float_timestamps=allow_float_timestamps)
