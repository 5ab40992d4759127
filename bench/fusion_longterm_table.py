"""The long-term navigation table across fusion experiments (README "Inertial-aided navigation"):

    python bench/fusion_longterm_table.py reports/fuse_euroc/results.json reports/fuse_tumvi/results.json ...

One row per experiment x aiding setting, one column pair per IMU input: position RMSE [m] over the
whole trajectory, causal / smoothed, averaged over the experiment's test recordings (EuRoC's MH_01
is reported on its own: it is a training flight of the shared models); for simulated aiding each
noise seed's average over the recordings, then mean ± std over the seeds. Prints markdown (the
table is transposed against the issue's sketch, inputs as columns, so it fits a page).
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Dict, List

from imu_learn.fuse.run import mean_std, runs_by_cell

NOT_IN_AVERAGE = ("MH_01_easy",)


def average(runs: List[dict], kind: str) -> str:
    """Mean ± std over the seeds of each seed's average over the recordings in ``runs``."""
    per_seed: Dict[object, List[float]] = {}
    for r in runs:
        per_seed.setdefault(r.get("seed"), []).append(math.nan if "failed" in r else r[kind]["pos_rmse_m"])
    return mean_std([sum(v) / len(v) for v in per_seed.values()])


def rows_of(name: str, runs: Dict[str, dict]) -> List[List[str]]:
    cells = runs_by_cell(runs)
    scenarios = list(dict.fromkeys(s for _, s, _ in cells))
    inputs = list(dict.fromkeys(i for _, _, i in cells))
    groups = {"test recordings": lambda rec: rec not in NOT_IN_AVERAGE, "MH_01_easy": lambda rec: rec in NOT_IN_AVERAGE}
    out = []
    for scn in scenarios:
        for label, keep in groups.items():
            recs = [rec for rec, s, _ in cells if s == scn and keep(rec)]
            recs = list(dict.fromkeys(recs))
            if not recs:
                continue
            row = [name, scn, f"{len(recs)}" if label == "test recordings" else label]
            for i in inputs:
                rs = [r for rec in recs for r in cells.get((rec, scn, i), [])]
                row.append(f"{average(rs, 'causal')} / {average(rs, 'smoothed')}" if rs else "–")
            out.append(row)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", type=Path)
    a = ap.parse_args(argv)
    inputs: List[str] = []
    rows: List[List[str]] = []
    for path in a.results:
        blob = json.loads(path.read_text())
        inputs = inputs or list(blob["config"]["inputs"])
        rows += rows_of(blob["config"]["name"], blob["runs"])
    print("| experiment | aiding | recordings | " + " | ".join(f"{i}: causal / smoothed [m]" for i in inputs) + " |")
    print("|---|---|---|" + "---|" * len(inputs))
    for r in rows:
        print("| " + " | ".join(r) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
