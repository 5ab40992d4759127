"""The calibration summary of docs/experiments/uncertainty.md from evaluation reports (``imu-learn evaluate
... --checkpoint <model with a covariance head>`` writes the full per-recording table into its
report.md; this prints the pooled rows of several reports side by side).

    python experiments/calibration_table.py reports/calibration_{euroc,tumvi,blackbird,broad}/result.json [--n 200]

Writes: the pooled calibration table of docs/experiments/uncertainty.md ("Calibration on held-out
data"). Data: the result.json of ``imu-learn evaluate --checkpoint <covariance model>`` runs
(EuRoC, TUM-VI, Blackbird, BROAD; their configs in configs/).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", type=Path)
    ap.add_argument("--n", type=int, action="append", help="horizons [samples] to show (default: all)")
    a = ap.parse_args(argv)
    print("| report | n | IMU | covariance | mean NEES, 9 dof | in 1σ / 2σ / 3σ (χ²: 0.001 / 0.089 / 0.563) "
          "| mean NEES rot / vel / pos (3 each) |")
    print("|---|---|---|---|---|---|---|")
    for path in a.results:
        r = json.loads(path.read_text())
        for row in r.get("calibration", []):
            if row["sequence"] != "all test" or (a.n and row["n"] not in a.n):
                continue
            s = row["summary"]
            frac = " / ".join(f"{s['all'][f'in_{m}sigma']:.3f}" for m in (1, 2, 3))
            blocks = " / ".join(f"{s[b]['mean_nees']:.3g}" for b in ("rot", "vel", "pos"))
            print(f"| {r['config_name']} | {row['n']} | {row['input']} | {row['covariance']} | "
                  f"{s['all']['mean_nees']:.3g} | {frac} | {blocks} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
