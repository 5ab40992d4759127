"""Device calibration (``imu-learn calibrate``): the device profile (profile.json: time offset, affine
calibration, gravity, noise; JSON; applies the ``traditional+timing`` floor, one
:class:`~imu_learn.baselines.affine.Floor`, without torch), the recordings each reference kind yields
(sources.py: poses, a config's split, still; positions.py: positions only), the floor fit against a
reference (fit.py), the noise from residuals and from Allan deviations of still stretches (noise.py),
Kalibr's imu.yaml (kalibr.py) and the plot (plot.py); run.py does the steps every kind shares."""
from imu_learn.calib.profile import Affine, NoiseTerm, Profile

__all__ = ["Affine", "NoiseTerm", "Profile"]
