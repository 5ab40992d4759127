"""Still stretches and gravity consistency together (docs/experiments/learning.md, "Each recording's own
bias"): the still estimate first, then gravity consistency on what it leaves with its prior narrowed to
the still estimate's trust (0.001 or 0.003 rad/s); recordings without a still stretch get gravity
consistency alone.

Writes: nothing to disk; prints the table of the mean bias error [mrad/s] per device and split,
segments >= 30 s.
Data: the training and test recordings of Fetch, TUM-VI, EuRoC and BROAD under the data root.

    IMU_LEARN_DATA=<root> python experiments/bias_combined.py
"""
import os
from dataclasses import replace

import numpy as np

from imu_learn.core.bias_gravity import GravitySettings, gravity_bias
from imu_learn.core.still import BIAS_SETTINGS, still_bias
from imu_learn.train.bias_data import load_device, training_mean


def estimates(r, mean):
    """{name: increment on the training mean (3,)} for one recording."""
    s = r.seg
    g0 = s.gyro - mean
    st = still_bias(s.t_ns, g0, s.acc, replace(BIAS_SETTINGS, gravity=r.gravity)).gyro_bias
    gr = gravity_bias(s.t_ns, g0, s.acc).gyro_bias
    out = {"mean": np.zeros(3), "still": np.zeros(3) if st is None else st, "gravity": gr}
    for name, sigma in (("still+gravity 0.001", 0.001), ("still+gravity 0.003", 0.003)):
        out[name] = gr if st is None else st + gravity_bias(s.t_ns, g0 - st, s.acc,
                                                             GravitySettings(prior_sigma=sigma)).gyro_bias
    return out


def main():
    root = os.environ.get("IMU_LEARN_DATA", "data")
    for device in ("euroc", "fetch", "tumvi", "broad"):
        recs = load_device(device, root)
        mean = training_mean(recs["train"])
        for split in ("train", "test"):
            errors = {}
            for r in recs[split]:
                if r.seg.duration_s < 30:
                    continue
                for name, inc in estimates(r, mean).items():
                    errors.setdefault(name, []).append(np.linalg.norm(mean + inc - r.gyro_bias))
            print(split, device, "  ".join(f"{k} {np.mean(v) * 1e3:.2f}" for k, v in errors.items()), flush=True)


if __name__ == "__main__":
    main()
