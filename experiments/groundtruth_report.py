"""Which ground truth does each recording's own IMU agree with, and in which body frame is it?

The check of one recording is the library's (imu_learn.eval.groundtruth, its doc gives the method;
``imu-learn groundtruth --input REC`` runs it on a recording of yours). This runs it over every
EuRoC / TUM-VI / Fetch recording under the data root and every ground-truth file each has, and
adds the TUM-VI motion-capture noise floor, drift and gap tables and the Fetch body frame.

    python experiments/groundtruth_report.py [--data ../shared/data] [--out docs/experiments/groundtruth.md]

Writes: docs/experiments/groundtruth.md (the whole page; about a minute). Data: EuRoC (euroc/, with
the extra ground-truth files of V1_01_easy), TUM-VI (tum-vi/dataset-room1..5_512_16) and Fetch
(fetch/) under --data (default $IMU_LEARN_DATA, else ../shared/data); missing ones are skipped.
"""
from __future__ import annotations

import argparse
import os
import time
from datetime import date
from pathlib import Path
from typing import List, Tuple

import numpy as np

from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.eval.groundtruth import (
    DRIFT_GAP_S,
    CheckOptions,
    GroundTruthCheck,
    Offset,
    check,
    drift,
    fmt_vec,
    gap_stats,
    gt_label,
    mocap_noise,
    pick_best,
    read,
    summary_line,
    survival,
)
from imu_learn.util.atomic import atomic_write_text

EUROC = ("MH_01_easy", "MH_03_medium", "MH_04_difficult", "MH_05_difficult", "V1_01_easy", "V1_03_difficult",
         "V2_01_easy", "V2_02_medium", "V2_03_difficult")
TUMVI = tuple(f"dataset-room{i}_512_16" for i in range(1, 6))
EUROC_GT = ("mav0/state_groundtruth_estimate0/data.csv", "groundtruth_pose.tum", "groundtruth_state_20hz.csv",
            "groundtruth_original_euroc.csv")
TUMVI_GT = ("mav0/mocap0/data.csv",)
FETCH = ("01_square", "03_um", "04_eight", "06_right_turn", "07_left_turn", "08_origin")
FETCH_GT = ("mav0/mocap0/data.csv",)
FETCH_GAP_S = 0.1  # the Fetch mocap has gaps up to 70 ms in every recording
GAPS_S = (0.05, 0.1, 0.3, 0.5)
Scored = Tuple[GroundTruthCheck, ImuData, GroundTruth, Offset]


def is_fetch(root: Path) -> bool:
    return root.parent.name == "fetch"


def score_gt(root: Path, gt_rel: str) -> Scored:
    """One ground-truth file of a recording: the library's check (a Fetch robot: gaps to 0.1 s, R_off
    from specific force), and what the TUM-VI tables need."""
    fetch = is_fetch(root)
    imu, gt = read(root, root / gt_rel, "fetch" if fetch else "euroc")
    options = CheckOptions(max_gap_s=FETCH_GAP_S, yaw_from_acc=True) if fetch else CheckOptions()
    row, off = check(imu, gt, root.name, gt_label(gt_rel), options)
    return row, imu, gt, off


# ---------------------------------------------------------------------------------------------
# report


def main_table(rows: List[GroundTruthCheck], best: dict) -> List[str]:
    out = ["| recording | GT file | rate [Hz] | samples (segs) | n=10 rot [°] / trans [m] | n=200 rot [°] / trans [m] "
           "| R_off [°] (axis) | τ [ms] | n=200 after R_off | n=200 after R_off + shift τ − dt/2 "
           "| lever arm [cm] ± se | verdict |", "|" + "---|" * 12]
    for r in rows:
        mark = " **best**" if best[r.recording] is r else ""
        out.append(f"| {r.recording} | {r.gt} | {r.rate_hz:.0f} | {r.samples} ({r.n_segments}) | "
                   f"{r.n10[0]:.4f} / {r.n10[1]:.5f} | {r.n200[0]:.3f} / {r.n200[1]:.4f} | "
                   f"{r.off_deg:.2f} {fmt_vec(r.off_axis)} | {r.tau_ms:+.1f} | "
                   f"{r.after_rot[0]:.3f} / {r.after_rot[1]:.4f} | {r.after_hold[0]:.3f} / {r.after_hold[1]:.4f} | "
                   f"{fmt_vec(r.lever_cm, 1)} ± {np.max(r.lever_se_cm):.1f} | {r.verdict}{mark} |")
    return out


