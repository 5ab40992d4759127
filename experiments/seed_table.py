"""Test figures of finished runs, read once after the choice on validation, and their mean ± spread.

Runs chosen on validation were trained with ``--data.split.test '[]'`` so that no test figure was
seen while choosing. This script then scores each run's ``best.pt`` on the test split of the
config given (the one the runs were made from), as ``imu_learn.fit``'s final table does (raw IMU
and model, open loop and start-up bias removed, at ``data.eval_horizons``, pooled and per test
recording), writes ``RUN/test_results.json`` atomically, and prints a markdown table: mean and
spread (sample standard deviation, and min–max) over the runs (seeds).

    python experiments/seed_table.py --config configs/tumvi.toml runs/tumvi_s0 runs/tumvi_s1 runs/tumvi_s2

Writes: docs/experiments/euroc_seed_table.md and docs/experiments/tumvi_seed_table.md (and the seed
rows of table2_euroc.md / table2_tumvi.md). Data: finished runs of ``imu-learn fit`` (e.g. made by
experiments/sweep.py) and the config's test recordings under the data root.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any, Dict, List

import torch

from imu_learn.data.splits import make_split
from imu_learn.infer.checkpoint import load_checkpoint, model_from_checkpoint
from imu_learn.infer.windowing import refine_sequence
from imu_learn.train.config import load_config
from imu_learn.train.trainer import evaluate_table
from imu_learn.util.atomic import atomic_write_bytes


def score_run(run: Path, cfg, test) -> Dict[str, Any]:
    """The final table of one run's best.pt on ``test`` (a list of Sequence)."""
    state = load_checkpoint(run / "best.pt")  # read once: the model and the window it was trained on
    model = model_from_checkpoint(state)
    saved = json.loads((run / "split.json").read_text()) if (run / "split.json").exists() else {}
    window = int(state["config"]["data"]["window"])
    refined = [refine_sequence(model, s) for s in test]  # the checkpoint's windowing rule (its training window)
    res = evaluate_table(list(test), refined, cfg)
    res["run"], res["window"], res["train_entries"] = str(run), window, [r["entry"] for r in saved.get("train", [])]
    text = json.dumps(res, indent=2)
    atomic_write_bytes(run / "test_results.json", lambda f: f.write(text.encode()))
    return res


def spread(xs: List[float]) -> str:
    if len(xs) == 1:
        return f"{xs[0]:.4g}"
    return f"{statistics.mean(xs):.4g} ± {statistics.stdev(xs):.2g} ({min(xs):.4g}–{max(xs):.4g})"


def cell_of(res: Dict[str, Any], rec: str, row: str, col: str, n: int, key: str) -> float:
    src = res["rows"] if rec == "pooled" else res["per_recording"][rec]
    return src[row][col][str(n)][key]


def table(results: List[Dict[str, Any]], horizons: List[int]) -> str:
    recs = list(results[0]["per_recording"])
    lines = ["| recording | protocol | n | raw rot [deg] | model rot [deg] | ratio | raw trans [m] | model trans [m] | ratio |",
             "|---|---|---|---|---|---|---|---|---|"]
    for rec in recs + ["pooled"]:
        for col in ("open_loop", "bias_removed"):
            for n in horizons:
                cell = []
                for key in ("rot_deg", "trans_m"):
                    raw = [cell_of(r, rec, "raw", col, n, key) for r in results]
                    mod = [cell_of(r, rec, "model", col, n, key) for r in results]
                    cell += [f"{raw[0]:.4g}", spread(mod), spread([m / a for m, a in zip(mod, raw)])]
                lines.append(f"| {rec} | {col.replace('_', ' ')} | {n} | " + " | ".join(cell) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", required=True, type=Path, help="the config the runs were made from (its test split)")
    ap.add_argument("runs", nargs="+", type=Path)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    cfg = load_config(args.config)
    test = make_split(cfg.data).test
    if not test:
        print(f"{args.config}: no test split", file=sys.stderr)
        return 2
    results = []
    for run in args.runs:
        print(f"scoring {run} on {len(test)} test segments", file=sys.stderr)
        results.append(score_run(run, cfg, test))
    print(table(results, list(cfg.data.eval_horizons)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
