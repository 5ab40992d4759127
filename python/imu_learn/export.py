"""`python -m imu_learn.export`: the same as `imu-learn export` (see :mod:`imu_learn.cli`)."""
if __name__ == "__main__":
    import sys

    from imu_learn.cli import entry

    entry(["export", *sys.argv[1:]])
