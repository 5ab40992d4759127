"""``imu-learn checkpoint info|strip``: what a checkpoint holds, or a small copy for shipping
(:mod:`imu_learn.infer.checkpoint`)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import run_command
from imu_learn.util.extras import require_extra

DESCRIPTION = """Inspect a checkpoint (info: JSON on stdout) or write a copy keeping only what inference needs
(strip: no optimiser state or metrics history; loads everywhere a checkpoint does, cannot be resumed)."""
EPILOG = """examples:
  imu-learn checkpoint info models/euroc_adis16448.pt
  imu-learn checkpoint strip runs/euroc1/best.pt models/euroc1.pt"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", required=True, metavar="{info,strip}")
    pi = sub.add_parser("info", help="print what a checkpoint holds (JSON)")
    pi.add_argument("path", type=Path, metavar="PT")
    ps = sub.add_parser("strip", help="copy a checkpoint keeping only what inference needs (no optimiser state)")
    ps.add_argument("src", type=Path, metavar="SRC")
    ps.add_argument("dst", type=Path, metavar="DST")
    for sp in (pi, ps):  # the common flags also after the action's arguments (set only when given)
        sp.add_argument("--quiet", "-q", action="store_true", default=argparse.SUPPRESS, help="as imu-learn checkpoint --quiet")
        sp.add_argument("--traceback", action="store_true", default=argparse.SUPPRESS,
                        help="as imu-learn checkpoint --traceback")


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    require_extra("train", "imu-learn checkpoint")
    from imu_learn.infer.checkpoint import describe, load_checkpoint, strip_checkpoint

    if args.action == "strip":
        strip_checkpoint(args.src, args.dst)
        before, after = args.src.stat().st_size, args.dst.stat().st_size
        print(f"{args.dst}: {after / 1e6:.3f} MB (from {before / 1e6:.3f} MB)")
    else:
        print(json.dumps(describe(load_checkpoint(args.path)), indent=2))
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn checkpoint ARGV``."""
    return run_command("checkpoint", argv)
