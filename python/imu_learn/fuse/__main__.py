"""``python -m imu_learn.fuse``: the same as ``imu-learn fuse`` (options and output: :mod:`imu_learn.cli.fuse`)."""
import sys

from imu_learn.cli import main

if __name__ == "__main__":
    sys.exit(main(["fuse", *sys.argv[1:]]))
