"""``python -m imu_learn.fuse --config configs/fuse_euroc.toml``: the fusion experiment (see
:mod:`imu_learn.fuse.run`); with ``--online``, each recording streamed sample by sample through the
causal model and iSAM2 with per-sample latency measured (see :mod:`imu_learn.fuse.online`). Known
errors print one line and exit 1."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import List, Optional

from imu_learn.errors import ImuError

DESCRIPTION = """Fuse IMU inputs (raw, a calibration, a trained model's refinement) with aiding in a GTSAM
factor graph and score the trajectories against ground truth: every recording x input x aiding
scenario of a config, causal (iSAM2) and smoothed (batch LM). With --online, each recording is
streamed sample by sample instead (the causal model's step, preintegration, iSAM2 at keyframes)
and the per-sample latency and real-time factor are measured. Known errors print one line and
exit 1."""

EPILOG = """examples:
  IMU_LEARN_DATA=<data root> python -m imu_learn.fuse --config configs/fuse_euroc.toml
      every recording x input x aiding scenario of the config, causal and smoothed
      -> reports/fuse_euroc/{results.json,table.md,trajectories/,plots/}
  IMU_LEARN_DATA=<data root> python -m imu_learn.fit --config configs/euroc_paper.toml --name euroc_causal_s0 \\
      --model.causal true --model.fir_taps 0
      a causal checkpoint (runs/euroc_causal_s0/best.pt; about 3 min on one CPU core)
  IMU_LEARN_DATA=<data root> python -m imu_learn.fuse --config configs/fuse_euroc.toml --online \\
      --checkpoint runs/euroc_causal_s0/best.pt --recordings V1_01_easy --scenarios gnss_1hz
      the recording as a stream (raw and the causal model's refinement), one line per run with the
      causal position RMSE, per-sample latency (median, p99) and real-time factor
      -> reports/fuse_euroc/online.json
"""

ONLINE_ONLY = ("checkpoint", "recordings", "scenarios")


def _names(text: str) -> List[str]:
    return [n.strip() for n in text.split(",") if n.strip()]


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m imu_learn.fuse", description=DESCRIPTION,
                                 epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", type=Path, required=True, metavar="TOML",
                    help="fusion config: recordings, IMU inputs, aiding scenarios (configs/fuse_*.toml)")
    ap.add_argument("--data-root", default=None, metavar="DIR",
                    help="data root the config's recording paths are relative to (beats the config's data_root "
                         "and IMU_LEARN_DATA)")
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
    ap.add_argument("--traceback", action="store_true", help="show the full traceback of a known error")
    return ap


def main(argv: Optional[List[str]] = None) -> int:
    ap = parser()
    args = ap.parse_args(argv)
    if not args.online:
        given = [f"--{o}" for o in ONLINE_ONLY if getattr(args, o) is not None]
        if given:
            ap.error(f"{', '.join(given)}: only with --online")
    if args.threads is not None and args.threads < 1:
        ap.error(f"--threads: must be >= 1, got {args.threads}")
    if args.threads is not None or args.online:
        import torch

        torch.set_num_threads(args.threads or 1)
    from .config import load

    try:
        cfg = load(args.config, args.data_root)
        out = args.out or Path(cfg.out_dir) / cfg.name
        if args.online:
            from .online import ONLINE_INPUTS, run_online

            run_online(cfg, out, args.checkpoint, args.recordings, args.scenarios, args.inputs or ONLINE_INPUTS,
                       log=lambda m: print(m, flush=True))
            print(f"imu_learn.fuse: wrote {out / 'online.json'}")
        else:
            from .run import run_experiment

            run_experiment(cfg, out, only_inputs=args.inputs)
            print(f"imu_learn.fuse: wrote {out / 'table.md'}")
    except (ImuError, FileNotFoundError, OSError) as e:
        if args.traceback:
            raise
        from imu_learn.errors import one_line

        print(f"imu_learn.fuse: error: {one_line(e)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("imu_learn.fuse: interrupted; " + ("the runs so far are in online.json" if args.online else
              "results so far are in results.json (rerun to resume)"), file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
