"""``imu-learn fit``: train the refiner (the training itself is :mod:`imu_learn.train.trainer`)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import add_data_root, run_command
from imu_learn.errors import ConfigError
from imu_learn.infer.rates import recording_device
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
  imu-learn fit --config configs/fetch_all.toml --loro reports/loro_fetch --jobs 2
                                                           leave-one-recording-out on top of the floor
  torchrun --nproc_per_node 4 -m imu_learn.fit --config configs/euroc.toml    several GPUs"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, metavar="TOML",
                   help="run config (default: built-in defaults = configs/default.toml)")
    p.add_argument("--resume", type=Path, metavar="RUN_DIR", help="continue the run in RUN_DIR from its last.pt")
    p.add_argument("--out", type=Path, metavar="DIR", help="run folder (default <runs_dir>/<name or timestamp>)")
    add_data_root(p, "the config's recording paths")
    p.add_argument("--print-config", action="store_true", help="print the resolved config as TOML and exit")
    p.add_argument("--loro", type=Path, metavar="DIR",
                   help="validate the recipe leave-one-recording-out instead of one run: each recording held out in turn, "
                        "the floor fitted on the others and a refiner trained on top of it per seed, both scored on the "
                        "held-out recording; DIR/loro.md and loro.json say whether a learned model beats the floor on "
                        "every one (imu_learn.train.loro); a rerun continues")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], metavar="S", help="with --loro (default 0 1 2)")
    p.add_argument("--recordings", nargs="+", metavar="NAME",
                   help="with --loro: the recordings (default: the config's training and validation recordings)")
    p.add_argument("--jobs", type=int, default=1, metavar="N", help="with --loro: runs at once (processes)")


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None],
        on_step: Optional[Callable[[int, float], None]] = None) -> int:
    require_extra("train", "imu-learn fit")
    overrides = parse_overrides(rest)
    if "data.data_root" in overrides:
        raise ConfigError("--data.data_root: set the data root with --data-root DIR (or IMU_LEARN_DATA)")
    if args.data_root:
        overrides["data.data_root"] = args.data_root
    if args.resume is not None and args.out is not None and Path(args.out).resolve() != Path(args.resume).resolve():
        raise ConfigError(f"--out {args.out}: a resumed run continues in its own folder ({args.resume}); leave --out "
                          "out, or copy the run folder there and resume that")
    from imu_learn.train import trainer

    cfg, state = trainer.resolve_config(args.config, args.resume, overrides)
    if args.print_config:
        sys.stdout.write(to_toml(cfg))
        return 0
    if args.loro is not None:
        return run_loro(cfg, args)
    run_dir, split = trainer.open_run(cfg, state, args.resume if args.resume is not None else args.out)

    def kept() -> str:
        if not (run_dir / "last.pt").exists():
            return f"nothing trained yet; start it again with: imu-learn fit --resume {run_dir}"
        return f"saved {run_dir / 'last.pt'}, continue with: imu-learn fit --resume {run_dir}"

    keep(kept)
    results = trainer.train(cfg, run_dir, state, split, on_step=on_step, progress=not args.quiet)
    if results and results.get("text"):
        print(results["text"])
    return 0


def run_loro(cfg: Any, args: argparse.Namespace) -> int:
    if args.resume is not None:
        raise ConfigError("--loro: not with --resume (a rerun with the same --loro DIR continues)")
    from imu_learn.train import loro

    device = (recording_device(cfg.data.roots[0].format) if cfg.data.roots else None) or cfg.name or "device"
    settings = loro.LoroSettings(tuple(args.seeds), tuple(args.recordings or ()), max(1, args.jobs))
    loro.run_loro(cfg, args.loro, settings, device, progress=lambda s: print(s, file=sys.stderr, flush=True))
    print((args.loro / "loro.md").read_text())
    return 0


def main(argv: Optional[Sequence[str]] = None, on_step: Optional[Callable[[int, float], None]] = None) -> int:
    """``imu-learn fit ARGV`` (``on_step(step, loss)`` after every optimiser step: a hook for tests)."""
    return run_command("fit", argv, on_step=on_step)
