"""Why a bias fitted on some Fetch recordings makes another's open-loop rotation worse: the z gyro's
error against the motion capture, per recording, regressed on the turn rate (e = b + s w_z) and on its
magnitude (e = b + c |w_z|). A diagnostic: nothing is chosen on it.

    IMU_LEARN_DATA=<root> python experiments/fetch_turn_rate.py

Rates from the motion capture's orientation over 10 samples (0.1 s), the gyro averaged over the same
samples. Writes: one table on stdout (docs/experiments/profile-selection.md, "Fetch: a turn-rate
dependent error"). Data: ``fetch/*`` under the data root.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from imu_learn.core.quat import quat_conj, quat_log, quat_mul
from imu_learn.data.loading import AlignOptions, load_sequence

RECORDINGS = ("01_square", "03_um", "04_eight", "06_right_turn", "07_left_turn", "08_origin")
K = 10  # samples per rate


def main() -> int:
    root = Path(os.environ.get("IMU_LEARN_DATA", "")) / "fetch"
    print("| recording | mean w_z [rad/s] | mean error x, y, z [rad/s] | z: b + s w_z | z: b + c abs(w_z) |")
    print("|---|---|---|---|---|")
    for r in RECORDINGS:
        s = max(load_sequence(root / r, "fetch", options=AlignOptions(max_gap_s=0.1)), key=len)
        t = s.t_ns * 1e-9
        w = quat_log(quat_mul(quat_conj(s.q_wxyz[:-K]), s.q_wxyz[K:])) / (t[K:] - t[:-K])[:, None]
        g = np.stack([np.convolve(s.gyro[:, i], np.ones(K) / K, "valid") for i in range(3)], 1)[:len(w)]
        e = g - w
        lin = np.linalg.lstsq(np.stack([np.ones(len(w)), w[:, 2]], 1), e[:, 2], rcond=None)[0]
        mag = np.linalg.lstsq(np.stack([np.ones(len(w)), np.abs(w[:, 2])], 1), e[:, 2], rcond=None)[0]
        print(f"| {r} | {w[:, 2].mean():+.3f} | {', '.join(f'{x:+.4f}' for x in e.mean(0))} | "
              f"b {lin[0]:+.4f}, s {lin[1]:+.4f} | b {mag[0]:+.4f}, c {mag[1]:+.4f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
