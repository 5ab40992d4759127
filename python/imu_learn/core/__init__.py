"""numpy wrappers of the Rust core (``imu_learn._imu_core``): quaternions, increment integration,
covariance propagation, training batches, Allan deviation; the sample-rate rule. No torch. The core
sits below data: it takes any object with the arrays it reads (:class:`integration.SegmentArrays`)."""
