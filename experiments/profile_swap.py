"""Which of a profile's terms moves an unseen flight's open-loop figures: terms of a donor profile
swapped one at a time (or ``+``-joined together) into a base profile, each hybrid applied with
``imu-learn refine --profile P --bias still+gravity`` and scored open loop as
experiments/reference_kinds.py scores (score.peers: AOE, RO_RMSE and RP_RMSE over 1 s windows).

    IMU_LEARN_DATA=<root> python experiments/profile_swap.py --base A/profile.json --donor B/profile.json \
        --terms none,M_g,G,b_g,tau,cut_a,acc_aff [--flights MH_04_difficult,...] [--out reports/profile_swap]

Terms: ``M_g`` (the gyro matrix), ``b_g``, ``G`` (g-sensitivity), ``tau`` (time offset), ``cut_g``,
``cut_a`` (the low-pass cut-offs), ``acc_aff`` (M_a and b_a), ``acc`` (M_a, b_a and cut_a), and
``M_g_I`` / ``G_0`` (the gyro matrix at the identity, no g-sensitivity: the donor not used);
parts of the gyro matrix: ``M_g_diag`` (its scales), ``M_g_skew`` (its antisymmetric part: a rotation),
``M_g_sym`` (its symmetric off-diagonal part: the axes' non-orthogonality), ``M_g_c0``, ``M_g_c1``,
``M_g_c2`` (its columns: what a rate about the IMU's x, y, z puts on each axis); columns of the
g-sensitivity: ``G_c0``, ``G_c1``, ``G_c2`` (the rate per m/s^2 of specific force along x, y, z);
``none``: the base as it is.

With ``--split A B`` (two earlier outputs' folder prefixes, e.g. OUT1/none and OUT2/none) nothing is
refined: for each flight the refined gyro of ``B_<flight>`` minus ``A_<flight>``'s is split into its mean
over the flight (the constant level the two leave; along and across the gravity direction refine's
gravity consistency found in A) and the rest, each added alone to A's refined gyro and scored; A's
mean rate over the flight (its net turn per second) printed with them:

    IMU_LEARN_DATA=<root> python experiments/profile_swap.py --split OUT1/none OUT2/none --out OUT3

Data: under the data root, euroc/<flight>. Writes: OUT/<terms>.json (each hybrid profile), OUT/<terms>_<flight>/
(refine's output), OUT/results.json; prints one line per hybrid (``--split``: OUT/split_<part>_<flight>/,
OUT/split.json).
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

import numpy as np
from reference_kinds import TEST, score

from imu_learn.data.formats import read_imu_source


def _part(m: np.ndarray, term: str) -> np.ndarray:
    """The part of a 3x3 matrix a term names (the rest zero): the parts of each add up to ``m``."""
    off = m - np.diag(np.diag(m))
    if term == "M_g_diag":
        return np.diag(np.diag(m))
    if term == "M_g_skew":
        return (off - off.T) / 2
    if term == "M_g_sym":
        return (off + off.T) / 2
    out = np.zeros((3, 3))
    j = int(term[-1])
    out[:, j] = m[:, j]
    return out


def _check_parts(m: np.ndarray) -> None:
    """The parts a swap names add up to the matrix (each family), so swapping all of them swaps it."""
    for family in (("M_g_diag", "M_g_skew", "M_g_sym"), ("M_g_c0", "M_g_c1", "M_g_c2")):
        if not np.allclose(sum(_part(m, t) for t in family), m, rtol=0.0, atol=1e-15):
            raise AssertionError(f"the parts {family} do not add up to the matrix")


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
    elif term in ("M_g_diag", "M_g_skew", "M_g_sym", "M_g_c0", "M_g_c1", "M_g_c2", "G_c0", "G_c1", "G_c2"):
        key, field = ("M_g", ("gyroscope", "matrix")) if term.startswith("M_g") else \
            ("G", ("g_sensitivity_rad_s_per_mps2",))
        m = np.asarray(f[key], dtype=np.float64)
        _check_parts(m)
        m = (m - _part(m, term) + _part(np.asarray(g[key], dtype=np.float64), term)).tolist()
        f[key] = m
        if len(field) == 2:
            p[field[0]][field[1]] = m
        else:
            p[field[0]] = m
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


def level_parts(d: np.ndarray, up: np.ndarray) -> Dict[str, np.ndarray]:
    """A gyro difference (N x 3) split into its constant level (all, along ``up``, across it) and the rest."""
    m = d.mean(axis=0)
    u = up / np.linalg.norm(up)
    along = u * float(u @ m)
    return {"mean": np.broadcast_to(m, d.shape), "mean_along_g": np.broadcast_to(along, d.shape),
            "mean_across_g": np.broadcast_to(m - along, d.shape), "varying": d - m}


def split(a_prefix: Path, b_prefix: Path, flights: str, root: Path, out: Path) -> int:
    out.mkdir(parents=True, exist_ok=True)
    results: Dict[str, Dict[str, Any]] = {}
    for flight in flights.split(","):
        a_dir, b_dir = Path(f"{a_prefix}_{flight}"), Path(f"{b_prefix}_{flight}")
        a, b = read_imu_source(a_dir), read_imu_source(b_dir)
        if not np.array_equal(a.t_ns, b.t_ns):
            raise SystemExit(f"{a_dir} and {b_dir}: different stamps")
        up = np.asarray(json.loads((a_dir / "summary.json").read_text())["bias"]["gravity"]["gravity_direction_body"])
        header = (a_dir / "mav0" / "imu0" / "data.csv").read_text().split("\n", 1)[0].lstrip("#")
        d = b.gyro - a.gyro
        span_s = (a.t_ns[-1] - a.t_ns[0]) / 1e9  # A's mean rate over the flight: its net turn per second
        row: Dict[str, Any] = {"mean_difference_rad_s": d.mean(axis=0).tolist(),
                               "mean_rate_rad_s": a.gyro.mean(axis=0).tolist(), "span_s": span_s}
        for part, add in [("A", np.zeros_like(d)), ("B", d)] + list(level_parts(d, up).items()):
            dst = out / f"split_{part}_{flight}"
            (dst / "mav0" / "imu0").mkdir(parents=True, exist_ok=True)
            np.savetxt(dst / "mav0" / "imu0" / "data.csv", np.column_stack([a.t_ns, a.gyro + add, a.acc]),
                       delimiter=",", fmt=["%d"] + ["%.12g"] * 6, header=header, comments="#")
            row[part] = score(root / "euroc" / flight, dst)
        results[flight] = row
        print(f"{flight:16s} mean rate {np.round(1e3 * a.gyro.mean(axis=0), 1)} mrad/s over {span_s:.0f} s, "
              f"difference's mean {np.round(1e3 * d.mean(axis=0), 3)} mrad/s")
        print(f"{flight:16s} " + " | ".join(f"{k} {v['aoe_deg']:.3f}° / {v['ro_rmse_deg']:.4f}°"
                                              for k, v in row.items() if isinstance(v, dict)), flush=True)
    (out / "split.json").write_text(json.dumps(results, indent=1, default=float))
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", type=Path)
    ap.add_argument("--donor", type=Path)
    ap.add_argument("--split", type=Path, nargs=2, metavar=("A", "B"))
    ap.add_argument("--terms", default="none,M_g,b_g,G,tau,cut_a,acc_aff")
    ap.add_argument("--flights", default=",".join(TEST))
    ap.add_argument("--out", type=Path, default=Path("reports/profile_swap"))
    args = ap.parse_args()
    root = Path(os.environ.get("IMU_LEARN_DATA", "datasets"))
    if args.split:
        return split(args.split[0], args.split[1], args.flights, root, args.out)
    if args.base is None or args.donor is None:
        ap.error("--base and --donor (or --split A B)")
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
