"""``python -m imu_learn.cli``: the same as ``imu-learn``."""
from imu_learn.cli import entry

entry()
