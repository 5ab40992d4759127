"""`python -m imu_learn.fit`: the same as `imu-learn fit` (see :mod:`imu_learn.cli`)."""
if __name__ == "__main__":
    import sys

    from imu_learn.cli import entry

    entry(["fit", *sys.argv[1:]])
