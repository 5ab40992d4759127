"""A recording written back in its own format with its IMU replaced: where the output goes, what is
refused before any work, and the steps (a device profile's floor, a model) applied in order. No
torch here: ``imu-learn refine --profile`` runs without it (a model's step is
:func:`imu_learn.infer.refiner.model_step`).

Each layout's module in :mod:`imu_learn.data.formats` writes its file back (a user's CSV in its own
columns and units); every file is written to a temporary file beside its target and renamed into
place (:mod:`imu_learn.util.atomic`). The input is never written: an OUT that resolves to the input
file (or, with ``copy_folder``, the input folder) is refused.

Two more steps live here: :func:`measured` records what a step adds (for refine's guard,
:mod:`imu_learn.infer.guard`), and :func:`still_bias_step` removes the recording's own gyro bias,
estimated from its still stretches (:mod:`imu_learn.core.still`) on what the steps before it give;
:func:`gravity_bias_step` from gravity consistency (:mod:`imu_learn.core.bias_gravity`); :func:`bias_step`
picks one for ``--bias`` (refine's and navigate's) and :func:`bias_entry` writes its summary entry.
:func:`summary_path` and :func:`write_summary` write refine's ``summary.json`` beside the output.
"""
from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Dict, Optional, Sequence, Tuple

import numpy as np

from imu_learn.core.bias_gravity import gravity_bias
from imu_learn.core.still import BIAS_SETTINGS, still_bias
from imu_learn.data import formats
from imu_learn.data.formats import ImuSource
from imu_learn.errors import InvalidInputError
from imu_learn.infer.guard import residual_rms
from imu_learn.util.atomic import atomic_write_text

# One step of a refinement: (t_ns or None, gyro, acc) -> (gyro, acc, per-sample variances (N, 6) or None).
Step = Callable[[Optional[np.ndarray], np.ndarray, np.ndarray], Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]]


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
    target = output_file(src, output)
    if _same(target, src.imu_file) or _same(output, input):
        raise InvalidInputError(f"refusing to overwrite the input: OUT {output} is the input {input}")
    return target


def rewrite_recording(src: ImuSource, input: Path, output: Path, steps: Sequence[Step], copy_folder: bool = False,
                      fill_covariance: bool = False) -> Path:
    """``src`` with its IMU passed through ``steps`` in order, written to ``output`` in the input's
    own format (``copy_folder``: the whole input folder copied first; ``fill_covariance``: a bag's
    IMU covariance fields get the last step's variances). Returns the file (or ROS 2 bag folder)
    written."""
    target = check_output(src, input, output, copy_folder, fill_covariance)
    gyro, acc, var = src.gyro, src.acc, None
    for step in steps:
        gyro, acc, v = step(src.t_ns, gyro, acc)
        var = v if v is not None else var
    if fill_covariance:
        if var is None:
            raise InvalidInputError("--fill-covariance needs a model with a covariance head")
        formats.rosbag.write_imu(src, target, gyro, acc, variances=var)
        return target
    if copy_folder:
        shutil.copytree(src.root, Path(output), dirs_exist_ok=True)
    formats.write_imu(src, target, gyro, acc)
    return target


def measured(step: Step, sink: Dict[str, Any]) -> Step:
    """``step``, recording in ``sink["residual_rms"]`` the RMS per axis of what it adds
    (:func:`imu_learn.infer.guard.residual_rms`)."""

    def wrapped(t_ns: Optional[np.ndarray], gyro: np.ndarray, acc: np.ndarray):
        g, a, v = step(t_ns, gyro, acc)
        sink["residual_rms"] = residual_rms(gyro, acc, g, a)
        return g, a, v

    return wrapped


