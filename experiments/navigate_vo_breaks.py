"""Navigate EuRoC's flights with their ORB-SLAM2 stereo trajectories as relative-pose aiding, with and
without two 10 s camera gaps, and tabulate what the navigator promises for VO aiding: the causal and
the smoothed tracks against the VO alone at its stamps, the coasting through each gap.

Per flight and setting it runs (the shipped EuRoC profile; ground truth read only by the scoring):

    imu-learn navigate --quiet --input DATA/euroc/REC --aiding DATA/euroc-vo/orbslam2_stereo/TRIAL/VO.txt
        --aiding-kind relative-pose --extrinsics DATA/euroc-vo/cam0_sensor.yaml --groundtruth GT
        --profile models/profiles/euroc_adis16448/profile.json --out OUT/TRIAL/GAPS/REC [--gaps 30:10,70:10]

(GT: mav0/state_groundtruth_estimate0/data.csv; V1_01: its groundtruth_state_20hz.csv), two flights at a
time, then prints one markdown row per trial and setting: the mean aligned causal RMSE, how many flights
have the causal (smoothed) track at or below the VO at the VO's stamps and the largest ratio, the RMS of
the in-gap errors summary.json reports, and the coasting drift: per gap, the causal track's
displacement from the gap's start against the truth's (rotated by a rigid alignment on the 20 s before
the gap), RMS over the gap and at its last keyframe before the camera returns.

    IMU_LEARN_DATA=<root> python experiments/navigate_vo_breaks.py [--trials trial0,trial1,trial2]
        [--out reports/navigate_vo_breaks] [--tabulate-only] [--raw] [--extrinsics T_BS.yaml] [--keep-aiding-frame]

Data: under the data root, euroc/<flight> (ASL layout) and euroc-vo/orbslam2_stereo/<trial>/<VO>.txt
with euroc-vo/cam0_sensor.yaml.
With ``--raw`` the same runs without ``--profile`` go under OUT/raw/; the profile's table then puts each
gap's coasting drift beside the raw IMU's. ``--extrinsics`` gives another T_BS (ORB-SLAM2's rectified left
camera: cam0's composed with its settings' LEFT.R transposed); ``--keep-aiding-frame`` passes navigate's
(the poses not turned onto the gyro's frame).

Writes: OUT/<trial>/<none|30_10_70_10>/<flight>/ (navigate's outputs) and OUT/table.md (with ``--raw``:
OUT/raw/...); the figures of docs/experiments/navigate-vo.md ("The world's poses weighed as the map's slow
error", "Re-measured", "The poses' frame turned onto the gyro's").
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from imu_learn.fuse.score import umeyama

FLIGHTS = {"MH_01_easy": "MH01", "MH_03_medium": "MH03", "MH_04_difficult": "MH04", "MH_05_difficult": "MH05",
           "V1_01_easy": "V101", "V1_03_difficult": "V103", "V2_01_easy": "V201", "V2_02_medium": "V202"}
GAPS = ("none", "30:10,70:10")
PROFILE = "models/profiles/euroc_adis16448/profile.json"


def groundtruth(data: Path, rec: str) -> Path:
    flight = data / "euroc" / rec
    return flight / "groundtruth_state_20hz.csv" if rec == "V1_01_easy" else \
        flight / "mav0" / "state_groundtruth_estimate0" / "data.csv"


def folder(gaps: str) -> str:
    """A gap setting's folder name (``30:10,70:10`` -> ``30_10_70_10``)."""
    return gaps.replace(":", "_").replace(",", "_")


