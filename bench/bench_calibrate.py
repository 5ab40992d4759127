"""``imu-learn calibrate``'s time: EuRoC's training flights, quiet and beside a busy loop, and a long
synthetic recording at a low rate.

    IMU_LEARN_DATA=/path/to/data python bench/bench_calibrate.py [--repeat 3] [--config configs/eval_euroc_paper.toml]
                                                                 [--seconds 400] [--rate 30] [--quick]

Each run is the command itself in a fresh process (``python -m imu_learn.cli calibrate ... --no-plot``),
so "wall s" includes the interpreter, the imports (their bytecode cached, as in a user's installation:
``PYTHONDONTWRITEBYTECODE`` is dropped for the runs) and reading the recordings;
"own s" is what the command reports for its own work ("calibrate took ... s": the floor, its
uncertainty refits, gravity, the noise, the files). Cases:

* ``euroc``: ``--config`` (default configs/eval_euroc_paper.toml: train MH_01, MH_03, MH_05, V2_01,
  V2_03, their last 15 % selecting), the default: each sensor's terms chosen on the flights held out
  in turn (five folds, their fits and scores on the cores); skipped with a message when the data
  root is absent;
* ``euroc + busy loop``: the same with one ``python -c "while True: pass"`` process started beside
  each run (one core of CPU-bound load; the busy process is ended after the run);
* ``euroc --no-select`` (alone and beside the busy loop): every term fitted, no selection;
* ``synthetic``: one ``--seconds`` s recording at ``--rate`` Hz with a 6-DoF reference (EuRoC ASL
  layout, written once into a temporary folder), with a known scale/misalignment, bias and noise
  on both sensors, calibrated by ``--input``; the fitted gyro bias and accelerometer scale are
  printed beside the true ones as a check that the run fitted something.

Prints the minimum and the median over ``--repeat`` runs per case of the wall time, of the
command's own time and of the process's CPU time (user + system, from ``getrusage`` of the child:
the steadier figure on a shared machine), the load average before the runs (other work on the
machine shows there) and the thread settings in the environment; then the project's targets
beside them (wall ≤ 5 s for EuRoC's five flights and for the 400 s recording, ≤ 2× that beside a
busy loop). Figures only: no pass/fail.

Writes: nothing (stdout only; the runs write into a temporary folder).
Data: EuRoC's five training flights under the data root (``DATA/euroc/...``), and the synthetic
recording it writes itself.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional, Tuple

REPO = Path(__file__).resolve().parents[1]
DEFAULT_CONFIG = REPO / "configs" / "eval_euroc_paper.toml"
EUROC_TRAIN = ("MH_01_easy", "MH_03_medium", "MH_05_difficult", "V2_01_easy", "V2_03_difficult")

# the synthetic device: raw = S (true) + b + noise
GYRO_S = [[1.004, 0.002, -0.003], [-0.001, 0.997, 0.002], [0.003, -0.002, 1.002]]
GYRO_B = [0.01, -0.02, 0.015]
ACC_S = [[1.01, 0.004, 0.0], [-0.003, 0.99, 0.005], [0.002, 0.0, 1.005]]
ACC_B = [0.1, -0.05, 0.08]
GYRO_SIGMA, ACC_SIGMA = 2e-3, 2e-2  # per sample


def data_root(arg: Optional[str]) -> Optional[Path]:
    root = arg or os.environ.get("IMU_LEARN_DATA")
    if not root:
        return None
    root = Path(root)
    have = all((root / "euroc" / r / "mav0" / "imu0" / "data.csv").is_file() for r in EUROC_TRAIN)
    return root if have else None


def trajectory(t):
    """Bounded motion that excites every axis: (q_wxyz, p, v, body rate, specific force), exact.

    Rotation R = Rz(psi) Ry(theta) Rx(phi) from sinusoidal angles; body rate from the Euler-rate
    relation; position a Lissajous curve; specific force R^T (a_world + g z)."""
    import numpy as np

    from imu_learn.data.synthetic import G, axis_angle, qconj, qmul, rotate

    phi, dphi = 0.5 * np.sin(0.9 * t), 0.45 * np.cos(0.9 * t)
    th, dth = 0.4 * np.sin(0.7 * t + 1.0), 0.28 * np.cos(0.7 * t + 1.0)
    psi, dpsi = 0.4 * t + 0.8 * np.sin(0.5 * t), 0.4 + 0.4 * np.cos(0.5 * t)
    q = qmul(qmul(axis_angle([0.0, 0.0, 1.0], psi), axis_angle([0.0, 1.0, 0.0], th)), axis_angle([1.0, 0.0, 0.0], phi))
    sp, cp, st, ct = np.sin(phi), np.cos(phi), np.sin(th), np.cos(th)
    gyro = np.stack([dphi - st * dpsi, cp * dth + sp * ct * dpsi, -sp * dth + cp * ct * dpsi], -1)
    amp, w = np.array([3.0, 2.0, 0.5]), np.array([0.6, 0.9, 1.3])
    tt = t[:, None]
    p = amp * np.sin(w * tt)
    v = amp * w * np.cos(w * tt)
    a_world = -amp * w**2 * np.sin(w * tt) + np.array([0.0, 0.0, G])
    acc = rotate(qconj(q), a_world)
    return q, p, v, gyro, acc


def write_synthetic(rec: Path, seconds: float, rate: float, seed: int = 0) -> int:
    import numpy as np

    from imu_learn import _imu_core as core

    n = int(round(seconds * rate)) + 1
    t_ns = 10**18 + np.round(np.arange(n) * (1e9 / rate)).astype(np.int64)
    q, p, v, g, a = trajectory((t_ns - t_ns[0]) * 1e-9)
    rng = np.random.default_rng(seed)
    gyro = g @ np.asarray(GYRO_S).T + GYRO_B + rng.normal(0.0, GYRO_SIGMA, g.shape)
    acc = a @ np.asarray(ACC_S).T + ACC_B + rng.normal(0.0, ACC_SIGMA, a.shape)
    (rec / "mav0" / "imu0").mkdir(parents=True, exist_ok=True)
    (rec / "mav0" / "state_groundtruth_estimate0").mkdir(parents=True, exist_ok=True)
    core.write_asl_imu(str(rec / "mav0" / "imu0" / "data.csv"), t_ns, gyro, acc)
    header = ("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
              "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], "
              "b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]")
    rows = np.column_stack([p, q, v, np.zeros((n, 6))])
    with open(rec / "mav0" / "state_groundtruth_estimate0" / "data.csv", "w") as f:
        f.write(header + "\n")
        for ti, r in zip(t_ns, rows):
            f.write(f"{ti}," + ",".join(f"{x:.10g}" for x in r) + "\n")
    return n


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_once(argv: List[str], env: Dict[str, str], busy: bool) -> Tuple[float, Optional[float], float]:
    """(wall s, the command's own s, its CPU s) of one calibrate process, with a busy loop beside it
    (the busy loop is reaped after the CPU time is read: its own time is not counted)."""
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if busy else None
    try:
        c0, t0 = children_cpu(), time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "imu_learn.cli", "calibrate", *argv], env=env, cwd=REPO,
                           capture_output=True, text=True)
        wall, cpu = time.perf_counter() - t0, children_cpu() - c0
    finally:
        if hog is not None:
            hog.terminate()
            hog.wait()
    if p.returncode != 0:
        raise RuntimeError(f"calibrate failed ({p.returncode}): {p.stderr.strip()[-800:]}")
    m = re.search(r"calibrate took ([0-9.]+) s", p.stdout + p.stderr)
    return wall, (float(m.group(1)) if m else None), cpu


def case(name: str, argv: List[str], env: Dict[str, str], repeat: int, busy: bool) -> float:
    """Runs one case ``repeat`` times, prints its line; returns the median wall time."""
    load = os.getloadavg()
    out = [run_once(argv, env, busy) for _ in range(repeat)]
    walls, cpus = [w for w, _, _ in out], [c for _, _, c in out]
    owns = [o for _, o, _ in out if o is not None]
    own = f"{min(owns):7.2f} {statistics.median(owns):7.2f}" if owns else "      -       -"
    print(f"{name:34s} {min(walls):7.2f} {statistics.median(walls):7.2f}   {own}   {min(cpus):7.2f} "
          f"{statistics.median(cpus):7.2f}   {len(out)} runs; load before {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}",
          flush=True)
    return statistics.median(walls)


TARGET_S, BUSY_RATIO = 5.0, 2.0  # the targets: at most 5 s on 2 cores, at most 2x that beside another job


def targets(label: str, alone: float, busy: float) -> None:
    ok = "met" if alone <= TARGET_S else "NOT met"
    ok_busy = "met" if busy <= BUSY_RATIO * alone else "NOT met"
    print(f"  target {label}: median wall {alone:.2f} s (target <= {TARGET_S:g} s: {ok}); beside a busy loop "
          f"{busy:.2f} s = {busy / alone:.2f}x (target <= {BUSY_RATIO:g}x: {ok_busy})")


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    ap.add_argument("--data-root", default=None, help="default: $IMU_LEARN_DATA")
    ap.add_argument("--seconds", type=float, default=400.0)
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--quick", action="store_true", help="one run per case")
    args = ap.parse_args(argv)
    repeat = 1 if args.quick else args.repeat

    print(f"# imu-learn calibrate: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}")
    threads = {k: os.environ[k] for k in ("RAYON_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                         "MKL_NUM_THREADS", "OMP_WAIT_POLICY") if k in os.environ}
    print(f"# thread settings in the environment: {threads or 'none (every pool at its default)'}")
    print(f"{'case':34s} {'wall s':>7s} {'':7s}   {'own s':>7s} {'':7s}   {'CPU s':>7s}")
    print(f"{'':34s} {'min':>7s} {'median':>7s}   {'min':>7s} {'median':>7s}   {'min':>7s} {'median':>7s}")
    env = dict(os.environ)
    # as a user's runs: the modules' bytecode cached (written by a first run), not compiled in every run
    # (PYTHONDONTWRITEBYTECODE, set on some machines, adds ~0.3 s of compiling to each run's start-up)
    if env.pop("PYTHONDONTWRITEBYTECODE", None) is not None:
        print("# PYTHONDONTWRITEBYTECODE dropped for the runs (bytecode cached as in a user's installation)")
    subprocess.run([sys.executable, "-m", "imu_learn.cli", "calibrate", "--help"], env=env, cwd=REPO,
                   capture_output=True, check=False)
    root = data_root(args.data_root)
    if root is None:
        print("euroc: skipped (no data root with EuRoC's training flights: set IMU_LEARN_DATA or --data-root)")
    else:
        env["IMU_LEARN_DATA"] = str(root)
        with tempfile.TemporaryDirectory() as tmp:
            common = ["--config", str(args.config), "--out", str(Path(tmp) / "out"), "--no-plot", "--quiet"]
            alone = case("euroc (5 flights), terms selected", common, env, repeat, busy=False)  # the default
            busy = case("euroc, terms selected + busy loop", common, env, repeat, busy=True)
            targets("euroc (the default: terms selected)", alone, busy)
            alone = case("euroc --no-select", [*common, "--no-select"], env, repeat, busy=False)
            busy = case("euroc --no-select + busy loop", [*common, "--no-select"], env, repeat, busy=True)
            targets("euroc --no-select", alone, busy)
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "synthetic"
        n = write_synthetic(rec, args.seconds, args.rate)
        out = Path(tmp) / "out"
        common = ["--input", str(rec), "--device", "synthetic", "--out", str(out), "--no-plot", "--quiet"]
        label = f"synthetic {args.seconds:g} s at {args.rate:g} Hz"
        alone = case(f"{label} ({n} samples)", common, env, repeat, busy=False)
        busy = case(f"{label} + busy loop", common, env, repeat, busy=True)
        targets("synthetic", alone, busy)
        prof = json.loads((out / "profile.json").read_text())
        g, a = prof["gyroscope"], prof["accelerometer"]
        print(f"  synthetic check: gyro bias {fmt(g['bias'])} (true {fmt(GYRO_B)}), accel scale diag "
              f"{fmt([a['matrix'][i][i] for i in range(3)])} (true inverse {fmt([1.0 / ACC_S[i][i] for i in range(3)])}), "
              f"time offset {prof['time_offset_s'] * args.rate:+.3f} samples")
    return 0


def fmt(v) -> str:
    return "[" + ", ".join(f"{x:+.4f}" if not (isinstance(x, float) and math.isnan(x)) else "nan" for x in v) + "]"


if __name__ == "__main__":
    sys.exit(main())
