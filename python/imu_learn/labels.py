"""`python -m imu_learn.labels`: the same as `imu-learn labels` (see :mod:`imu_learn.cli`)."""
if __name__ == "__main__":
    import sys

    from imu_learn.cli import entry

    entry(["labels", *sys.argv[1:]])
