"""imu-learn: learn a low-cost IMU's error model from recordings with ground truth."""
from imu_learn._imu_core import __version__

__all__ = ["__version__"]
