"""The car drive's outage ends on shifted gap schedules: how much of a no-option ``imu-learn navigate``
run's mean end error is where the gaps fall, and what two candidate changes do to it
(docs/experiments/fusion_gnss.md, "Where the gaps fall").

    IMU_LEARN_DATA=DIR python experiments/drive_gap_grids.py [--offsets 0,15,30] [--nhc]
        [--variants rms,max,axes,rest-bias] [--profile PROFILE.json]

Each run is ``imu-learn navigate`` with no noise, mounting or delay given (``--nhc`` adds the mounting of
docs/navigate.md and the constraint), the drive's fixes withheld in 15 s gaps every 45 s from 36.77 s
after the IMU's first sample (the peer EKF's schedule) plus an offset, scored against the ``.pos`` at
its RTK-fixed rows (``scores.causal.gaps[*].horizontal.end_m``). The variants change one thing each,
by replacing a function of ``imu_learn.fuse.navigate`` in this process (nothing of the package is
changed): ``axes`` is the package as it is (the white noise raised, axis by axis, to each body axis's
per-sample spread over the rest, a diagonal covariance in GTSAM's preintegration); ``rms`` the rule
before it (one figure for the three axes: the RMS over the axes); ``max`` one figure, the largest axis's;
``rest-bias`` the package with the first state's bias from the parked rest the track shows (the gyro's
mean; the accelerometer's excess over normal gravity along its mean). ``--profile`` adds ``--profile P
--force`` to every run (a device profile from another recording of the same IMU, made at another rate:
calibrate on the walk's fixes; docs/experiments/fusion_gnss.md, "The walk's profile on the drive").

Writes: on stdout navigate's one-line summary and one JSON line per run (variant, offset, NHC, the horizontal end of every gap, their
mean, the causal horizontal RMSE); each run's outputs under a temporary folder, removed at the end.
Data: ``gnss-imu/drive_0708`` (rtklibexplorer/GNSS_IMU) under the data root.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Optional

import numpy as np

import imu_learn.fuse.navigate as nav
from imu_learn.cli import entry

MOUNTING = "180,-6.79,185.35"  # docs/navigate.md's mounting of the drive's IMU (z-down body, x forward)
NORMAL_GRAVITY = 9.7968  # at the drive's origin (docs/experiments/fusion_gnss.md)


def isotropic_rule(rule: str):
    """``at_rest_floor`` with one white-noise figure per sensor: the rest's per-axis variances reduced by
    ``rule`` (``rms``: their mean, the rule before the per-axis one; ``max``: the largest)."""
    def floor(noise, imu, rest, gravity):
        t_ns, gyro, acc = imu
        span = nav.start_rest(t_ns, gyro, acc, gravity, rest, nav.MIN_STILL_START_S)
        if span is None:
            return noise
        first, end = span[0], span[1]
        dt = float(np.median(np.diff(t_ns[first:end]))) * 1e-9
        g, a = (float(np.sqrt((np.max if rule == "max" else np.mean)(np.var(x[first:end], axis=0) * dt)))
                for x in (gyro, acc))
        return replace(noise, gyro_noise_density=max(g, noise.gyro_noise_density),
                       acc_noise_density=max(a, noise.acc_noise_density), gyro_axes=None, acc_axes=None)
    return floor


def rest_bias(imu_csv: Path):
    """``checkpoint_bias`` giving the bias the parked rest shows (the 34 s the track stands still)."""
    d = np.loadtxt(imu_csv, delimiter=",")
    gyro, f = np.radians(d[10:3435, 3:6]).mean(0), (d[10:3435, 0:3] * 9.80665).mean(0)
    b = np.r_[gyro, (np.linalg.norm(f) - NORMAL_GRAVITY) * f / np.linalg.norm(f)]
    return lambda checkpoint: (b.copy(), "the parked rest (experiment)")


def run(variant: str, offset: float, nhc: bool, drive: Path, out: Path, profile: Optional[Path] = None) -> dict:
    """One navigate run with ``variant`` in place; its gap ends."""
    saved = (nav.at_rest_floor, nav.checkpoint_bias)
    if variant in ("rms", "max"):
        nav.at_rest_floor = isotropic_rule(variant)
    if variant == "rest-bias":
        nav.checkpoint_bias = rest_bias(drive / "imu_1934.csv")
    starts = [36.77 + offset + 45 * i for i in range(12) if 36.77 + offset + 45 * i + 15 < 505]
    argv = ["navigate", "--quiet", "--input", str(drive / "imu_1934.csv"), "--aiding", str(drive / "gnss_1934_sf.pos"),
            "--groundtruth", str(drive / "gnss_1934_sf.pos"), "--gaps", ",".join(f"{s:.2f}:15" for s in starts),
            "--out", str(out)] + (["--imu-rotation-rpy-deg", MOUNTING, "--nhc"] if nhc else [])
    argv += ["--profile", str(profile), "--force"] if profile else []  # another recording's rate: its biases only
    try:
        entry(argv)
    except SystemExit as e:
        if e.code:
            raise
    finally:
        nav.at_rest_floor, nav.checkpoint_bias = saved
    s = json.loads((out / "summary.json").read_text())["scores"]["causal"]
    ends = [g["horizontal"]["end_m"] for g in s["gaps"]]
    return {"variant": variant, "offset_s": offset, "nhc": nhc, "profile": str(profile) if profile else None, "ends_m": [round(e, 2) for e in ends],
            "mean_m": round(float(np.mean(ends)), 3), "horizontal_rmse_m": round(s["horizontal_rmse_m"], 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path(os.environ.get("IMU_LEARN_DATA", "../shared/data")),
                    help="data root (default: $IMU_LEARN_DATA, else ../shared/data)")
    ap.add_argument("--offsets", default="0,15,30", help="seconds added to the peer's gap schedule")
    ap.add_argument("--variants", default="axes,rms,max,rest-bias")
    ap.add_argument("--nhc", action="store_true", help="with the mounting and --nhc")
    ap.add_argument("--profile", type=Path, help="a device profile given to every run")
    args = ap.parse_args()
    os.environ.setdefault("RAYON_NUM_THREADS", "1")
    drive = args.data / "gnss-imu" / "drive_0708"
    tmp = Path(tempfile.mkdtemp(prefix="drive_grids_"))
    try:
        for offset in (float(x) for x in args.offsets.split(",")):
            for variant in args.variants.split(","):
                print(json.dumps(run(variant, offset, args.nhc, drive, tmp / f"{variant}_{offset:g}", args.profile)), flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