def tumvi_frame(rows: List[GroundTruthCheck]) -> str:
    """One line: which body frame mocap0 is, from the fitted rotation, lever arm and time offset."""
    offs = [r.off_deg for r in rows]
    arms = [float(np.linalg.norm(r.lever_cm)) for r in rows]
    taus = [r.tau_ms for r in rows]
    frame = "the IMU frame" if max(offs) < 0.5 and max(arms) < 2 else "NOT the IMU frame"
    return (f"TUM-VI mocap0 is {frame}: R_off {min(offs):.2f}–{max(offs):.2f}°, lever arm |r| {min(arms):.1f}–"
            f"{max(arms):.1f} cm, τ {min(taus):+.1f}…{max(taus):+.1f} ms over {len(rows)} rooms.")


def fetch_frame(rows: List[GroundTruthCheck]) -> List[str]:
    """The Fetch mocap body frame against the IMU, in a few lines."""
    if not rows:
        return []
    offs = [r.off_deg for r in rows]
    taus = [r.tau_ms for r in rows]
    return ["", "## Fetch mocap0 body frame", "",
            f"Fetch (Debias_IMU) mocap0 against the IMU over {len(rows)} recordings, segments at max_gap_s = "
            f"{FETCH_GAP_S} (the mocap has gaps up to 70 ms): R_off {min(offs):.2f}–{max(offs):.2f}° "
            f"(fitted on specific force: the robot turns about z only, so the gyro leaves R_off's yaw free), "
            f"τ {min(taus):+.1f}…{max(taus):+.1f} ms. The pose is used as it is (no rotation, no time offset)."]


def noise_table(tum: List[Scored]) -> List[str]:
    out = ["", "## TUM-VI mocap0: noise floor", "",
           "σ: mocap orientation noise at the mocap's own 120 Hz stamps (RMSE of gyro vs. mocap relative rotation "
           "over h = 1..10 samples, fitted as RMSE² = 2σ² + k h²). Drift: raw gyro, bias removed, rotation RMSE "
           f"over 5 s / 20 s, windows every 10 samples from 10 s on, segments at max_gap_s = {DRIFT_GAP_S}.", "",
           "| room | σ mocap [°] | RMSE h=1 / 2 / 5 / 10 [°] | lag-1 autocorr. h=1 (white: −0.5) "
           "| 5 s start-up bias [°] | 20 s start-up bias [°] | 5 s whole-rec. bias [°] | 20 s whole-rec. bias [°] |",
           "|" + "---|" * 8]
    for row, imu, gt, off in tum:
        sigma, errs, lag1 = mocap_noise(imu, gt, off)
        d = drift(imu, gt)
        out.append(f"| {row.recording} | {sigma:.4f} | {errs[0]:.4f} / {errs[1]:.4f} / {errs[4]:.4f} / {errs[9]:.4f} "
                   f"| {lag1:+.2f} | {d['startup_5s']:.3f} | {d['startup_20s']:.3f} | {d['whole_5s']:.3f} "
                   f"| {d['whole_20s']:.3f} |")
    return out


