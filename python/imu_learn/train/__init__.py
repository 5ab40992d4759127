"""Training: the run configuration, the loop with its validation and selection, checkpoints."""
