"""Train several variants x seeds of ``python -m imu_learn.fit`` side by side, then print each run's
validation choice: the variant table behind the README's "what we tried".

    python experiments/sweep.py --config configs/euroc_paper.toml --seeds 0 1 2 --jobs 12 \\
        paper= \\
        fir="--model.fir_taps 5 --optim.lr 1e-3"

Each ``NAME=OVERRIDES`` becomes runs ``<prefix>NAME_s<seed>`` (``--name``), trained with
``--config CONFIG --seed S --data.split.test []`` plus the overrides: the test split is not loaded
at all, so no test figure is seen while choosing (score the chosen runs afterwards with
``experiments/seed_table.py``). Up to ``--jobs`` runs at once; each run's output goes to
``<runs_dir>/<run>.log``. Prints, per run, the best epoch and its validation score, then per
variant the mean and spread of the score over seeds. Exit status 1 if any run failed.

Writes: the variant tables of docs/experiments/learning.md ("The variants, three seeds each") and
the runs behind docs/experiments/tumvi_seed_table.md. Data: the config's train and validation
recordings under the data root.
"""
from __future__ import annotations

import argparse
import csv
import shlex
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List, Tuple


def parse_variants(items: List[str]) -> List[Tuple[str, List[str]]]:
    out = []
    for item in items:
        name, sep, rest = item.partition("=")
        if not sep or not name:
            raise SystemExit(f"sweep: expected NAME=OVERRIDES, got {item!r}")
        out.append((name, shlex.split(rest)))
    return out


def best_of(run: Path) -> Dict[str, object]:
    """The best epoch and its validation score, from the run's metrics.csv (a run without a test
    split writes no results.json)."""
    path = run / "metrics.csv"
    if not path.exists():
        return {}
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return {}
    best = rows[-1].get("best_epoch")
    key = "val_pose_score" if "val_pose_score" in rows[-1] else "val_total"
    for r in rows:
        if r["epoch"] == best:
            return {"best_epoch": int(best), "score": float(r[key]), "epochs": len(rows), "wall_s": float(rows[-1]["elapsed_s"])}
    return {}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", required=True)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--jobs", type=int, default=2, help="runs at once")
    ap.add_argument("--runs-dir", default="runs")
    ap.add_argument("--prefix", default="", help="prepended to every run name")
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("variants", nargs="+", help="NAME=OVERRIDES (quoted; may be empty)")
    args = ap.parse_args(argv)
    runs_dir = Path(args.runs_dir)
    runs_dir.mkdir(parents=True, exist_ok=True)
    todo = []
    for name, extra in parse_variants(args.variants):
        for seed in args.seeds:
            run = f"{args.prefix}{name}_s{seed}"
            cmd = [args.python, "-m", "imu_learn.fit", "--config", args.config, "--name", run, "--runs_dir", str(runs_dir),
                   "--seed", str(seed), "--data.split.test", "[]", "--quiet", *extra]
            todo.append((name, seed, run, cmd))
    running: List[Tuple[str, subprocess.Popen, object]] = []
    failed = []
    t0 = time.time()
    queue = list(todo)
    while queue or running:
        while queue and len(running) < args.jobs:
            name, seed, run, cmd = queue.pop(0)
            log = open(runs_dir / f"{run}.log", "w")
            log.write(shlex.join(cmd) + "\n")
            log.flush()
            running.append((run, subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT), log))
        time.sleep(2)
        for item in list(running):
            run, proc, log = item
            if proc.poll() is not None:
                log.close()
                running.remove(item)
                print(f"[{time.time() - t0:6.0f} s] {run}: exit {proc.returncode}", file=sys.stderr, flush=True)
                if proc.returncode != 0:
                    failed.append(run)
    print("| variant | seed | best epoch / epochs | validation score | wall [s] |\n|---|---|---|---|---|")
    by_variant: Dict[str, List[float]] = {}
    for name, seed, run, _ in todo:
        b = best_of(runs_dir / run)
        score = b.get("score")
        if isinstance(score, (int, float)):
            by_variant.setdefault(name, []).append(float(score))
        shown = f"{score:.4f}" if isinstance(score, float) else "failed"
        print(f"| {name} | {seed} | {b.get('best_epoch', '-')} / {b.get('epochs', '-')} | {shown} | {b.get('wall_s', '-')} |")
    print("\n| variant | validation score, mean ± std (min–max) over seeds |\n|---|---|")
    for name, xs in by_variant.items():
        sd = statistics.stdev(xs) if len(xs) > 1 else 0.0
        print(f"| {name} | {statistics.mean(xs):.4f} ± {sd:.4f} ({min(xs):.4f}–{max(xs):.4f}) |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
