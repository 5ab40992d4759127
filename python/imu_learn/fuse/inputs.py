"""The IMU inputs fusion takes, by name and file: one resolver for every entry point (the experiments
by a config's input names, the navigator by ``--checkpoint`` / ``--calibration`` / ``--displacement``).

* :func:`load` loads what a name's file holds, once per (name, file): a refiner checkpoint
  (``proposed`` and the learned-covariance inputs; a covariance head is required by the latter) or a
  method ``imu-learn evaluate`` fitted and saved (``traditional``, ``timing``, ``tlio-style``, ...);
* :func:`apply` turns the raw samples into the input's samples and, for the learned-covariance
  inputs, their per-sample noise variances (:data:`Imu`); ``raw`` is the samples as they are;
* :func:`displacement_hook` is the graph's factor hook of a displacement model (``tlio-style`` or its
  floor ``zero-displacement``), regressed from the raw samples;
* :func:`checkpoint_input` and :func:`method_input` refine arrays by a checkpoint or a saved fit,
  each with its label, through the correction plan's steps (:mod:`imu_learn.calib.correction`, which
  the navigator applies with its checks).

Checkpoints run through the one windowing rule (:func:`imu_learn.infer.windowing.apply`), as refine,
evaluate and fit apply them.
"""
from __future__ import annotations

from pathlib import Path
from typing import Dict, Optional, Tuple, Union

import numpy as np

from imu_learn.baselines.registry import load_method_class
from imu_learn.calib import correction
from imu_learn.data.types import Segment
from imu_learn.errors import ConfigError

from .factors.displacement import displacement_factors_for

# "raw+learned-cov" / "proposed+learned-cov": the raw or refined samples, each weighted in the
# graph by its own noise variances from a refiner's covariance head (covariance_checkpoint) instead
# of the datasheet's white noise; the pair separates the refined samples' effect from the covariance's.
# "learned": the one learned input: the device model's refined samples weighted by its learned
# covariance (as proposed+learned-cov), plus the tlio-style displacement factors where the device has
# that model (<methods_dir>/tlio-style.pt; regressed from the raw samples).
LEARNED_INPUT = "learned"
LEARNED_COV_INPUTS = ("raw+learned-cov", "proposed+learned-cov", LEARNED_INPUT)
INPUTS = ("raw", "traditional", "proposed") + LEARNED_COV_INPUTS
TLIO_INPUT = "tlio-style"  # the learned displacement model (the `learned` input adds its factors)
# fusion inputs that add displacement factors to the raw IMU (the second is the first's simple floor:
# zero displacement, baselines/zero_displacement.py)
FACTOR_INPUTS = (TLIO_INPUT, "zero-displacement")

# (gyro (N, 3), acc (N, 3), per-sample variances (N, 6) or None for the datasheet's white noise)
Imu = Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]
Cache = Dict[Tuple[str, str], object]


def is_refiner(name: str) -> bool:
    """Whether input ``name``'s file is a refiner checkpoint (else a saved method, or nothing for raw)."""
    return name == "proposed" or name in LEARNED_COV_INPUTS


def load(name: str, path: str, cache: Optional[Cache] = None) -> object:
    """The refiner (``proposed``, the learned-covariance inputs) or the fitted ``imu-learn evaluate``
    method (every other input) in ``path``, loaded once per ``cache``."""
    cache = {} if cache is None else cache
    if (name, path) not in cache:
        if not Path(path).is_file():
            hint = ("" if name == "proposed" else
                    f" (imu-learn evaluate with the '{name}' method writes it to <report>/methods/)")
            raise FileNotFoundError(f"{name}: {path} not found{hint}")
        if is_refiner(name):
            from imu_learn.infer.checkpoint import load_model

            model = load_model(Path(path))
            if name in LEARNED_COV_INPUTS and model.cov_head is None:
                raise ConfigError(f"{name}: {path} has no covariance head (a model fitted with model.covariance = true)")
            cache[(name, path)] = model
        else:
            cache[(name, path)] = load_method_class(name)().load(Path(path))
    return cache[(name, path)]


def apply(name: str, model, seq: Segment) -> Imu:
    """Input ``name``'s samples of the raw ``seq`` through its loaded ``model`` (None for raw)."""
    if name == "raw":
        return seq.gyro, seq.acc, None
    from imu_learn.infer.windowing import apply as apply_windows  # the checkpoint's windowing rule

    if name in LEARNED_COV_INPUTS:
        gyro, acc, var = apply_windows(model, seq.gyro, seq.acc, variance=True)
        # The head's variances are a function of the raw samples (the model's input) either way.
        return (seq.gyro, seq.acc, var) if name == "raw+learned-cov" else (gyro, acc, var)
    if name != "proposed":
        return (*model.refine(seq), None)
    gyro, acc, _ = apply_windows(model, seq.gyro, seq.acc)
    return gyro, acc, None


