"""Relative-pose aiding with breaks on another device: Blackbird's motion capture made into a VO's output
(a forward camera 8 cm from the IMU, a world turned 35 / 8 / -6 deg and shifted, 20 Hz, white noise of
5 mm and 0.2 deg per pose), fused with ``imu-learn navigate``'s default relative-pose path, with and
without two 10 s camera gaps, raw IMU and the shipped Blackbird profile. Variants of the rules the
navigator applies to aiding with breaks (set by replacing two functions of ``imu_learn.fuse.aiding.kinds``
for the run; the package is not changed):

* ``shipped``: as the package runs it;
* ``raised``: the consecutive chain's default sigmas raised, per axis, to the noise estimated from the data;
* ``world-x1``: the world's poses at their own noise in the causal solver (no inflation for the map's slow
  error);
* ``raised+world-x1``: both.

    IMU_LEARN_DATA=DIR python experiments/vo_like_breaks.py [--recording train] [--out reports/vo_like_breaks]

Writes: one JSON line per run on stdout (docs/experiments/navigate-vo.md, "A VO with white errors on
another device"); the VO-like files and each run's navigate outputs under ``--out``. Data:
``blackbird/clover_yawForward_maxSpeed5p0/<recording>`` (IMU and ``stamped_groundtruth_imu.txt``) under
the data root; the profile ``models/profiles/blackbird_clover/profile.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from imu_learn.core.quat import wxyz_to_xyzw
from imu_learn.data.formats.groundtruth import read_groundtruth
from imu_learn.fuse.aiding import kinds
from imu_learn.fuse.aiding.noise import PoseNoise
from imu_learn.fuse.navigate import NavigateOptions, Sources, navigate, parse_gaps
from imu_learn.fuse.output import write_trajectory

REPO = Path(__file__).resolve().parents[1]
PROFILE = REPO / "models" / "profiles" / "blackbird_clover" / "profile.json"
R_BC = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=float)  # camera axes (columns) in the IMU frame
T_BC = np.array([0.08, -0.01, 0.03])
WORLD_RPY_DEG, WORLD_SHIFT = (35.0, 8.0, -6.0), np.array([2.0, -1.0, 0.5])
SIGMA_M, SIGMA_DEG, EVERY = 0.005, 0.2, 5  # per pose; every 5th ground-truth row (100 Hz -> 20 Hz)


def make_vo(gt_txt: Path, out: Path, seed: int = 0) -> tuple:
    """(VO-like TUM file, its T_BS yaml, the ground truth as TUM) written into ``out`` from Blackbird's
    ``stamped_groundtruth_imu.txt`` (the IMU's pose in the world; the package's reader and writer)."""
    gt = read_groundtruth(gt_txt)
    rng = np.random.default_rng(seed)
    k = np.arange(0, len(gt.t_ns), EVERY)
    R_wi = Rotation.from_quat(wxyz_to_xyzw(gt.q_wxyz[k])).as_matrix()
    R_vw = Rotation.from_euler("zyx", WORLD_RPY_DEG, degrees=True).as_matrix()
    R_vc = Rotation.from_rotvec(rng.normal(0, np.radians(SIGMA_DEG), (len(k), 3))).as_matrix() @ (R_vw @ R_wi @ R_BC)
    p_vc = (R_vw @ (gt.p[k] + np.einsum("nij,j->ni", R_wi, T_BC)).T).T + WORLD_SHIFT + rng.normal(0, SIGMA_M, (len(k), 3))
    vo, yaml, gt_tum = out / "vo.tum", out / "T_BC.yaml", out / "groundtruth.tum"
    write_trajectory(vo, gt.t_ns[k], p_vc, R_vc)
    write_trajectory(gt_tum, gt.t_ns, gt.p, Rotation.from_quat(wxyz_to_xyzw(gt.q_wxyz)).as_matrix())
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R_BC, T_BC
    yaml.write_text("%YAML:1.0\nT_BS:\n  cols: 4\n  rows: 4\n  data: [" + ", ".join(f"{x:.12g}" for x in T.ravel()) + "]\n")
    return vo, yaml, gt_tum


SHIPPED_NOISE, SHIPPED_INFLATION = kinds.relative_noise, kinds.world_inflation


def raised_noise(rows, opts, whole=True):
    """The shipped rule, its default sigmas raised per axis to the data's estimate."""
    noise, source = SHIPPED_NOISE(rows, opts, whole)
    if source == "default" and rows.noise is not None:
        e = rows.noise
        noise = PoseNoise(np.maximum(noise.rot_rad, e.rot_rad), np.maximum(noise.trans_m, e.trans_m),
                          e.n_rot, e.n_trans, e.span_s)
        source = "default raised to the estimate"
    return noise, source


def use_variant(name: str) -> None:
    kinds.relative_noise = raised_noise if "raised" in name else SHIPPED_NOISE
    kinds.world_inflation = (lambda t_ns: 1.0) if "world-x1" in name else SHIPPED_INFLATION


def run(variant: str, imu: Path, files: tuple, profile: bool, gaps: str, out: Path) -> dict:
    use_variant(variant)
    vo, yaml, gt = files
    opts = NavigateOptions(aiding_kind="relative-pose")
    if gaps != "none":
        opts = replace(opts, gaps=parse_gaps(gaps))
    t0 = time.time()
    s = navigate(Sources(input=imu, aiding=vo, extrinsics=yaml, groundtruth=gt,
                         profile=PROFILE if profile else None), out, opts)
    sc = s["scores"]
    used = s["aiding_estimates"]["noise_used"] if "aiding_estimates" in s else None
    return {"variant": variant, "imu": "profile" if profile else "raw", "gaps": gaps,
            "causal_at_aiding_stamps_m": round(sc["causal_at_aiding_stamps"]["pos_rmse_m"], 4),
            "aiding_alone_m": round(sc["aiding_only"]["pos_rmse_m"], 4),
            "causal_m": round(sc["causal"]["pos_rmse_m"], 4), "smoothed_m": round(sc["smoothed"]["pos_rmse_m"], 4),
            "gap_ends_m": [round(g["end_m"], 3) for g in sc["causal"].get("gaps", [])],
            "noise_used": used, "seconds": round(time.time() - t0)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("IMU_LEARN_DATA", str(REPO.parent / "shared" / "data")))
    ap.add_argument("--recording", default="train")
    ap.add_argument("--gaps", default="30:10,60:10")
    ap.add_argument("--variants", default="shipped,raised,world-x1,raised+world-x1")
    ap.add_argument("--out", type=Path, default=Path("reports/vo_like_breaks"))
    a = ap.parse_args()
    rec = Path(a.data) / "blackbird" / "clover_yawForward_maxSpeed5p0" / a.recording
    files = make_vo(rec / "stamped_groundtruth_imu.txt", a.out / "vo")
    for variant in a.variants.split(","):
        for gaps in (("none", a.gaps) if variant == "shipped" else (a.gaps,)):
            for profile in (False, True):
                tag = f"{variant}_{'profile' if profile else 'raw'}_{gaps.replace(':', '_').replace(',', '-')}"
                print(json.dumps(run(variant, rec, files, profile, gaps, a.out / tag)), flush=True)


if __name__ == "__main__":
    main()
