"""A profile's noise as Kalibr's ``imu.yaml`` (the file Kalibr, OpenVINS, VINS-Fusion and ORB-SLAM3
read): the four noise figures in continuous time, the update rate they were measured at, and a
rostopic placeholder. Each figure's line says where it came from (residuals, Allan deviation of
still stretches, or, for a random walk no fit observed or a figure nothing measured, the device-class
default, with the data's bound where there is one). Written by hand (no YAML library needed), read back by any
YAML parser (tests/test_calibrate.py parses it with PyYAML)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Union

from imu_learn.calib.profile import (
    CLASS_DEFAULT_SOURCE,
    CLASS_DEFAULTS,
    NOISE_KEYS,
    NOISE_UNITS,
    Profile,
    unobserved_value,
)
from imu_learn.util.atomic import atomic_write_text

ROSTOPIC_PLACEHOLDER = "/imu0"


def _value(x: float) -> str:
    return ".nan" if x is None or not math.isfinite(x) else f"{x:.4e}"


def kalibr_yaml(profile: Profile, rostopic: str = ROSTOPIC_PLACEHOLDER) -> str:
    """The text of ``imu.yaml`` for ``profile``: a figure the profile lacks (no reference and no still
    stretch measured it) is the device-class default (:data:`~imu_learn.calib.profile.CLASS_DEFAULTS`),
    as an unobserved random walk is, its comment saying so (Kalibr, OpenVINS and the rest read every line)."""
    lines = [
        "# IMU noise model in Kalibr's form (continuous time; discretise with update_rate)",
        f"# device: {profile.device}; written by imu-learn calibrate from profile.json ({profile.created})",
    ]
    values = profile.kalibr()
    for key in NOISE_KEYS:
        term = profile.noise.get(key)
        if profile.unobserved_noise(key):
            src = term.detail.get("upper_bound_from", term.source)
            why = f"not observed ({src} upper bound {_value(term.bound)}): {unobserved_value(key, term.bound)[1]}"
        elif term is None:  # neither a reference nor a still stretch: a documented default, said so
            why = f"not measured (no reference, no still stretch): the {CLASS_DEFAULT_SOURCE}; put your datasheet's here"
            values[key] = CLASS_DEFAULTS[key]
        else:
            kind = term.detail.get("kind", "fit")
            why = f"{term.source}, {kind}" + (f", +-{term.std:.1e}" if term.std is not None and math.isfinite(term.std) else "")
        value = _value(values[key] if values[key] is not None else math.nan)
        lines.append(f"{key}: {value}  # [{NOISE_UNITS[key]}] {why}")
    lines.append(f"rostopic: {rostopic}  # placeholder: your IMU topic")
    lines.append(f"update_rate: {profile.sample_rate_hz:.6g}  # [Hz]")
    return "\n".join(lines) + "\n"


def write_kalibr_yaml(profile: Profile, path: Union[str, Path], rostopic: str = ROSTOPIC_PLACEHOLDER) -> None:
    atomic_write_text(Path(path), kalibr_yaml(profile, rostopic))
