"""``imu-learn fuse``: IMU fused with aiding in a GTSAM factor graph (:mod:`imu_learn.fuse.run`), or
streamed sample by sample with ``--online`` (:mod:`imu_learn.fuse.online`)."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import add_data_root, run_command
from imu_learn.errors import ConfigError

DESCRIPTION = """Fuse IMU inputs (raw, a calibration, a trained model's refinement) with aiding in a GTSAM
factor graph and score the trajectories against ground truth: every recording x input x aiding
scenario of a config, causal (iSAM2) and smoothed (batch LM). With --online, each recording is
streamed sample by sample instead (the causal model's step, preintegration, iSAM2 at keyframes)
and the per-sample latency and real-time factor are measured. Prints the file written."""

EPILOG = """examples:
  imu-learn fuse --config configs/fuse_euroc.toml --data-root <data root>
      every recording x input x aiding scenario of the config, causal and smoothed
      -> reports/fuse_euroc/{results.json,table.md,trajectories/,plots/}
  imu-learn fit --config configs/euroc_paper.toml --data-root <data root> --name euroc_causal_s0 \\
      --model.causal true --model.fir_taps 0
      a causal checkpoint (runs/euroc_causal_s0/best.pt; about 3 min on one CPU core)
  imu-learn fuse --config configs/fuse_euroc.toml --data-root <data root> --online \\
      --checkpoint runs/euroc_causal_s0/best.pt --recordings V1_01_easy --scenarios gnss_1hz
      the recording as a stream (raw and the causal model's refinement), one line per run with the
      causal position RMSE, per-sample latency (median, p99) and real-time factor
      -> reports/fuse_euroc/online.json
"""

ONLINE_ONLY = ("checkpoint", "recordings", "scenarios")


def _names(text: str) -> List[str]:
    return [n.strip() for n in text.split(",") if n.strip()]


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--config", type=Path, required=True, metavar="TOML",
                    help="fusion config: recordings, IMU inputs, aiding scenarios (configs/fuse_*.toml)")
    add_data_root(ap, "the config's recording paths")
    ap.add_argument("--out", type=Path, default=None, metavar="DIR",
                    help="report folder (default <out_dir>/<name> of the config)")
    ap.add_argument("--online", action="store_true",
                    help="stream each recording sample by sample (causal model step, preintegration, iSAM2 at "
                         "keyframes), measure per-sample latency and the real-time factor, write <out>/online.json; "
                         "no smoothing; simulated aiding from the config's first noise seed")
    ap.add_argument("--checkpoint", default=None, metavar="PT",
                    help="with --online: the CAUSAL checkpoint (trained with --model.causal true) for the "
                         "'proposed' input, for every recording (default: the config's checkpoint, which must "
                         "then be causal)")
    ap.add_argument("--recordings", type=_names, default=None, metavar="NAME,...",
                    help="with --online: only these recordings (folder names, e.g. V1_01_easy; default all)")
    ap.add_argument("--scenarios", type=_names, default=None, metavar="NAME,...",
                    help="with --online: only these aiding scenarios (their names in the config, e.g. gnss_1hz; "
                         "default all)")
    ap.add_argument("--inputs", type=_names, default=None, metavar="NAME,...",
                    help="with --online: IMU inputs to stream, of raw and proposed (default raw,proposed); "
                         "without: run only these of the config's inputs (e.g. tlio-style), the results of "
                         "the others in results.json are left as they are")
    ap.add_argument("--threads", type=int, default=None, metavar="N",
                    help="torch threads for the models (default: 1 with --online, where one sample at a time "
                         "gains nothing from more; torch's own otherwise)")


def parser() -> argparse.ArgumentParser:
    """The full ``imu-learn fuse`` parser (common flags included)."""
    from imu_learn.cli.common import parser as common_parser

    return common_parser("fuse")


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    if not args.online:
        given = [f"--{o}" for o in ONLINE_ONLY if getattr(args, o) is not None]
        if given:
            raise ConfigError(f"{', '.join(given)}: only with --online")
    if args.threads is not None and args.threads < 1:
        raise ConfigError(f"--threads: must be >= 1, got {args.threads}")
    from imu_learn.fuse.config import load

    cfg = load(args.config, args.data_root)
    out = args.out or Path(cfg.out_dir) / cfg.name
    if args.threads is not None or args.online:
        import torch

        torch.set_num_threads(args.threads or 1)
    if args.online:
        from imu_learn.fuse.online import ONLINE_INPUTS, run_online

        keep(f"the runs so far are in {out / 'online.json'}")
        run_online(cfg, out, args.checkpoint, args.recordings, args.scenarios, args.inputs or ONLINE_INPUTS,
                   log=lambda m: print(m, flush=True))
        print(f"wrote {out / 'online.json'}")
    else:
        from imu_learn.fuse.run import run_experiment

        keep(f"results so far are in {out / 'results.json'} (rerun to resume)")
        run_experiment(cfg, out, only_inputs=args.inputs)
        print(f"wrote {out / 'table.md'}")
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn fuse ARGV``."""
    return run_command("fuse", argv)
