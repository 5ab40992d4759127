"""Calibrate from the references users have, scored where no fit has been: EuRoC's motion capture
against ORB-SLAM2 stereo poses (left camera, first-camera world, no extrinsic given) and wrong
references (rotated, late), each a profile of the same four flights scored open loop on unseen ones.

For each reference kind: ``imu-learn calibrate --input F --groundtruth REF ...`` on MH_01, MH_03, MH_05
and V2_01 (as a user runs it), then on each test flight ``imu-learn refine --profile P --bias
still+gravity`` and the peers' open-loop figures of the refined IMU against the flight's ground truth
(score.peers: AOE RMSE, RO_RMSE and RP_RMSE over 1 s windows). The estimated extrinsic is compared with
cam0's ``T_BS`` (euroc-vo/cam0_sensor.yaml).

Kinds: ``mocap`` (the ground truth as given), ``mocap20hz`` (its every 10th pose: a 20 Hz reference
already in the IMU's frame), ``orbslam2``, ``orbslam2+extrinsics`` (cam0's ``T_BS`` given, or ``--extrinsics``'s:
the rectified left camera's, cam0's composed with ORB-SLAM2's ``LEFT.R``ᵀ), ``rot90``,
``rot119``, ``rot180`` (the ground truth's body rotated about (1, 2, 3)), ``late100ms``, ``monoS`` /
``monoSdD`` (ORB-SLAM2's poses with each step of their positions multiplied by S, or by a scale drifting
linearly from S to S·(1 + D) along the flight: a monocular VO's unknown, drifting scale); a ``+select``
suffix adds ``calibrate --select`` (the floor's terms chosen on held-out recordings), without it
``--no-select`` (every term).

    IMU_LEARN_DATA=<root> python experiments/reference_kinds.py [--out reports/reference_kinds] [--trial 0] \
        [--kinds mocap,orbslam2,orbslam2+select] [--extrinsics T_BS.yaml]

Data: under the data root, euroc/<flight>, euroc-vo/orbslam2_stereo/trial<k>/<code>.txt,
euroc-vo/cam0_sensor.yaml. Prints one markdown table; writes OUT/results.json. Writes:
docs/experiments/references.md ("6-DoF poses in another frame"; "ORB-SLAM2 runs 3 and 4, and V2_02's
translation").
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List

import numpy as np

from imu_learn.core.quat import quat_mul, wxyz_to_xyzw, xyzw_to_wxyz
from imu_learn.data.formats import read_imu_source, read_recording
from imu_learn.data.formats.extrinsics import read_t_bs
from imu_learn.data.loading import AlignOptions, align
from imu_learn.score.peers import PeerErrors, add_segment, segment_errors, summarise

TRAIN = {"MH_01_easy": "MH01", "MH_03_medium": "MH03", "MH_05_difficult": "MH05", "V2_01_easy": "V201"}
TEST = ["MH_04_difficult", "V1_03_difficult", "V2_02_medium"]


def run(cmd: List[str]) -> subprocess.CompletedProcess:
    print("$ " + " ".join(cmd), file=sys.stderr, flush=True)
    return subprocess.run(cmd, capture_output=True, text=True)


def rotated_tum(src: Path, dst: Path, deg: float, axis: np.ndarray, late_s: float = 0.0) -> Path:
    """A TUM trajectory with its body frame rotated by ``deg`` about ``axis`` and stamps ``late_s`` late."""
    rows = np.loadtxt(src, comments="#")
    a = math.radians(deg)
    q_rot = np.r_[math.cos(a / 2), math.sin(a / 2) * axis / np.linalg.norm(axis)]
    q = quat_mul(xyzw_to_wxyz(rows[:, 4:8]), q_rot[None])
    out = np.column_stack([rows[:, 0] + late_s, rows[:, 1:4], wxyz_to_xyzw(q)])
    np.savetxt(dst, out, fmt="%.9f")
    return dst


def tum_of_groundtruth(flight: Path, dst: Path) -> Path:
    _, gt = read_recording(flight)
    np.savetxt(dst, np.column_stack([gt.t_ns * 1e-9, gt.p, wxyz_to_xyzw(gt.q_wxyz)]), fmt="%.9f")
    return dst


def monocular_tum(src: Path, dst: Path, scale: float, drift: float) -> Path:
    """A TUM trajectory whose position steps are multiplied by a scale going linearly from ``scale`` to
    ``scale * (1 + drift)`` over its span (the first position scaled by ``scale``)."""
    lines = [ln.split() for ln in src.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    rows = np.array([[float(x) for x in ln] for ln in lines])
    t = rows[:, 0]
    s = scale * (1.0 + drift * (t - t[0]) / (t[-1] - t[0]))
    steps = s[1:, None] * np.diff(rows[:, 1:4], axis=0)
    p = np.vstack([scale * rows[:1, 1:4], scale * rows[:1, 1:4] + np.cumsum(steps, axis=0)])
    # the stamps and quaternions as written (a stamp printed again moves it by a few ns)
    dst.write_text("".join(f"{ln[0]} {x:.9f} {y:.9f} {z:.9f} {' '.join(ln[4:8])}\n" for ln, (x, y, z) in zip(lines, p)))
    return dst


def thinned_tum(src: Path, dst: Path, every: int) -> Path:
    """Every ``every``-th pose of a TUM trajectory (the 200 Hz ground truth as a 20 Hz reference)."""
    rows = np.loadtxt(src, comments="#")
    np.savetxt(dst, rows[::every], fmt="%.9f")
    return dst


def score(flight: Path, refined: Path) -> Dict[str, float]:
    imu, gt = read_recording(flight)
    src = read_imu_source(refined)
    e = PeerErrors()
    for s in align(imu, gt, AlignOptions(max_gap_s=0.05)).segments:
        i0 = int(np.searchsorted(src.t_ns, s.t_ns[0]))
        g, a = src.gyro[i0:i0 + len(s)], src.acc[i0:i0 + len(s)]
        add_segment(e, segment_errors(s, g, a))
    return summarise(e)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("reports/reference_kinds"))
    ap.add_argument("--trial", type=int, default=0)
    ap.add_argument("--kinds", default="mocap,orbslam2,orbslam2+extrinsics,rot90,rot119,rot180,late100ms")
    ap.add_argument("--extrinsics", type=Path, default=None,
                    help="the T_BS yaml of the +extrinsics kinds and of the extrinsic's error (default: "
                         "euroc-vo/cam0_sensor.yaml under the data root)")
    args = ap.parse_args()
    root = Path(os.environ.get("IMU_LEARN_DATA", "datasets"))
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    vo = root / "euroc-vo" / "orbslam2_stereo" / f"trial{args.trial}"
    cam0 = args.extrinsics or root / "euroc-vo" / "cam0_sensor.yaml"
    exe = [sys.executable, "-m", "imu_learn.cli"]
    results: Dict[str, dict] = {}
    for kind in args.kinds.split(","):
        calib = out / kind
        cmd = exe + ["calibrate", "--out", str(calib), "--no-plot", "--device", "euroc-adis16448"]
        for flight, code in TRAIN.items():
            f = root / "euroc" / flight
            base = kind.split("+")[0]
            if base == "mocap":
                ref = tum_of_groundtruth(f, out / f"{flight}_gt.tum")
            elif base == "mocap20hz":
                ref = thinned_tum(tum_of_groundtruth(f, out / f"{flight}_gt.tum"), out / f"{flight}_gt20.tum", 10)
            elif base == "orbslam2":
                ref = vo / f"{code}.txt"
            elif base.startswith("mono"):
                scale, _, drift = base[4:].partition("d")
                ref = monocular_tum(vo / f"{code}.txt", out / f"{flight}_{base}.tum", float(scale), float(drift or 0))
            elif base.startswith("rot"):
                ref = rotated_tum(tum_of_groundtruth(f, out / f"{flight}_gt.tum"), out / f"{flight}_{base}.tum",
                                  float(base[3:]), np.array([1.0, 2.0, 3.0]))
            elif base == "late100ms":
                ref = rotated_tum(tum_of_groundtruth(f, out / f"{flight}_gt.tum"), out / f"{flight}_{base}.tum",
                                  0.0, np.array([0, 0, 1.0]), late_s=0.1)
            else:
                raise SystemExit(f"unknown reference kind {kind!r}")
            cmd += ["--input", str(f), "--groundtruth", str(ref)]
        if "+extrinsics" in kind:
            cmd += ["--extrinsics", str(cam0)]
        # the floor's terms chosen on held-out recordings (calib.select), else every term (calibrate's
        # default for a 20-30 Hz VO is the selection since 2026-11-29; the tables before it fitted every term)
        cmd += ["--select"] if "+select" in kind else ["--no-select"]
        t0 = time.time()
        res = run(cmd)
        row: dict = {"exit": res.returncode, "seconds": round(time.time() - t0, 1),
                     "said": (res.stdout + res.stderr).strip().splitlines()[-12:]}
        print(f"{kind}: exit {res.returncode} in {row['seconds']} s", file=sys.stderr)
        profile = calib / "profile.json"
        if res.returncode == 0 and profile.exists():
            prof = json.loads(profile.read_text())
            ref_fit = prof.get("reference") or {}
            if "rotation_imu_from_reference" in ref_fit:
                r = np.asarray(ref_fit["rotation_imu_from_reference"])
                t_bs = read_t_bs(cam0)[:3, :3]
                row["extrinsic_error_deg"] = math.degrees(math.acos(np.clip((np.trace(r @ t_bs.T) - 1) / 2, -1, 1)))
            row["gyro_bias"] = prof["gyroscope"]["bias"]
            row["acc_bias"] = prof["accelerometer"]["bias"]
            row["acc_matrix"] = prof["accelerometer"]["matrix"]
            row["floor"] = {k: prof["floor"].get(k) for k in ("time_offset", "cutoff_gyro", "cutoff_acc", "M_g", "G")}
            row["selection"] = {k: prof.get("selection", {}).get(k) for k in ("gyro", "acc", "skipped")}
            for flight in TEST:
                f = root / "euroc" / flight
                dst = out / f"{kind}_{flight}"
                r = run(exe + ["refine", "--profile", str(profile), "--input", str(f), "--out", str(dst),
                               "--bias", "still+gravity", "--force"])
                if r.returncode != 0:
                    row[flight] = {"refine_exit": r.returncode, "said": r.stderr.strip()[-300:]}
                    continue
                row[flight] = score(f, dst)
        results[kind] = row
        (out / "results.json").write_text(json.dumps(results, indent=2, default=float))
    print("| reference | exit | s | extrinsic err [deg] | " + " | ".join(f"{f[:5]} AOE / RO 1s / RP 1s" for f in TEST) + " |")
    print("|---|---|---|---|" + "---|" * len(TEST))
    for kind, row in results.items():
        cells = []
        for f in TEST:
            s = row.get(f)
            cells.append(f"{s['aoe_deg']:.2f}° / {s['ro_rmse_deg']:.3f}° / {100 * s['rp_rmse_m']:.2f} cm"
                         if s and "aoe_deg" in s else "-")
        ext = row.get("extrinsic_error_deg")
        print(f"| {kind} | {row['exit']} | {row['seconds']} | {'-' if ext is None else f'{ext:.2f}'} | "
              + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
