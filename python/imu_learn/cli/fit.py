"""``imu-learn fit``: train the refiner (the training itself is :mod:`imu_learn.train.trainer`)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import add_data_root, run_command
from imu_learn.errors import ConfigError
from imu_learn.train.config import parse_overrides, to_toml
from imu_learn.util.extras import require_extra

OVERRIDES = True
DESCRIPTION = """Train the IMU refiner. Config: the built-in defaults (= configs/default.toml, the shipped
crops), then --config FILE, then --key.sub VALUE overrides of any config field. The run folder gets
config.toml, split.json, best.pt, last.pt, metrics.csv and results.json; the held-out table is
printed to stdout at the end."""
EPILOG = """examples:
  imu-learn fit                                            the shipped EuRoC crops
  imu-learn fit --config configs/euroc.toml --data-root ~/data --name euroc1
  imu-learn fit --optim.lr 3e-4 --optim.epochs 50 --data.window 100 --model.hidden 32
  imu-learn fit --resume runs/euroc1 --optim.epochs 80     continue (only optim.epochs, device, threads)
  torchrun --nproc_per_node 4 -m imu_learn.fit --config configs/euroc.toml    several GPUs"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, metavar="TOML",
                   help="run config (default: built-in defaults = configs/default.toml)")
    p.add_argument("--resume", type=Path, metavar="RUN_DIR", help="continue the run in RUN_DIR from its last.pt")
    p.add_argument("--out", type=Path, metavar="DIR", help="run folder (default <runs_dir>/<name or timestamp>)")
    add_data_root(p, "the config's recording paths")
    p.add_argument("--print-config", action="store_true", help="print the resolved config as TOML and exit")


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None],
        on_step: Optional[Callable[[int, float], None]] = None) -> int:
    require_extra("train", "imu-learn fit")
    overrides = parse_overrides(rest)
    if "data.data_root" in overrides:
        raise ConfigError("--data.data_root: set the data root with --data-root DIR (or IMU_LEARN_DATA)")
    if args.data_root:
        overrides["data.data_root"] = args.data_root
    from imu_learn.train import trainer

    cfg, state = trainer.resolve_config(args.config, args.resume, overrides)
    if args.print_config:
        sys.stdout.write(to_toml(cfg))
        return 0
    run_dir, split = trainer.open_run(cfg, state, args.resume if state is not None else args.out)

    def kept() -> str:
        if not (run_dir / "last.pt").exists():
            return ""
        return f"saved {run_dir / 'last.pt'}, continue with: imu-learn fit --resume {run_dir}"

    keep(kept)
    results = trainer.train(cfg, run_dir, state, split, on_step=on_step, progress=not args.quiet)
    if results and results.get("text"):
        print(results["text"])
    return 0


def main(argv: Optional[Sequence[str]] = None, on_step: Optional[Callable[[int, float], None]] = None) -> int:
    """``imu-learn fit ARGV`` (``on_step(step, loss)`` after every optimiser step: a hook for tests)."""
    return run_command("fit", argv, on_step=on_step)
