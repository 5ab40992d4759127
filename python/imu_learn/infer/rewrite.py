"""A recording written back in its own format with its IMU replaced: where the output goes, what is
refused before any work, and the steps (a device profile's floor, a model) applied in order. No
torch here: ``imu-learn refine --profile`` runs without it (a model's step is
:func:`imu_learn.infer.refiner.model_step`).

Each layout's module in :mod:`imu_learn.data.formats` writes its file back (a user's CSV in its own
columns and units); every file is written to a temporary file beside its target and renamed into
place (:mod:`imu_learn.util.atomic`). The input is never written: an OUT that resolves to the input
file (or, with ``copy_folder``, the input folder) is refused.

One more step lives here: :func:`measured` records what a step adds (for refine's guard,
:mod:`imu_learn.infer.guard`). The ``--bias`` step (the recording's own gyro bias, refine's and
navigate's) is the registry's: :mod:`imu_learn.infer.bias`.
:func:`summary_path` and :func:`write_summary` write refine's ``summary.json`` beside the output.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any, Callable, Dict, Optional, Sequence

import numpy as np

from imu_learn.data import formats
from imu_learn.data.formats import ImuSource
from imu_learn.errors import InvalidInputError
from imu_learn.infer.bias import Step, still_along_gravity  # noqa: F401  (their home is infer.bias)
from imu_learn.infer.guard import residual_rms
from imu_learn.util.atomic import atomic_write_text
from imu_learn.util.interrupts import held_interrupts
from imu_learn.util.staging import check_can_make

# file endings that name a data file, not a folder: an OUT ending in one other than the input's is refused
DATA_SUFFIXES = (".csv", ".txt", ".tum", ".hdf5", ".h5", ".mat", ".bag", ".mcap", ".db3", ".json", ".npz", ".npy")


def output_file(src: ImuSource, out: Path) -> Path:
    """The file to write for OUT: OUT itself when it names a file of the input's kind, else the
    input's relative path under the folder OUT."""
    if out.suffix.lower() == src.imu_file.suffix.lower() and not out.is_dir():
        return out
    return out / src.rel


