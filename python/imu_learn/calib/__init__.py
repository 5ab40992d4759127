"""Device calibration (``imu-learn calibrate``): the device profile (profile.py: time offset, affine
calibration, gravity, noise; JSON; applies the ``traditional+timing`` floor without torch), the floor
fit against a reference (fit.py), the noise from residuals and from Allan deviations of still
stretches (noise.py), Kalibr's imu.yaml (kalibr.py) and the plot (plot.py)."""
from imu_learn.calib.profile import Affine, NoiseTerm, Profile

__all__ = ["Affine", "NoiseTerm", "Profile"]
