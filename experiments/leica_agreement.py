"""How well EuRoC's Leica MS50 positions and the ground truth agree (imu_learn.fuse's real aiding):

    IMU_LEARN_DATA=<data root> python experiments/leica_agreement.py [euroc/MH_01_easy]

Each Leica fix (the prism, world frame) is compared with the ground-truth body position at the
same stamp plus the body-to-prism lever arm (``leica0/sensor.yaml`` T_BS) rotated into the world:
residual RMSE with the lever arm, without it, with a lever arm fitted by least squares, and after
fitting a constant time offset. Prints a markdown table.

Writes: the Leica figures of docs/experiments/fusion.md ("Using `imu-learn fuse`") and
configs/fuse_euroc.toml's time_offset_s. Data: EuRoC MH_01_easy with its leica0 folder under the
data root.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn import AlignOptions, load_recording
from imu_learn.core.quat import wxyz_to_xyzw
from imu_learn.data.formats.asl import read_leica


def residuals(t_leica, p_leica, seq, lever, shift_ns=0):
    t = t_leica + shift_ns
    ok = (t >= seq.t_ns[0]) & (t <= seq.t_ns[-1])
    ts = seq.t_ns.astype(np.float64)
    p_gt = np.stack([np.interp(t[ok].astype(np.float64), ts, seq.p[:, k]) for k in range(3)], 1)
    k = np.clip(np.searchsorted(seq.t_ns, t[ok]), 0, len(seq) - 1)
    R = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[k]))
    return p_leica[ok] - (p_gt + R.apply(lever)), R, p_leica[ok] - p_gt


def rmse(e):
    return float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))


def main(rel: str = "euroc/MH_01_easy") -> None:
    root = Path(os.environ.get("IMU_LEARN_DATA", ".")) / rel
    gt = root / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    rec = load_recording(root, "euroc", groundtruth=gt, options=AlignOptions(max_gap_s=0.05))
    seq = max(rec.segments, key=len)
    t, p, lever = read_leica(root)
    e, R, d = residuals(t, p, seq, lever)
    e0, _, _ = residuals(t, p, seq, np.zeros(3))
    # least-squares lever arm (and a constant world offset): d = c + R l
    A = np.concatenate([np.tile(np.eye(3), (len(d), 1)), R.as_matrix().reshape(-1, 3)], axis=1)
    sol, *_ = np.linalg.lstsq(A, d.reshape(-1), rcond=None)
    e_fit = d - (sol[:3] + R.apply(sol[3:]))
    shifts = np.arange(-200, 201, 2) * 1_000_000
    best = min(shifts, key=lambda s: rmse(residuals(t, p, seq, lever, s)[0]))
    e_shift = residuals(t, p, seq, lever, best)[0]
    print(f"{rel}: {len(t)} Leica fixes, {len(e)} inside the ground truth ({seq.duration_s:.0f} s)\n")
    print("| comparison | residual RMSE [m] | median |e| [m] |")
    print("|---|---|---|")
    for name, x in (("with the sensor.yaml lever arm " + str(np.round(lever, 4).tolist()), e),
                    ("without a lever arm", e0),
                    (f"lever arm fitted {np.round(sol[3:], 4).tolist()}, offset {np.round(sol[:3], 4).tolist()}", e_fit),
                    (f"sensor.yaml lever arm, Leica clock shifted {best / 1e6:+.0f} ms (best of +-200 ms, 2 ms steps)", e_shift)):
        print(f"| {name} | {rmse(x):.4f} | {np.median(np.linalg.norm(x, axis=1)):.4f} |")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording", nargs="?", default="euroc/MH_01_easy", help="relative to $IMU_LEARN_DATA")
    main(ap.parse_args().recording)
