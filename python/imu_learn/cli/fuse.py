"""``imu-learn fuse``: the fusion experiments of a config (:mod:`imu_learn.fuse.experiments`): every
recording x IMU input x aiding scenario in a GTSAM factor graph, or streamed sample by sample with
``--online``; a config with ``kind = "gnss-outages"`` runs the GNSS outage experiment. A user's own
recording is ``imu-learn navigate`` (:mod:`imu_learn.cli.navigate`)."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import add_data_root, run_command
from imu_learn.cli.common import parser as common_parser
from imu_learn.cli.navigate import require_gtsam, set_torch_threads
from imu_learn.errors import ConfigError
from imu_learn.fuse.experiments import batch, gnss, online
from imu_learn.fuse.experiments.config import load
from imu_learn.settings import read_toml

DESCRIPTION = """Fusion experiments: fuse IMU inputs (raw, a calibration, a trained model's refinement) with
aiding in a GTSAM factor graph and score the trajectories against ground truth, for every recording x
input x aiding scenario of a config, causal (iSAM2) and smoothed (batch LM). With --online, each
recording is streamed sample by sample instead (the causal model's step, preintegration, iSAM2 at
keyframes) and the per-sample latency and real-time factor are measured. A config with
kind = "gnss-outages" (configs/fuse_gnss_*.toml) runs the GNSS/IMU experiment with simulated outages.
Prints the file written.

To navigate your own recording with its aiding file, use imu-learn navigate."""

EPILOG = """examples:
  imu-learn fuse --config configs/fuse_euroc.toml --data-root <data root>
      every recording x input x aiding scenario of the config, causal and smoothed
      -> reports/fuse_euroc/{results.json,table.md,trajectories/,plots/}
  imu-learn fuse --config configs/fuse_gnss_drive.toml --data-root <data root> [--set nhc.sigma_lat=0.05] \\
      [--variants raw]
      a kind = "gnss-outages" config: the car drive (or the walk) with the peer's simulated 15 s GNSS
      outages, live and smoothed error against the withheld RTK fixes, one line per variant
      -> reports/fuse_gnss_drive/{results.json,table.md}
  imu-learn fit --config configs/euroc_paper.toml --data-root <data root> --name euroc_causal_s0 \\
      --model.causal true --model.fir_taps 0
      a causal checkpoint (runs/euroc_causal_s0/best.pt; about 3 min on one CPU core)
  imu-learn fuse --config configs/fuse_euroc.toml --data-root <data root> --online \\
      --checkpoint runs/euroc_causal_s0/best.pt --recordings V1_01_easy --scenarios gnss_1hz
      the recording as a stream (raw and the causal model's refinement), one line per run with the
      causal position RMSE, per-sample latency (median, p99) and real-time factor
      -> reports/fuse_euroc/online.json
"""

GNSS_KIND = "gnss-outages"
ONLINE_ONLY = ("checkpoint", "recordings", "scenarios")
NOT_GNSS = ("online", "checkpoint", "recordings", "scenarios", "inputs", "threads", "init")


def _names(text: str) -> List[str]:
    return [n.strip() for n in text.split(",") if n.strip()]


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--config", type=Path, default=None, metavar="TOML",
                    help="the experiment's config (configs/fuse_*.toml): recordings, IMU inputs, aiding scenarios; "
                         "or kind = \"gnss-outages\" (required)")
    # a user's recording is `imu-learn navigate --input ...`: said in one line, not an option of this command
    ap.add_argument("--input", nargs=argparse.REMAINDER, default=None, help=argparse.SUPPRESS)
    add_data_root(ap, "the config's recording paths")
    ap.add_argument("--out", type=Path, default=None, metavar="DIR",
                    help="report folder (default <out_dir>/<name> of the config; gnss-outages: its out_dir)")
    ap.add_argument("--online", action="store_true",
                    help="stream each recording sample by sample (causal model step, preintegration, iSAM2 at "
                         "keyframes), measure per-sample latency and the real-time factor, write <out>/online.json; "
                         "no smoothing; simulated aiding from the config's first noise seed")
    ap.add_argument("--checkpoint", default=None, metavar="PT",
                    help="with --online: the CAUSAL checkpoint (trained with --model.causal true) for the 'proposed' "
                         "input, for every recording (default: the config's checkpoint, which must then be causal)")
    ap.add_argument("--recordings", type=_names, default=None, metavar="NAME,...",
                    help="with --online: only these recordings (folder names, e.g. V1_01_easy; default all)")
    ap.add_argument("--scenarios", type=_names, default=None, metavar="NAME,...",
                    help="with --online: only these aiding scenarios (their names in the config, e.g. gnss_1hz; "
                         "default all)")
    ap.add_argument("--inputs", type=_names, default=None, metavar="NAME,...",
                    help="run only these IMU inputs (default: the config's; the results of the others in "
                         "results.json are left as they are); with --online of raw, proposed and learned (default "
                         "raw,proposed; learned: the config's covariance_checkpoint run once per window)")
    ap.add_argument("--init", choices=("data", "groundtruth"), default=None,
                    help="the runs' first state, instead of the config's init: from the data alone (the default), or "
                         "a prior from ground truth (the controlled setting; tables say which)")
    ap.add_argument("--jobs", type=int, default=1, metavar="N",
                    help="runs fused at a time, in worker processes (one thread each); results.json is the same")
    ap.add_argument("--set", action="append", default=None, metavar="KEY=JSON", dest="set_values",
                    help="a kind = \"gnss-outages\" config: override a value, e.g. --set velocity_sigma_mps=0 "
                         "--set nhc.sigma_lat=0.05 (repeatable)")
    ap.add_argument("--variants", type=_names, default=None, metavar="NAME,...",
                    help="a kind = \"gnss-outages\" config: run only these of its variants (raw, raw+nhc)")
    ap.add_argument("--threads", type=int, default=None, metavar="N",
                    help="torch threads for the models (default: 1 with --online, where one sample at a time "
                         "gains nothing from more; torch's own otherwise)")


def parser() -> argparse.ArgumentParser:
    """The full ``imu-learn fuse`` parser (common flags included)."""
    return common_parser("fuse")


def config_kind(path: Path) -> Optional[str]:
    """The config's ``kind`` (None for the fusion experiment's configs, which have none)."""
    kind = read_toml(Path(path)).get("kind")
    if kind is not None and kind != GNSS_KIND:
        raise ConfigError(f"{path}: kind: {GNSS_KIND!r} or none (the fusion experiment), got {kind!r}")
    return kind


def gnss_outages(args: argparse.Namespace, keep: Callable[[Any], None]) -> int:
    """A ``kind = "gnss-outages"`` config: the GNSS/IMU experiment with simulated outages
    (:mod:`imu_learn.fuse.experiments.gnss`); prints one line per variant and the files written."""
    wrong = [f"--{o}" for o in NOT_GNSS if getattr(args, o) not in (None, False)]
    if wrong:
        raise ConfigError(f"{', '.join(wrong)}: not with a kind = \"{GNSS_KIND}\" config")
    require_gtsam("fuse")
    cfg = gnss.load_config(args.config, args.data_root)
    for item in args.set_values or []:
        gnss.apply_override(cfg, item)
    if args.variants is not None:
        cfg.variants = list(args.variants)
    gnss.check(cfg, f"{args.config} (after --set/--variants)")
    out = Path(args.out or cfg.out_dir)
    keep(f"nothing is written to {out} before the last variant ends")
    res = gnss.experiment(cfg)
    files = gnss.write_results(res, cfg, out)
    for line in gnss.summary_lines(res, cfg):
        print(line)
    print(f"wrote {files[0]} and {files[1]}")
    return 0


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    if args.input is not None:
        raise ConfigError("--input: a recording is navigated with imu-learn navigate --input REC --aiding FILE "
                          "--aiding-kind KIND (imu-learn fuse runs the experiments of a --config)")
    if args.config is None:
        raise ConfigError("--config TOML is required (a user's recording: imu-learn navigate)")
    if not args.online:  # options checked before any file is read
        given = [f"--{o}" for o in ONLINE_ONLY if getattr(args, o) is not None]
        if given:
            raise ConfigError(f"{', '.join(given)}: only with --online")
    kind = config_kind(args.config)
    if kind == GNSS_KIND:
        return gnss_outages(args, keep)
    gnss_given = [f"--{o}" for o, a in (("set", "set_values"), ("variants", "variants")) if getattr(args, a) is not None]
    if gnss_given:
        raise ConfigError(f"{', '.join(gnss_given)}: only with a kind = \"{GNSS_KIND}\" config")
    if args.threads is not None and args.threads < 1:
        raise ConfigError(f"--threads: must be >= 1, got {args.threads}")
    require_gtsam("fuse")
    cfg = load(args.config, args.data_root)
    if args.init is not None:
        cfg.init = args.init
    out = args.out or Path(cfg.out_dir) / cfg.name
    if args.threads is not None or args.online:
        set_torch_threads(args.threads or 1)
    if args.online:
        keep(f"the runs so far are in {out / 'online.json'}")
        online.run_online(cfg, out, args.checkpoint, args.recordings, args.scenarios, args.inputs or online.ONLINE_INPUTS,
                   log=lambda m: print(m, flush=True))
        print(f"wrote {out / 'online.json'}")
    else:
        keep(f"results so far are in {out / 'results.json'} (rerun to resume)")
        batch.run_experiment(cfg, out, only_inputs=args.inputs, jobs=args.jobs)
        print(f"wrote {out / 'table.md'}")
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn fuse ARGV``."""
    return run_command("fuse", argv)