def still_bias_step(gravity: float, sink: Dict[str, Any]) -> Step:
    """The recording's own gyro bias, from its still stretches (:func:`imu_learn.core.still.still_bias`
    with the accelerometer norm checked against ``gravity``), subtracted from what the steps before
    give (after a profile's floor and a model it is the bias they leave: the floor's bias is the
    device's average, this one the recording's). ``sink["still"]`` gets the estimate; without a
    still stretch nothing is subtracted."""
    settings = replace(BIAS_SETTINGS, gravity=float(gravity))

    def step(t_ns: Optional[np.ndarray], gyro: np.ndarray, acc: np.ndarray):
        if t_ns is None:
            raise InvalidInputError("--bias still needs the recording's stamps")
        est = still_bias(t_ns, gyro, acc, settings)
        sink["still"] = est
        if est.gyro_bias is None:
            return gyro, acc, None
        return gyro - est.gyro_bias, acc, None

    return step


def gravity_bias_step(sink: Dict[str, Any]) -> Step:
    """The recording's own gyro bias from gravity consistency (:func:`imu_learn.core.bias_gravity.gravity_bias`:
    only the rates perpendicular to gravity are observed), an increment on what the steps before give,
    subtracted from it. ``sink["gravity"]`` gets the estimate; on a recording too short for its
    windows nothing is subtracted."""

    def step(t_ns: Optional[np.ndarray], gyro: np.ndarray, acc: np.ndarray):
        if t_ns is None:
            raise InvalidInputError("--bias gravity needs the recording's stamps")
        est = gravity_bias(t_ns, gyro, acc)
        sink["gravity"] = est
        if est.gyro_bias is None:
            return gyro, acc, None
        return gyro - est.gyro_bias, acc, None

    return step


def still_along_gravity(still: Optional[np.ndarray], grav: Any) -> Optional[np.ndarray]:
    """The still stretches' bias along gravity's body direction and gravity consistency's across it
    (gravity consistency cannot see the rate about gravity; the still estimate carries the rest-to-
    motion change of the bias across it, docs/experiments/learning.md "Flight by flight against the
    peers"); either alone where the other has none."""
    if still is None:
        return grav.gyro_bias
    if grav.gyro_bias is None or grav.gravity_body is None:
        return still
    u = np.asarray(grav.gravity_body, dtype=np.float64)
    u = u / np.linalg.norm(u)
    return grav.gyro_bias + u * float(u @ (np.asarray(still) - grav.gyro_bias))


@dataclass
class CombinedBias:
    """``--bias still+gravity``: :func:`still_along_gravity` of the two estimates."""

    gyro_bias: Optional[np.ndarray]
    still: Any
    gravity: Any

    def to_dict(self) -> Dict[str, object]:
        b = self.gyro_bias
        return {"gyro_bias_rad_s": None if b is None else [float(v) for v in b],
                "gyro_bias_deg_s": None if b is None else [float(v) for v in np.rad2deg(b)],
                "rule": "the still stretches' estimate along gravity, gravity consistency's across it (either alone "
                        "where the other has none)",
                "still": self.still.to_dict(), "gravity": self.gravity.to_dict()}


def still_gravity_bias_step(gravity: float, sink: Dict[str, Any]) -> Step:
    """Both estimators on what the steps before give, combined (:func:`still_along_gravity`) and
    subtracted. ``sink["still+gravity"]`` gets the estimate."""
    settings = replace(BIAS_SETTINGS, gravity=float(gravity))

    def step(t_ns: Optional[np.ndarray], gyro: np.ndarray, acc: np.ndarray):
        if t_ns is None:
            raise InvalidInputError("--bias still+gravity needs the recording's stamps")
        still, grav = still_bias(t_ns, gyro, acc, settings), gravity_bias(t_ns, gyro, acc)
        est = CombinedBias(still_along_gravity(still.gyro_bias, grav), still, grav)
        sink["still+gravity"] = est
        if est.gyro_bias is None:
            return gyro, acc, None
        return gyro - est.gyro_bias, acc, None

    return step


