"""Ctrl-C at a grid of moments after ``imu-learn navigate`` starts its batch pass: each process's exit
status and last stderr line (docs/robustness.md: "a Ctrl-C stops a command wherever it lands").

    python experiments/navigate_ctrl_c_grid.py [--from 0.26] [--to 0.42] [--step 0.01] [--repeat 3]

The run: the shipped MH_04_difficult crop (60 s of IMU) with its ground truth as 20 Hz body poses
(``--aiding-kind pose``) and ``--nhc``, so that the batch pass calls Python factors from GTSAM; a real
SIGINT is sent ``delay`` seconds after "smoothing" appears on stderr. Each exit is 130 (nothing of the
run written) or 0 (the run had finished); the counts of every other status are printed with the
delays that gave them. The window where the plot imports matplotlib depends on the machine: scan
coarsely first (``--from 0 --to 1.5 --step 0.05``).

Writes: one line per process and the counts per exit status on stdout (docs/robustness.md); its runs'
outputs in a temporary folder, removed at the end.
Data: the shipped crop ``datasets/euroc/MH_04_difficult`` (no data root needed).
"""
from __future__ import annotations

import argparse
import collections
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
CROP = REPO / "datasets" / "euroc" / "MH_04_difficult"


def recording(root: Path) -> tuple:
    """The crop's IMU and its ground truth as 20 Hz body poses (TUM, q_xyzw)."""
    shutil.copytree(CROP / "mav0" / "imu0", root / "MH_04_difficult" / "mav0" / "imu0")
    gt = np.loadtxt(CROP / "mav0" / "state_groundtruth_estimate0" / "data.csv", delimiter=",", comments="#")[::10]
    tum = root / "poses.tum"
    tum.write_text("".join(f"{r[0] * 1e-9:.9f} {r[1]} {r[2]} {r[3]} {r[5]} {r[6]} {r[7]} {r[4]}\n" for r in gt))
    return root / "MH_04_difficult", tum


def one(rec: Path, tum: Path, out: Path, delay: float) -> tuple:
    """(exit status, last stderr line) of one navigate process interrupted ``delay`` s into its batch pass."""
    env = {**os.environ, "RAYON_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "imu_learn.cli", "navigate", "--input", str(rec), "--aiding",
                             str(tum), "--aiding-kind", "pose", "--nhc", "--out", str(out)],
                            cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    err = b""
    while b"smoothing" not in err:
        c = proc.stderr.read(1)
        if not c:
            break
        err += c
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    _, rest = proc.communicate(timeout=300)
    lines = [ln for ln in (err + rest).decode(errors="replace").replace("\r", "\n").splitlines() if ln.strip()]
    return proc.returncode, lines[-1] if lines else ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--from", dest="lo", type=float, default=0.26)
    ap.add_argument("--to", dest="hi", type=float, default=0.42)
    ap.add_argument("--step", type=float, default=0.01)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    delays = np.round(np.arange(a.lo, a.hi + a.step / 2, a.step), 4)
    seen = collections.defaultdict(list)
    with tempfile.TemporaryDirectory() as tmp:
        rec, tum = recording(Path(tmp))
        for r in range(a.repeat):
            for d in delays:
                out = Path(tmp) / "out"
                shutil.rmtree(out, ignore_errors=True)
                code, last = one(rec, tum, out, float(d))
                seen[code].append(float(d))
                print(f"round {r + 1} delay {d:.3f} s: exit {code}: {last[:160]}", flush=True)
    total = sum(len(v) for v in seen.values())
    for code, ds in sorted(seen.items()):
        print(f"exit {code}: {len(ds)} of {total}" + ("" if code in (0, 130) else f" (delays {sorted(set(ds))})"))


if __name__ == "__main__":
    main()
