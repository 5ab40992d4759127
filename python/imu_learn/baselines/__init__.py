"""Competing methods, each fitted only on the training split (see base.py for the interface)."""
from imu_learn.baselines.base import FitSettings, Method, PosePrediction, Raw, poses_from_imu

__all__ = ["FitSettings", "Method", "PosePrediction", "Raw", "poses_from_imu"]
