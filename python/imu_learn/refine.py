"""`python -m imu_learn.refine`: the same as `imu-learn refine` (see :mod:`imu_learn.cli`)."""
if __name__ == "__main__":
    import sys

    from imu_learn.cli import entry

    entry(["refine", *sys.argv[1:]])