@dataclass
class LearnedBias:
    """The learned estimator's answer (:mod:`imu_learn.nn.bias_net`): ``gyro_bias`` [rad/s] (3,), None
    on a recording shorter than its window."""

    gyro_bias: Optional[np.ndarray]
    model: str
    window_s: float
    record: Dict[str, Any]

    def to_dict(self) -> Dict[str, object]:
        b = self.gyro_bias
        return {"gyro_bias_rad_s": None if b is None else [float(v) for v in b],
                "gyro_bias_deg_s": None if b is None else [float(v) for v in np.rad2deg(b)],
                "model": self.model, "window_s": self.window_s, "trained_on": self.record.get("device"),
                "observable": "learned from the training recordings (a random bias injected per window); no "
                              "uncertainty: docs/refine.md for where it helped"}


def learned_bias_step(model: Path, sink: Dict[str, Any]) -> Step:
    """The recording's own gyro bias from the learned long-context estimator ``model`` (torch is
    imported here only), subtracted from what the steps before give (the floor it was trained on)."""

    def step(t_ns: Optional[np.ndarray], gyro: np.ndarray, acc: np.ndarray):
        from imu_learn.nn.bias_net import load_bias_net, predict_bias

        if t_ns is None:
            raise InvalidInputError("--bias learned needs the recording's stamps")
        net, record = load_bias_net(model, with_record=True)
        est = LearnedBias(predict_bias(net, t_ns, gyro, acc), str(model), net.cfg.window_s, record)
        sink["learned"] = est
        if est.gyro_bias is None:
            return gyro, acc, None
        return gyro - est.gyro_bias, acc, None

    return step


# --bias METHOD: the recording's own gyro bias, estimated on what the steps before give (navigate:
# the estimators without a model)
ESTIMATORS = ("none", "still", "gravity", "still+gravity")
BIAS_METHODS = ESTIMATORS + ("learned",)
BIAS_WORDS = {"still": "the recording's own gyro bias from its still stretches removed",
              "gravity": "the recording's own gyro bias from gravity consistency removed (rates perpendicular "
                         "to gravity only)",
              "still+gravity": "the recording's own gyro bias removed: from its still stretches along gravity, from "
                               "gravity consistency across it",
              "learned": "the recording's own gyro bias from the learned estimator removed"}


def bias_step(method: str, gravity: float, sink: Dict[str, Any], model: Optional[Path] = None) -> Step:
    """The step of ``--bias METHOD`` (``still``, ``gravity``, ``still+gravity``, or ``learned`` with
    ``model``)."""
    if method == "still":
        return still_bias_step(gravity, sink)
    if method == "gravity":
        return gravity_bias_step(sink)
    if method == "still+gravity":
        return still_gravity_bias_step(gravity, sink)
    if method == "learned" and model is not None:
        return learned_bias_step(Path(model), sink)
    if method == "learned":
        raise InvalidInputError("--bias learned needs --bias-model PATH (a bias estimator, imu_learn.train.bias_train)")
    raise InvalidInputError(f"--bias: one of {', '.join(BIAS_METHODS)}, got {method!r}")


def bias_entry(method: str, sink: Dict[str, Any], where: str) -> Tuple[Dict[str, Any], Optional[str]]:
    """(the summary's ``bias`` entry, a warning line naming ``where`` when nothing could be estimated,
    else None)."""
    if method == "none":
        return {"method": "none"}, None
    est = sink[method]
    warning = None
    if est.gyro_bias is None and method == "still":
        warning = (f"--bias still: no still stretch in {where} (docs/refine.md: the detector's thresholds); no bias "
                   "subtracted")
    elif est.gyro_bias is None and method == "still+gravity":
        warning = f"--bias still+gravity: neither a still stretch nor enough windows in {where}; no bias subtracted"
    elif est.gyro_bias is None and method == "learned":
        warning = f"--bias learned: {where} is shorter than the estimator's window of {est.window_s:g} s; no bias subtracted"
    elif est.gyro_bias is None:
        warning = (f"--bias gravity: {where} is shorter than {est.settings.min_windows} windows of "
                   f"{est.settings.window_s:g} s; no bias subtracted")
    return {"method": method, "applied": est.gyro_bias is not None, **est.to_dict()}, warning


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
