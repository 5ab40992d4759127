"""The long-term navigation table across fusion experiments (README "Inertial-aided navigation"):

    python experiments/fusion_longterm_table.py reports/fuse_euroc/results.json reports/fuse_tumvi/results.json ...

One row per experiment x aiding setting, one column pair per IMU input: position RMSE [m] over the
whole trajectory, causal / smoothed, averaged over the experiment's test recordings (EuRoC's MH_01
is reported on its own: it is a training flight of the shared models); for simulated aiding each
noise seed's average over the recordings, then mean ± std over the seeds that every recording of
the row has ("seeds"; an unfinished experiment counts only those). The paired table counts wins
over every run pair there is. Prints markdown (the
table is transposed against the issue's sketch, inputs as columns, so it fits a page).

Writes: the long-term navigation tables of docs/experiments/fusion.md and
docs/experiments/uncertainty.md. Data: the results.json of ``imu-learn fuse --config
configs/fuse_<data>.toml`` runs (reports/fuse_*).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Dict, List

from imu_learn.fuse.experiments.batch import NOT_IN_AVERAGE, average, complete_seeds, mean_std, runs_by_cell


def rows_of(name: str, runs: Dict[str, dict], inputs: List[str]) -> List[List[str]]:
    cells = runs_by_cell(runs)
    scenarios = list(dict.fromkeys(s for _, s, _ in cells))
    groups = {"test recordings": lambda rec: rec not in NOT_IN_AVERAGE, "MH_01_easy": lambda rec: rec in NOT_IN_AVERAGE}
    out = []
    for scn in scenarios:
        for label, keep in groups.items():
            recs = [rec for rec, s, _ in cells if s == scn and keep(rec)]
            recs = list(dict.fromkeys(recs))
            if not recs:
                continue
            row = [name, scn, f"{len(recs)}" if label == "test recordings" else label]
            seeds = None
            for i in inputs:
                rs = [r for rec in recs for r in cells.get((rec, scn, i), [])]
                if not rs:
                    continue
                seeds = complete_seeds(rs, len(recs)) if seeds is None else [x for x in seeds if x in complete_seeds(rs, len(recs))]
            row.append("real" if seeds == [None] else str(len(seeds)))
            for i in inputs:
                rs = [r for rec in recs for r in cells.get((rec, scn, i), [])]
                row.append(f"{average(rs, 'causal', seeds)} / {average(rs, 'smoothed', seeds)}" if rs and seeds else "–")
            out.append(row)
    return out


def paired_rows(name: str, runs: Dict[str, dict], base: str = "raw") -> List[List[str]]:
    """Each input against ``base`` on the same aiding draw: per noise seed the difference of the
    average over the test recordings, mean ± std over the seeds (negative: better than ``base``),
    and on how many recording x seed pairs the input's causal RMSE is the lower."""
    cells = runs_by_cell(runs)
    out = []
    for scn in dict.fromkeys(s for _, s, _ in cells):
        recs = list(dict.fromkeys(rec for rec, s, _ in cells if s == scn and rec not in NOT_IN_AVERAGE))
        for i in dict.fromkeys(i for _, s, i in cells if s == scn and i != base):
            diffs: Dict[str, Dict[object, List[float]]] = {"causal": {}, "smoothed": {}}
            wins = pairs = 0
            for rec in recs:
                mine = {r.get("seed"): r for r in cells.get((rec, scn, i), []) if "failed" not in r}
                for b in cells.get((rec, scn, base), []):
                    r = mine.get(b.get("seed"))
                    if r is None or "failed" in b:
                        continue
                    for kind in diffs:
                        diffs[kind].setdefault(b.get("seed"), []).append(r[kind]["pos_rmse_m"] - b[kind]["pos_rmse_m"])
                    pairs += 1
                    wins += r["causal"]["pos_rmse_m"] < b["causal"]["pos_rmse_m"]
            full = [sd for sd, v in diffs["causal"].items() if len(v) == len(recs)]
            if pairs and full:
                d = [mean_std([sum(diffs[k][sd]) / len(recs) for sd in full]) for k in ("causal", "smoothed")]
                out.append([name, scn, f"{i} − {base}", d[0], d[1], f"{wins} of {pairs}"])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", type=Path)
    ap.add_argument("--inputs", help="comma list of the input columns (default: every input of the configs)")
    a = ap.parse_args(argv)
    blobs = [json.loads(path.read_text()) for path in a.results]
    inputs = list(dict.fromkeys(i for b in blobs for i in b["config"]["inputs"]))  # "–" where one lacks it
    if a.inputs:
        inputs = [i.strip() for i in a.inputs.split(",") if i.strip()]
    rows: List[List[str]] = []
    paired: List[List[str]] = []
    for blob in blobs:
        rows += rows_of(blob["config"]["name"], blob["runs"], inputs)
        paired += [r for r in paired_rows(blob["config"]["name"], blob["runs"])
                   if r[2].split(" − ")[0] in inputs]
    print("| experiment | aiding | recordings | seeds | " + " | ".join(f"{i}: causal / smoothed [m]" for i in inputs) + " |")
    print("|---|---|---|---|" + "---|" * len(inputs))
    for r in rows:
        print("| " + " | ".join(r) + " |")
    print("\nPaired with raw IMU on the same aiding draw (test recordings; difference of the recordings' average "
          "position RMSE [m] per seed, mean ± std over the seeds; negative = better than raw):\n")
    print("| experiment | aiding | input | causal difference [m] | smoothed difference [m] | causal RMSE lower than raw |")
    print("|---|---|---|---|---|---|")
    for r in paired:
        print("| " + " | ".join(r) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
