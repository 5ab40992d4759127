"""The paper's long-term navigation tables (its Tables I and III) beside ours, from a fusion
experiment's results:

    python experiments/fusion_paper_tables.py [reports/fuse_euroc/results.json] [--scenario vo_10hz]

Our analogue of the paper's visual-inertial setting is the simulated 10 Hz relative-pose aiding
(no absolute fix, so the position drifts as in visual odometry): full-trajectory position RMSE
[m], causal (live) and smoothed, for each IMU input on each test flight, then the average over
the flights (the paper's Table III "EuRoC" column); mean ± std over the noise seeds. Prints markdown.

Writes: docs/experiments/fusion.md, "Beside the paper's Tables I and III". Data: the results.json
of ``imu-learn fuse --config configs/fuse_euroc.toml`` (reports/fuse_euroc).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Dict, List

from imu_learn.fuse.experiments.batch import NOT_IN_AVERAGE, average, cell_text, complete_seeds, runs_by_cell

# Quoted from the paper (Zhang et al., Table I: positional RMSE [m] over the entire trajectories,
# the processed IMU fused with visual data; VINS as reported by its authors). MH_02 has no IMU here.
PAPER_TABLE1 = {
    "MH_02_easy": {"Tr.": 0.185, "VINS": 0.150, "TLIO": 0.303, "End-to-End": 3.307, "Pr.": 0.150},
    "MH_04_difficult": {"Tr.": 0.151, "VINS": 0.320, "TLIO": 0.823, "End-to-End": 5.199, "Pr.": 0.138},
    "V1_03_difficult": {"Tr.": 0.267, "VINS": 0.180, "TLIO": 0.653, "End-to-End": 5.329, "Pr.": 0.147},
    "V2_02_medium": {"Tr.": 0.111, "VINS": 0.160, "TLIO": 0.509, "End-to-End": 2.897, "Pr.": 0.104},
    "V1_01_easy": {"Tr.": 0.081, "VINS": 0.079, "TLIO": 0.343, "End-to-End": 8.166, "Pr.": 0.066},
}
# Table III, EuRoC column (average positional RMSE [m]).
PAPER_TABLE3_EUROC = {"Tr.": 0.1592, "Pr.": 0.1210, "VINS": 0.1778, "End-to-End": 2.0402, "TLIO": 0.5262}
INPUT_LABEL = {"raw": "raw", "traditional": "Tr. (traditional)", "proposed": "Pr. (proposed)"}


def ours(runs: Dict[str, dict], scenario: str) -> List[str]:
    """Per flight: mean ± std over the noise seeds; the average: each seed's average over the test
    flights, then mean ± std over the seeds every test flight has."""
    cells = runs_by_cell(runs)
    recs = list(dict.fromkeys(rec for rec, s, _ in cells if s == scenario))
    inputs = list(dict.fromkeys(i for _, s, i in cells if s == scenario))
    lines = ["| input | " + " | ".join(f"{x} causal / smoothed" for x in recs)
             + " | average of the test flights, causal / smoothed |", "|---|" + "---|" * (len(recs) + 1)]
    for i in inputs:
        row = [f"{cell_text(cells[(rec, scenario, i)], 'causal')} / {cell_text(cells[(rec, scenario, i)], 'smoothed')}"
               for rec in recs]
        test = [r for rec in recs if rec not in NOT_IN_AVERAGE for r in cells[(rec, scenario, i)]]
        seeds = complete_seeds(test, len([rec for rec in recs if rec not in NOT_IN_AVERAGE]))
        avg = [average(test, kind, seeds) for kind in ("causal", "smoothed")]
        lines.append(f"| {INPUT_LABEL.get(i, i)} | " + " | ".join(row) + f" | {' / '.join(avg)} |")
    return lines


def paper() -> List[str]:
    cols = ["Tr.", "VINS", "TLIO", "End-to-End", "Pr."]
    lines = ["| sequence | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
    for seq, row in PAPER_TABLE1.items():
        lines.append(f"| {seq} | " + " | ".join(f"{row[c]:.3f}" for c in cols) + " |")
    lines.append("| Average (Table III, EuRoC) | " + " | ".join(f"{PAPER_TABLE3_EUROC[c]:.4f}" for c in cols) + " |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="?", default="reports/fuse_euroc/results.json")
    ap.add_argument("--scenario", default="vo_10hz")
    a = ap.parse_args(argv)
    runs = json.loads(Path(a.results).read_text())["runs"]
    print(f"Ours ({a.results}, scenario {a.scenario}): position RMSE [m] over the whole trajectory\n")
    print("\n".join(ours(runs, a.scenario)))
    print("\nQuoted: the paper's Table I (and Table III's EuRoC average), position RMSE [m]\n")
    print("\n".join(paper()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
