"""numpy wrappers of the Rust core (``imu_learn._imu_core``): quaternions, increment integration,
covariance propagation, training batches. No torch."""
