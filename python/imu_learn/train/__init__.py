"""Training: the run configuration, the loop with its validation and selection (checkpoints are
written and read through :mod:`imu_learn.infer.checkpoint`)."""
