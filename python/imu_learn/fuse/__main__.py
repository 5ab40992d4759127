"""``python -m imu_learn.fuse --config configs/fuse_euroc.toml``: the fusion experiment (see
:mod:`imu_learn.fuse.run`). Known errors print one line and exit 1."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import List, Optional

from imu_learn.errors import ImuError


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m imu_learn.fuse", description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, required=True, help="fusion TOML (configs/fuse_*.toml)")
    ap.add_argument("--data-root", default=None, help="data root (beats the config and IMU_LEARN_DATA)")
    ap.add_argument("--out", type=Path, default=None, help="report folder (default <out_dir>/<name>)")
    ap.add_argument("--traceback", action="store_true", help="show the full traceback of a known error")
    args = ap.parse_args(argv)
    from .config import load
    from .run import run_experiment

    try:
        cfg = load(args.config, args.data_root)
        out = args.out or Path(cfg.out_dir) / cfg.name
        run_experiment(cfg, out)
        print(f"imu_learn.fuse: wrote {out / 'table.md'}")
    except (ImuError, FileNotFoundError, OSError) as e:
        if args.traceback:
            raise
        print(f"imu_learn.fuse: error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("imu_learn.fuse: interrupted; results so far are in results.json (rerun to resume)", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