def _same(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _inside(child: Path, parent: Path) -> bool:
    try:
        child.resolve().relative_to(parent.resolve())
        return True
    except ValueError:
        return False


def check_output(src: ImuSource, input: Path, output: Path, copy_folder: bool = False,
                 fill_covariance: bool = False) -> Path:
    """The file (or ROS 2 bag folder) that refining ``src`` (read from ``input``) into ``output``
    writes; every refusal is raised here, before any work."""
    input, output = Path(input), Path(output)
    if fill_covariance and src.fmt != formats.rosbag.NAME:
        raise InvalidInputError(f"--fill-covariance writes the covariance fields of a ROS bag's IMU messages; "
                                f"{input} is {src.fmt}, not a bag")
    if copy_folder and src.fmt == formats.rosbag.NAME:
        raise InvalidInputError("--copy-folder does not apply to ROS bags: the output bag holds every topic already")
    if copy_folder:
        if output.suffix.lower() == src.imu_file.suffix.lower() and not output.is_dir():
            raise InvalidInputError(f"--copy-folder needs OUT to be a folder, got {output}")
        if _same(output, src.root) or _inside(output, src.root) or _inside(src.root, output):
            raise InvalidInputError(f"--copy-folder: OUT {output} and the input folder {src.root} overlap")
        if output.exists() and (not output.is_dir() or any(output.iterdir())):
            raise InvalidInputError(f"--copy-folder: {output} exists and is not an empty folder")
    if src.fmt == formats.rosbag.NAME and (output / formats.rosbag.ROS2_METADATA).is_file():
        raise InvalidInputError(f"{output} exists already and is a ROS 2 bag (a bag folder is never replaced, nor "
                                "written into): remove it or give OUT a new name")
    own = src.imu_file.suffix.lower()
    if output.suffix.lower() in DATA_SUFFIXES and output.suffix.lower() != own and not output.is_dir():
        raise InvalidInputError(f"OUT {output} names a {output.suffix} file, but refine writes the input's own format "
                                f"({src.fmt}, a {own or 'folder'} file): give OUT ending in {own} or a folder")
    target = output_file(src, output)
    if _same(target, src.imu_file) or _same(output, input):
        raise InvalidInputError(f"refusing to overwrite the input: OUT {output} is the input {input}")
    check_can_make(target.parent, str(target), "give OUT a place you can write")  # before the work
    summary = summary_path(output, target)
    if target.exists() and not summary.is_file():  # a file of the user's (another recording's IMU, a log)
        raise InvalidInputError(f"{target} exists and is not an earlier refine output (no {summary.name} beside it): "
                                "refine replaces only its own outputs; remove it or give OUT a new name")
    return target


def rewrite_recording(src: ImuSource, input: Path, output: Path, steps: Sequence[Step], copy_folder: bool = False,
                      fill_covariance: bool = False, then: Callable[[Path], None] = lambda target: None) -> Path:
    """``src`` with its IMU passed through ``steps`` in order, written to ``output`` in the input's
    own format (``copy_folder``: the whole input folder copied first; ``fill_covariance``: a bag's
    IMU covariance fields get the last step's variances). ``then(target)`` writes what goes beside it
    (refine's summary): the IMU and it are written with Ctrl-C held, so an interrupted rerun leaves both
    files of the previous run or both of this one, never this run's IMU beside that run's summary.
    Returns the file (or ROS 2 bag folder) written."""
    target = check_output(src, input, output, copy_folder, fill_covariance)
    gyro, acc, var = src.gyro, src.acc, None
    for step in steps:
        gyro, acc, v = step(src.t_ns, gyro, acc)
        var = v if v is not None else var
    if fill_covariance and var is None:
        raise InvalidInputError("--fill-covariance needs a model with a covariance head")
    if copy_folder:  # into a new or empty folder (check_output): nothing of a previous run to mix with
        shutil.copytree(src.root, Path(output), dirs_exist_ok=True)
    with held_interrupts():
        if fill_covariance:
            formats.rosbag.write_imu(src, target, gyro, acc, variances=var)
        else:
            formats.write_imu(src, target, gyro, acc)
        then(target)
    return target


def measured(step: Step, sink: Dict[str, Any]) -> Step:
    """``step``, recording in ``sink["residual_rms"]`` the RMS per axis of what it adds
    (:func:`imu_learn.infer.guard.residual_rms`)."""

    def wrapped(t_ns: Optional[np.ndarray], gyro: np.ndarray, acc: np.ndarray):
        g, a, v = step(t_ns, gyro, acc)
        sink["residual_rms"] = residual_rms(gyro, acc, g, a)
        return g, a, v

    return wrapped


def summary_path(out: Path, target: Path) -> Path:
    """Where refine's summary goes: ``OUT/summary.json`` when OUT is a folder holding the output,
    else ``OUT.summary.json`` beside the file (or ROS 2 bag folder) written."""
    out, target = Path(out), Path(target)
    if target.resolve() != out.resolve() and _inside(target, out):
        return out / "summary.json"
    return out.with_name(out.name + ".summary.json")


def write_summary(path: Path, summary: Dict[str, Any]) -> None:
    """``summary`` as JSON, atomically (NaN and inf as null)."""

    def plain(x: Any) -> Any:
        if isinstance(x, dict):
            return {str(k): plain(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [plain(v) for v in x]
        if isinstance(x, np.ndarray):
            return plain(x.tolist())
        if isinstance(x, np.bool_):
            return bool(x)
        if isinstance(x, (np.floating, float)):
            return float(x) if np.isfinite(x) else None
        if isinstance(x, np.integer):
            return int(x)
        return x

    atomic_write_text(Path(path), json.dumps(plain(summary), indent=2, allow_nan=False) + "\n")
