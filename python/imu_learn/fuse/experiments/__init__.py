"""The fusion experiments ``imu-learn fuse --config`` runs: :mod:`.batch` (every recording x IMU input x
aiding scenario of a :class:`~.config.FuseConfig`, causal and smoothed), :mod:`.online` (the same
streamed sample by sample, timed) and :mod:`.gnss` (a ``kind = "gnss-outages"`` config: GNSS/IMU with
simulated outages)."""