def gap_table(tum: List[Scored]) -> List[str]:
    out = ["", "## TUM-VI mocap0: gaps and what survives per max_gap_s", "",
           "kept = IMU samples inside segments (min_segment_s = 1); score = bias-removed rot [°] / trans [m] at n=200 "
           "on those segments (gaps bridged by interpolation show up here).", "",
           "| room | gaps > 50 ms | gaps > 0.3 s | longest [s] | time in gaps [s] | "
           + " | ".join(f"max_gap {g} s: kept, segs, longest seg [s], score" for g in GAPS_S) + " |",
           "|" + "---|" * (5 + len(GAPS_S))]
    ok = dict.fromkeys(GAPS_S, True)
    for row, imu, gt, _ in tum:
        n50, n300, longest, total = gap_stats(gt)
        cells = [survival(imu, gt, g) for g in GAPS_S]
        for g, c in zip(GAPS_S, cells):
            ok[g] &= c[3] <= 1.05 * cells[0][3]
        out.append(f"| {row.recording} | {n50} | {n300} | {longest:.2f} | {total:.2f} | " + " | ".join(
            f"{100 * kept:.1f} %, {nseg}, {seg_s:.0f}, {rot:.3f} / {trans:.4f}" for kept, nseg, seg_s, rot, trans in cells)
            + " |")
    good = max(g for g in GAPS_S if ok[g])
    return out + ["", f"Largest max_gap_s whose 1 s rotation score stays within 5 % of max_gap 0.05's in every room: "
                  f"**{good}**."]


def header(seconds: float) -> List[str]:
    return ["# Ground truth vs. own IMU, per recording", "",
            "> **Measured:** every recording's ground truth against its own IMU: relative pose RMSE, a fitted "
            "rotation and time offset, a lever arm, TUM-VI's mocap noise and gaps.  ",
            "> **Command:** `python experiments/groundtruth_report.py` (one recording: "
            "`imu-learn groundtruth --input REC`).  ",
            "> **Data:** EuRoC MAV (`euroc/`), TUM-VI (`tum-vi/`), Fetch (`fetch/`) under the data root.  ",
            f"> **Date:** {date.today().isoformat()} (generated).", "",
            f"Generated by `experiments/groundtruth_report.py` in {seconds:.0f} s (method: its docstring).", "",
            "Bias: one constant gyro + accelerometer bias per recording, fitted on the whole recording (medians "
            "of 10-sample window residuals, as experiments/label_agreement.py). Relative pose RMSE over every window "
            "(stride 1) of n IMU samples. R_off maps GT-body vectors to the IMU frame (axis in either frame); "
            "τ > 0: GT stamps late (IMU(t) ≈ GT(t + τ)). Segments at max_gap_s = 0.05 (0.075 for the 20 Hz "
            "state). Lever arm: IMU origin in the GT body frame. Best = lowest rot n=200 per recording (ties to "
            "the ASL layout's own file). The metric's integrator holds IMU sample k over [t_k, t_k+1], half a "
            "period after it was taken; the column 'after R_off + shift τ − dt/2' undoes that.", ""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path(os.environ.get("IMU_LEARN_DATA", "../shared/data")))
    ap.add_argument("--out", type=Path, default=Path("docs/experiments/groundtruth.md"))
    args = ap.parse_args()
    start = time.time()
    jobs = [(args.data / "euroc" / r, EUROC_GT) for r in EUROC] + [(args.data / "tum-vi" / r, TUMVI_GT) for r in TUMVI]
    jobs += [(args.data / "fetch" / r, FETCH_GT) for r in FETCH]
    results = []
    for root, cands in jobs:
        for gt_rel in cands:
            if (root / gt_rel).is_file():
                results.append(score_gt(root, gt_rel))
                r = results[-1][0]
                print(f"{r.recording} / {r.gt}: n=200 rot {r.n200[0]:.3f}°, R_off {r.off_deg:.2f}°, "
                      f"τ {r.tau_ms:+.1f} ms, lever {fmt_vec(r.lever_cm, 1)} cm ({time.time() - start:.0f} s)", flush=True)
    rows = [x[0] for x in results]
    best = pick_best(rows)
    tum = [x for x in results if x[0].recording in TUMVI]
    tum_lines = ["", "## TUM-VI body frame", "", tumvi_frame([x[0] for x in tum])] + noise_table(tum) + gap_table(tum)
    tum_lines += fetch_frame([x[0] for x in results if x[0].recording in FETCH])
    lines = header(time.time() - start) + main_table(rows, best) + tum_lines
    lines += ["", "## Per recording", ""] + [f"- {summary_line(rec, rows, b)}" for rec, b in best.items()]
    text = "\n".join(lines) + "\n"
    atomic_write_text(args.out, text)
    print(text)
    print(f"wrote {args.out} in {time.time() - start:.0f} s")


if __name__ == "__main__":
    main()