def imu_input(name: str, seq: Segment, path: str, cache: Optional[Cache] = None) -> Imu:
    """Input ``name`` of ``seq``, its model loaded from ``path`` ("" for raw)."""
    return apply(name, None if name == "raw" else load(name, path, cache), seq)


def imu_only(name: str, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> Segment:
    """A recording's IMU as a :class:`Segment` without ground truth (zeros: refiners read the IMU only)."""
    n = len(t_ns)
    z = np.zeros((n, 3))
    return Segment(name, t_ns, gyro, acc, z, z, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))


def checkpoint_input(checkpoint: Optional[Path], t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray,
                     variance_scale: Optional[Tuple[float, float]] = None) -> Tuple[np.ndarray, np.ndarray,
                                                                                    Optional[np.ndarray], str]:
    """(gyro, acc, per-sample variances or None, label): the IMU refined by ``checkpoint`` (raw without
    one; ``proposed``; after the profile it carries, as the correction plan applies it:
    :mod:`imu_learn.calib.correction`, unchecked here), weighted by its covariance head's variances when
    it has one (``proposed+learned-cov``, the ``learned`` input's samples). ``variance_scale`` (k_gyro,
    k_acc), dimensionless: multiplies the head's gyro and acc variances (:mod:`.variance` calibrates them
    over the keyframe interval); a :class:`ConfigError` without a covariance head."""
    if checkpoint is None:
        if variance_scale is not None:
            raise ConfigError("--variance-scale scales a covariance head's variances: it needs --checkpoint")
        return gyro, acc, None, "raw"
    plan = correction.build(correction.Request(checkpoint=Path(checkpoint), variance="if-head",
                                               command="imu-learn navigate"))
    if not plan.covariance:
        if variance_scale is not None:
            raise ConfigError(f"--variance-scale: {Path(checkpoint).name} has no covariance head (model.covariance)")
        g, a, _ = plan.apply(t_ns, gyro, acc)
        return g, a, None, f"refined by {Path(checkpoint).name}"
    g, a, var = plan.apply(t_ns, gyro, acc)
    label = f"refined by {Path(checkpoint).name}, weighted by its learned covariance"
    if variance_scale is not None:
        kg, ka = (float(x) for x in variance_scale)
        var = var * np.repeat([kg, ka], 3)
        label += f" scaled by {kg:g} (gyro), {ka:g} (acc)"
    return g, a, var, label


def method_input(path: Path, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> Tuple[np.ndarray, np.ndarray, str]:
    """(gyro, acc, label): the IMU through a fit ``imu-learn evaluate`` saved (``<out>/methods/timing.json``,
    ``traditional+timing.json``, ...; the method is the file's name), the floor a learned input is judged by
    (:func:`imu_learn.calib.correction.from_calibration`)."""
    plan = correction.from_calibration(Path(path))
    g, a, _ = plan.apply(t_ns, gyro, acc)
    return g, a, plan.words[0]


def displacement_model(path: Path, cache: Optional[Cache] = None):
    """A saved ``tlio-style`` model, or its floor ``zero-displacement`` (a ``.json`` file: zero
    displacement with the fitted spread)."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"--displacement: {path} not found (imu-learn evaluate --methods tlio-style writes it)")
    return load("zero-displacement" if Path(path).suffix.lower() == ".json" else TLIO_INPUT, str(path), cache)


def displacement_hook(model, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray, update_s: float = 1.0):
    """The graph's factor hook of a displacement ``model``, regressed from the raw samples ``gyro``,
    ``acc`` (the network's training input) every ``update_s`` seconds."""
    return displacement_factors_for(model, t_ns, np.ascontiguousarray(gyro), np.ascontiguousarray(acc), update_s)


def checkpoint_bias(path: Union[str, Path, None]) -> Tuple[np.ndarray, str]:
    """(bias (6,) gyro then acc, where it came from): the checkpoint's ``device_bias`` (top level or
    under ``extra``: ``{"gyro": [3], "acc": [3]}``) when it carries one, else zeros."""
    if path is None:
        return np.zeros(6), "zero (no checkpoint)"
    from imu_learn.infer.checkpoint import load_checkpoint

    state = load_checkpoint(Path(path))
    dev = state.get("device_bias") or (state.get("extra") or {}).get("device_bias")
    if isinstance(dev, dict) and "gyro" in dev and "acc" in dev:
        b = np.r_[np.asarray(dev["gyro"], dtype=np.float64).reshape(3), np.asarray(dev["acc"], dtype=np.float64).reshape(3)]
        if np.all(np.isfinite(b)):
            return b, f"the checkpoint's device bias ({path})"
    return np.zeros(6), f"zero (the checkpoint {Path(path).name} carries no device bias)"
