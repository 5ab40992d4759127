"""Which of a profile's terms moves an unseen flight's open-loop figures: terms of a donor profile
swapped one at a time (or ``+``-joined together) into a base profile, each hybrid applied with
``imu-learn refine --profile P --bias still+gravity`` and scored open loop as
experiments/reference_kinds.py scores (score.peers: AOE, RO_RMSE and RP_RMSE over 1 s windows).

    IMU_LEARN_DATA=<root> python experiments/profile_swap.py --base A/profile.json --donor B/profile.json \
        --terms none,M_g,G,b_g,tau,cut_a,acc_aff [--flights MH_04_difficult,...] [--out reports/profile_swap]

Terms: ``M_g`` (the gyro matrix), ``b_g``, ``G`` (g-sensitivity), ``tau`` (time offset), ``cut_g``,
``cut_a`` (the low-pass cut-offs), ``acc_aff`` (M_a and b_a), ``acc`` (M_a, b_a and cut_a), and
``M_g_I`` / ``G_0`` (the gyro matrix at the identity, no g-sensitivity: the donor not used);
``none``: the base as it is.

Data: under the data root, euroc/<flight>. Writes: OUT/<terms>.json (each hybrid profile), OUT/<terms>_<flight>/
(refine's output), OUT/results.json; prints one line per hybrid.
"""
from __future__ import annotations

import argparse
import copy
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, Dict

from reference_kinds import TEST, score


def swap(p: Dict[str, Any], d: Dict[str, Any], term: str) -> Dict[str, Any]:
    """``p`` with ``term`` taken from ``d`` (the floor and the profile's own fields alike)."""
    p = copy.deepcopy(p)
    f, g = p["floor"], d["floor"]
    if term == "none":
        pass
    elif term == "M_g":
        f["M_g"], p["gyroscope"]["matrix"] = g["M_g"], d["gyroscope"]["matrix"]
    elif term == "M_g_I":
        f["M_g"] = p["gyroscope"]["matrix"] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    elif term == "b_g":
        f["b_g"], p["gyroscope"]["bias"] = g["b_g"], d["gyroscope"]["bias"]
    elif term == "G":
        f["G"], p["g_sensitivity_rad_s_per_mps2"] = g["G"], d["g_sensitivity_rad_s_per_mps2"]
    elif term == "G_0":
        f["G"] = p["g_sensitivity_rad_s_per_mps2"] = [[0.0] * 3 for _ in range(3)]
    elif term == "tau":
        f["time_offset"], p["time_offset_s"] = g["time_offset"], d["time_offset_s"]
    elif term == "cut_g":
        f["cutoff_gyro"] = g["cutoff_gyro"]
    elif term == "cut_a":
        f["cutoff_acc"] = g["cutoff_acc"]
    elif term in ("acc_aff", "acc"):
        f["M_a"], f["b_a"], p["accelerometer"] = g["M_a"], g["b_a"], d["accelerometer"]
        if term == "acc":
            f["cutoff_acc"] = g["cutoff_acc"]
    else:
        raise SystemExit(f"unknown term {term!r}")
    return p


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", type=Path, required=True)
    ap.add_argument("--donor", type=Path, required=True)
    ap.add_argument("--terms", default="none,M_g,b_g,G,tau,cut_a,acc_aff")
    ap.add_argument("--flights", default=",".join(TEST))
    ap.add_argument("--out", type=Path, default=Path("reports/profile_swap"))
    args = ap.parse_args()
    root = Path(os.environ.get("IMU_LEARN_DATA", "datasets"))
    base, donor = json.loads(args.base.read_text()), json.loads(args.donor.read_text())
    args.out.mkdir(parents=True, exist_ok=True)
    results: Dict[str, Dict[str, Any]] = {}
    for term in args.terms.split(","):
        p = base
        for t in term.split("+"):
            p = swap(p, donor, t)
        path = args.out / f"{term}.json"
        path.write_text(json.dumps(p))
        row: Dict[str, Any] = {}
        for flight in args.flights.split(","):
            dst = args.out / f"{term}_{flight}"
            r = subprocess.run([sys.executable, "-m", "imu_learn.cli", "refine", "--profile", str(path), "--input",
                                str(root / "euroc" / flight), "--out", str(dst), "--bias", "still+gravity", "--force"],
                               capture_output=True, text=True)
            row[flight] = score(root / "euroc" / flight, dst) if r.returncode == 0 else {"refine_exit": r.returncode}
        results[term] = row
        print(f"{term:24s} " + " | ".join(
            f"{fl[:5]} {s['aoe_deg']:.2f}° / {s['ro_rmse_deg']:.4f}° / {100 * s['rp_rmse_m']:.2f} cm"
            for fl, s in row.items() if "aoe_deg" in s), flush=True)
    (args.out / "results.json").write_text(json.dumps(results, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
