"""How closely do real IMU samples and ground-truth labels agree?

For each EuRoC sequence: ground truth aligned to the IMU stamps, labels Δq/Δβ/Δγ at 0.2..1 s, and
the same increments integrated from the IMU. Printed: RMSE of the residual (rotation angle [rad],
velocity [m/s], position [m]) per horizon, for the raw IMU and for the IMU with one constant
gyro/accelerometer bias removed, fitted by least squares over the whole sequence (an upper bound
on what a constant-bias calibration can do; what remains is noise, time-varying bias, ground-truth
noise and the velocity derivation of pose-only ground truth).

    python experiments/label_agreement.py [--data ../shared/data/euroc]

Writes: docs/experiments/alignment.md, "How well do real IMU and ground-truth labels agree?".
Data: the EuRoC flights under --data (default: the shipped crops' folder layout, full files under
the data root).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import imu_learn as il


def rot_err(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    return 2 * np.arccos(np.abs(np.sum(qa * qb, -1)).clip(0, 1))


def log_q(q: np.ndarray) -> np.ndarray:
    q = q * np.sign(q[..., :1] + (q[..., :1] == 0))
    n = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    return q[..., 1:] * (2 * np.arctan2(n, q[..., :1]) / np.maximum(n, 1e-300))


def quat_conj_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a⁻¹ b for unit quaternions (w,x,y,z)."""
    aw, ax, ay, az = np.moveaxis(a * [1, -1, -1, -1], -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)


def fit_constant_bias(seq: il.Segment, n: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares constant biases from short windows: rotation residual / Δt for the gyro, then
    velocity residual / Δt for the accelerometer (with the gyro bias removed)."""
    lab = il.window_labels(seq, window=n, stride=n, fractions=[1.0])
    imu = il.integrate_windows(seq, lab.starts, lab.horizons)
    dt = lab.dt[:, 0:1]
    bg = np.median(log_q(quat_conj_mul(lab.dq_wxyz[:, 0], imu.dq_wxyz[:, 0])) / dt, axis=0)
    s2 = il.Segment("g", seq.t_ns, seq.gyro - bg, seq.acc, seq.p, seq.v, seq.q_wxyz)
    imu2 = il.integrate_windows(s2, lab.starts, lab.horizons)
    ba = np.median((imu2.dv[:, 0] - lab.dv[:, 0]) / dt, axis=0)
    return bg, ba


def residuals(seq: il.Segment, lab: il.WindowLabels) -> np.ndarray:
    imu = il.integrate_windows(seq, lab.starts, lab.horizons)
    r = np.sqrt(np.mean(rot_err(imu.dq_wxyz, lab.dq_wxyz) ** 2, axis=0))
    v = np.sqrt(np.mean(np.sum((imu.dv - lab.dv) ** 2, -1), axis=0))
    p = np.sqrt(np.mean(np.sum((imu.dp - lab.dp) ** 2, -1), axis=0))
    return np.stack([r, v, p], 1)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", type=Path, default=Path("datasets/euroc"))
    a = ap.parse_args()
    for root in sorted(p.parent for p in a.data.glob("*/mav0")):
        # EuRoC's own ground truth (ASL state, IMU frame) where the folder has it: V1_01's
        # groundtruth_pose.tum is ~5.5 deg off the IMU frame (README, "EuRoC ground truth").
        state = root / "groundtruth_state_20hz.csv"
        if state.is_file():
            seq = il.load_sequence(root, groundtruth=state, options=il.AlignOptions(max_gap_s=0.06))[0]
        else:
            seq = il.load_sequence(root)[0]
        gt_name = state.name if state.is_file() else "default ground truth"
        lab = il.window_labels(seq, window=200, stride=20)
        bg, ba = fit_constant_bias(seq)
        fixed = il.Segment("c", seq.t_ns, seq.gyro - bg, seq.acc - ba, seq.p, seq.v, seq.q_wxyz)
        raw, cor = residuals(seq, lab), residuals(fixed, lab)
        print(f"\n{root.name} ({gt_name}): {len(seq)} samples, {len(lab.starts)} windows; fitted gyro bias "
              f"{np.array2string(bg, precision=4)} rad/s, accel bias {np.array2string(ba, precision=3)} m/s²")
        print("| horizon [s] | rot raw [rad] | rot bias-fit [rad] | vel raw [m/s] | vel bias-fit | pos raw [m] | pos bias-fit |")
        print("|---|---|---|---|---|---|---|")
        for h in range(len(lab.horizons)):
            t = float(np.mean(lab.dt[:, h]))
            print(f"| {t:.1f} | {raw[h, 0]:.4f} | {cor[h, 0]:.4f} | {raw[h, 1]:.4f} | {cor[h, 1]:.4f} | "
                  f"{raw[h, 2]:.4f} | {cor[h, 2]:.4f} |")


if __name__ == "__main__":
    main()
