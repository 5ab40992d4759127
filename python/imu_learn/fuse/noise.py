"""The IMU noise model the factor graph assumes, and its GTSAM preintegration parameters.

Densities are continuous-time, as in a Kalibr/ASL ``sensor.yaml``: white noise in rad/s/sqrt(Hz)
and m/s^2/sqrt(Hz), bias random walk in rad/s^2/sqrt(Hz) and m/s^3/sqrt(Hz). GTSAM's
``PreintegrationCombinedParams`` takes their squares as continuous-time covariances and
discretises them itself over each sample's dt.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Optional, Sequence, Tuple

import numpy as np

from imu_learn.data.formats.asl import read_sensor_yaml
from imu_learn.errors import InvalidInputError

BUILT_IN = "EuRoC ADIS16448 sensor.yaml (built-in)"
SENSOR_KEYS = {
    "gyro_noise_density": "gyroscope_noise_density",
    "acc_noise_density": "accelerometer_noise_density",
    "gyro_random_walk": "gyroscope_random_walk",
    "acc_random_walk": "accelerometer_random_walk",
}


@dataclass(frozen=True)
class ImuNoise:
    gyro_noise_density: float = 1.6968e-4  # EuRoC ADIS16448 sensor.yaml
    acc_noise_density: float = 2.0e-3
    gyro_random_walk: float = 1.9393e-5
    acc_random_walk: float = 3.0e-3
    integration_sigma: float = 1e-4  # [m/s^2/sqrt(Hz)]-like slack on position integration (GTSAM's default style)
    source: str = BUILT_IN
    # the white noise per body axis where it was measured per axis (navigate's rest floor: a car's engine shakes
    # one axis 25x another); None: the density above on every axis. The graph takes these, the summary both
    gyro_axes: Optional[Tuple[float, float, float]] = None
    acc_axes: Optional[Tuple[float, float, float]] = None

    def __post_init__(self) -> None:
        for k in ("gyro_noise_density", "acc_noise_density", "gyro_random_walk", "acc_random_walk"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v > 0):
                raise InvalidInputError(f"noise.{k} must be a positive number, got {v!r}")
        for k in ("gyro_axes", "acc_axes"):
            v = getattr(self, k)
            if v is not None and not (len(v) == 3 and all(np.isfinite(x) and x > 0 for x in v)):
                raise InvalidInputError(f"noise.{k} must be three positive numbers, got {v!r}")

    def white_covariances(self) -> Tuple[np.ndarray, np.ndarray]:
        """The gyro's and accelerometer's continuous-time white-noise covariances (3x3): per axis where
        measured so, else the density on every axis."""
        return tuple(np.diag(np.square(axes)) if axes is not None else density ** 2 * np.eye(3)
                     for axes, density in ((self.gyro_axes, self.gyro_noise_density),
                                           (self.acc_axes, self.acc_noise_density)))

    @classmethod
    def from_sensor_yaml(cls, path: Path) -> ImuNoise:
        """The four densities of an ASL ``mav0/imu0/sensor.yaml``."""
        y = read_sensor_yaml(Path(path))
        missing = [v for v in SENSOR_KEYS.values() if not isinstance(y.get(v), float)]
        if missing:
            raise InvalidInputError(f"{path}: no numeric {', '.join(missing)}")
        return cls(**{k: float(y[v]) for k, v in SENSOR_KEYS.items()}, source=str(path))

    def to_dict(self) -> dict:
        """The four densities under Kalibr's names, and where they came from (summary.json)."""
        axes = {name: [float(x) for x in v] for name, v in (("gyroscope_noise_density_axes", self.gyro_axes),
                                                             ("accelerometer_noise_density_axes", self.acc_axes))
                if v is not None}
        return {**{v: float(getattr(self, k)) for k, v in SENSOR_KEYS.items()}, **axes, "source": self.source}

    def gtsam_params(self, gravity: float):
        """``PreintegrationCombinedParams`` for a z-up world with gravity ``gravity`` [m/s^2]."""
        import gtsam

        p = gtsam.PreintegrationCombinedParams.MakeSharedU(gravity)
        eye = np.eye(3)
        gyro, acc = self.white_covariances()
        p.setGyroscopeCovariance(gyro)
        p.setAccelerometerCovariance(acc)
        p.setIntegrationCovariance(self.integration_sigma ** 2 * eye)
        p.setBiasOmegaCovariance(self.gyro_random_walk ** 2 * eye)
        p.setBiasAccCovariance(self.acc_random_walk ** 2 * eye)
        return p


def from_profile(kalibr: Dict[str, Optional[float]], where: str, defaults: Sequence[str] = ()) -> ImuNoise:
    """The noise of a device profile (:meth:`imu_learn.calib.profile.Profile.kalibr`: Kalibr's four
    names; ``defaults``: those of them that are the device-class default, not observed); a figure the
    profile lacks is the built-in one, and the source says which."""
    ours = {v: k for k, v in SENSOR_KEYS.items()}
    missing = [name for name in ours if kalibr.get(name) is None]
    values = {ours[name]: float(v) for name, v in kalibr.items() if name in ours and v is not None}
    source = f"profile {where}"
    if defaults:
        source += f" ({', '.join(defaults)}: not observed, the MEMS class default or the data's lower bound)"
    if missing:
        source += f" ({', '.join(missing)}: built-in EuRoC ADIS16448)"
    return ImuNoise(**values, source=source)
