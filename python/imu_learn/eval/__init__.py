"""Evaluation (``imu-learn evaluate``): the fit-and-score protocol over the baselines registry, the
peers' metrics, reports, calibration of learned covariances. The metrics themselves live in
:mod:`imu_learn.score`."""
