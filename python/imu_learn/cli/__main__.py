"""``python -m imu_learn.cli``: the same as ``imu-learn``."""
import sys

from imu_learn.cli import main

sys.exit(main())
