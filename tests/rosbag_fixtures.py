"""The ROS bag fixtures of the tests: imu_learn.data.sample_bags written from the shipped
MH_04_difficult crop (its topics and stamps: that module's doc)."""
from __future__ import annotations

from pathlib import Path

from imu_learn.data import sample_bags
from imu_learn.data.sample_bags import KINDS, POSE_TOPICS, RECEIVE_DELAY_NS, TOPICS, bag_name

REPO = Path(__file__).resolve().parent.parent
CROP = REPO / "datasets" / "euroc" / "MH_04_difficult"
IMU_CSV = CROP / sample_bags.IMU_CSV
GT_CSV = CROP / sample_bags.GT_CSV

__all__ = ["CROP", "GT_CSV", "IMU_CSV", "KINDS", "POSE_TOPICS", "RECEIVE_DELAY_NS", "TOPICS", "bag_name",
           "write_fixture_bag"]


def write_fixture_bag(folder: Path, kind: str, seconds: float = 0.0, messages=None, name: str = "") -> Path:
    """A bag of ``kind`` (ros1, sqlite3, mcap) in ``folder`` from the crop (``sample_bags.write_sample_bag``)."""
    return sample_bags.write_sample_bag(folder, kind, CROP, seconds=seconds, messages=messages, name=name)
