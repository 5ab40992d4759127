"""`python -m imu_learn.evaluate`: the same as `imu-learn evaluate` (see :mod:`imu_learn.cli`)."""
if __name__ == "__main__":
    import sys

    from imu_learn.cli import entry

    entry(["evaluate", *sys.argv[1:]])
