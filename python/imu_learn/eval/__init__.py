"""Evaluation: metrics, the fit-and-score protocol over the baselines registry, reports,
calibration of learned covariances."""
