"""Fit's start-up time: from the resolved config to the end of the first training step.

Two ways to get the data, same config otherwise (``configs/euroc.toml``: full EuRoC MH_01_easy and
V1_01_easy, needs the data root):

* ``raw``: ``data.cache`` unset, fit parses and aligns the raw files (what fit did before it read
  the label cache);
* ``cache``: ``data.cache`` set to a label cache built beforehand for the same recordings (not
  timed), so fit loads the aligned segments from it and parses nothing.

Each measurement runs in its own process (imports are excluded: both modes import the same
modules; what is timed: ``trainer.open_run`` (the split, the run folder) and ``trainer.train`` up to the
end of step 1: sampler, validation windows and scores, model, first step), ``--repeat`` times, and prints the median, min and max; the time spent getting the split
(``make_split``) is reported on its own as well::

    IMU_LEARN_DATA=/path/to/data python bench/bench_fit_startup.py [--repeat 3] [--config configs/euroc.toml]

Without a data root (or with ``--shipped``) it runs on the shipped crops (``configs/default.toml``).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
from pathlib import Path
from imu_learn.train import trainer
from imu_learn.train.config import parse_overrides

class Stop(Exception):
    pass

spent = {"split": 0.0}
real = trainer.make_split
def timed(*a, **k):
    t = time.perf_counter()
    try:
        return real(*a, **k)
    finally:
        spent["split"] += time.perf_counter() - t
trainer.make_split = timed

def first_step(step, loss):
    raise Stop

config, out, more = sys.argv[1], Path(sys.argv[2]), json.loads(sys.argv[3])
t0 = time.perf_counter()
cfg, _ = trainer.resolve_config(Path(config), None, parse_overrides(more))
run_dir, split = trainer.open_run(cfg, None, out)
try:
    trainer.train(cfg, run_dir, None, split, on_step=first_step, progress=False)
except Stop:
    pass
else:
    raise SystemExit("fit ended before its first step")
print(json.dumps({"startup_s": time.perf_counter() - t0, "split_s": spent["split"]}))
"""


def run_once(config: Path, out_dir: Path, overrides: list, env: dict) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(config), str(out_dir), json.dumps(overrides)], env=env, cwd=ROOT,
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"bench_fit_startup: child failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def build_cache_for(config: Path, cache: Path, env: dict) -> float:
    code = (
        "import sys; from pathlib import Path\n"
        "from imu_learn.train.config import build_config, parse_overrides, read_toml\n"
        "from imu_learn.data.splits import make_split\n"
        "cfg = build_config(read_toml(Path(sys.argv[1])), parse_overrides(['--data.cache', sys.argv[2]]))\n"
        "make_split(cfg.data)\n"
    )
    t = time.perf_counter()
    subprocess.run([sys.executable, "-c", code, str(config), str(cache)], env=env, cwd=ROOT, check=True)
    return time.perf_counter() - t


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=None)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--shipped", action="store_true", help="the shipped crops (configs/default.toml)")
    ap.add_argument("--modes", default="raw,cache")
    a = ap.parse_args()
    env = {**os.environ, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}
    if a.config is None:
        shipped = a.shipped or not os.environ.get("IMU_LEARN_DATA")
        a.config = ROOT / ("configs/default.toml" if shipped else "configs/euroc.toml")
    modes = a.modes.split(",")
    print(f"fit start-up (to the end of step 1), {a.config.relative_to(ROOT) if a.config.is_relative_to(ROOT) else a.config}, "
          f"data root {os.environ.get('IMU_LEARN_DATA') or '(none: shipped crops)'}, {a.repeat} runs each")
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        cache = tmp_path / "cache"
        if "cache" in modes:
            built = build_cache_for(a.config, cache, env)
            print(f"  label cache built beforehand in {built:.2f} s (not timed below)")
        for mode in modes:
            res = []
            for i in range(a.repeat):
                more = ["--device", "cpu"] + (["--data.cache", str(cache)] if mode == "cache" else [])
                res.append(run_once(a.config, tmp_path / f"{mode}{i}", more, env))
            st = [r["startup_s"] for r in res]
            sp = [r["split_s"] for r in res]
            print(f"  {mode:5}: start-up median {statistics.median(st):6.2f} s (min {min(st):.2f}, max {max(st):.2f}); "
                  f"of which the split {statistics.median(sp):6.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