def navigate(data: Path, trial: str, gaps: str, rec: str, out: Path, raw: bool = False,
             extrinsics: Optional[Path] = None, keep_frame: bool = False) -> Optional[str]:
    cmd = [sys.executable, "-m", "imu_learn.cli", "navigate", "--quiet", "--input", str(data / "euroc" / rec),
           "--aiding", str(data / "euroc-vo" / "orbslam2_stereo" / trial / f"{FLIGHTS[rec]}.txt"),
           "--aiding-kind", "relative-pose", "--extrinsics", str(extrinsics or data / "euroc-vo" / "cam0_sensor.yaml"),
           "--groundtruth", str(groundtruth(data, rec)), "--out", str(out)]
    if not raw:
        cmd += ["--profile", PROFILE]
    if gaps != "none":
        cmd += ["--gaps", gaps]
    if keep_frame:
        cmd += ["--keep-aiding-frame"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    return None if done.returncode == 0 else f"{rec}: exit {done.returncode}: {done.stderr.strip()[-300:]}"


def coast_drift(run: Path, gt_csv: Path) -> List[Dict[str, float]]:
    """Per gap of ``run``'s summary: the causal track's drift over it (module doc): ``rms_m``, ``end_m``."""
    gt = np.loadtxt(gt_csv, delimiter=",", comments="#")
    tg, pg = gt[:, 0] * 1e-9, gt[:, 1:4]
    track = np.loadtxt(run / "causal.tum")
    t, p = track[:, 0], track[:, 1:4]
    rel = t - t[0]
    inside = (t >= tg[0]) & (t <= tg[-1])
    g = np.stack([np.interp(t, tg, pg[:, i]) for i in range(3)], axis=1)
    out = []
    for gap in json.loads((run / "summary.json").read_text())["scores"]["causal"].get("gaps", []):
        s, e = gap["start_s"], gap["start_s"] + gap["duration_s"]
        before = inside & (rel >= s - 20.0) & (rel < s)
        during = np.flatnonzero(inside & (rel >= s) & (rel < e - 0.1))  # the camera's return re-anchors at e
        if before.sum() < 10 or len(during) < 2:
            continue
        R = umeyama(p[before], g[before])[0]
        k0 = during[0]
        err = np.linalg.norm((p[during] - p[k0]) @ R.T - (g[during] - g[k0]), axis=1)
        out.append({"rms_m": float(np.sqrt(np.mean(err ** 2))), "end_m": float(err[-1])})
    return out


def row(data: Path, trial: str, gaps: str, base: Path) -> str:
    causal, cv, sv, in_gaps, drift = [], [], [], [], []
    for rec in FLIGHTS:
        run = base / rec
        if not (run / "summary.json").exists():
            continue
        sc = json.loads((run / "summary.json").read_text())["scores"]
        vo = sc["aiding_only"]["pos_rmse_m"]
        causal.append(sc["causal"]["pos_rmse_m"])
        cv.append(sc["causal_at_aiding_stamps"]["pos_rmse_m"] / vo)
        sv.append(sc["smoothed_at_aiding_stamps"]["pos_rmse_m"] / vo)
        in_gaps += [g["rmse_m"] for g in sc["causal"].get("gaps", [])]
        drift += coast_drift(run, groundtruth(data, rec))
    if not causal:
        return f"| {trial} | {gaps} | (no runs) |"
    gap_cells = "| - | - |" if not drift else (
        f"| {np.sqrt(np.mean(np.square(in_gaps))):.3f} | {np.sqrt(np.mean([d['rms_m'] ** 2 for d in drift])):.3f} / "
        f"{np.mean([d['end_m'] for d in drift]):.3f} |")
    return (f"| {trial} | {gaps} | {len(causal)} | {np.mean(causal):.3f} | {sum(x <= 1.0 for x in cv)}, max {max(cv):.3f} "
            f"| {sum(x <= 1.0 for x in sv)}, max {max(sv):.3f} {gap_cells}")


def flight_rows(data: Path, trials: List[str], out: Path) -> List[str]:
    """One row per flight and run: causal and smoothed over the VO at its stamps, without and with the gaps,
    and each gap's coasting drift RMS (the raw IMU's beside it where ``out/raw`` holds the same run)."""
    lines = ["| run | flight | causal / VO, smoothed / VO: no gaps | with the gaps | coasting drift RMS per gap [m] "
             "| raw IMU's |", "|---|---|---|---|---|---|"]
    for trial in trials:
        for rec in FLIGHTS:
            cells = []
            for gaps in GAPS:
                run = out / trial / folder(gaps) / rec
                if not (run / "summary.json").exists():
                    cells.append("-")
                    continue
                r = json.loads((run / "summary.json").read_text())["scores"]["against_aiding"]["ratio"]
                cells.append(f"{r['causal']:.3f}, {r['smoothed']:.3f}")
            gapped = folder(GAPS[1])
            drift = [coast_drift(base / trial / gapped / rec, groundtruth(data, rec))
                     if (base / trial / gapped / rec / "summary.json").exists() else []
                     for base in (out, out / "raw")]
            cells += [", ".join(f"{d['rms_m']:.2f}" for d in ds) or "-" for ds in drift]
            lines.append(f"| {trial} | {rec} | " + " | ".join(cells) + " |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", default="trial0,trial1,trial2")
    ap.add_argument("--out", type=Path, default=Path("reports/navigate_vo_breaks"))
    ap.add_argument("--tabulate-only", action="store_true", help="only the table, from OUT's runs")
    ap.add_argument("--raw", action="store_true", help="the raw IMU (no --profile), its runs under OUT/raw/")
    ap.add_argument("--extrinsics", type=Path, default=None,
                    help="the poses' T_BS yaml (default: DATA/euroc-vo/cam0_sensor.yaml)")
    ap.add_argument("--keep-aiding-frame", action="store_true",
                    help="navigate's --keep-aiding-frame: the poses fused in the extrinsic's frame, not turned onto the gyro's")
    args = ap.parse_args()
    data = Path(os.environ.get("IMU_LEARN_DATA", ""))
    if not (data / "euroc-vo").is_dir():
        sys.exit("set IMU_LEARN_DATA to the data root (euroc/, euroc-vo/)")
    trials = args.trials.split(",")
    out = args.out / "raw" if args.raw else args.out
    if not args.tabulate_only:
        jobs = [(t, g, r) for t in trials for g in GAPS for r in FLIGHTS]
        with ThreadPoolExecutor(2) as pool:
            for err in pool.map(lambda j: navigate(data, *j, out / j[0] / folder(j[1]) / j[2], args.raw,
                                                 args.extrinsics, args.keep_aiding_frame), jobs):
                if err:
                    print(err, file=sys.stderr)
    lines = ["| run | gaps | flights | causal, mean aligned RMSE [m] | causal <= VO at its stamps (flights), largest "
             "ratio | smoothed <= VO, largest ratio | in the gaps, RMS [m] | coasting drift RMS / mean end [m] |",
             "|---|---|---|---|---|---|---|---|"]
    lines += [row(data, t, g, out / t / folder(g)) for t in trials for g in GAPS]
    if not args.raw:
        lines += [""] + flight_rows(data, trials, out)
    text = "\n".join(lines) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "table.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
