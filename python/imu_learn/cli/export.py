"""``imu-learn export``: TorchScript, ONNX and a JSON card of a checkpoint (:mod:`imu_learn.infer.exporters`)."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import run_command
from imu_learn.util.extras import require_extra

DESCRIPTION = """Export a refiner to TorchScript (model.ts) and ONNX (model.onnx) with a JSON card (model.json:
inputs, outputs, units, normalisation, and each export's largest difference from the torch model)."""
EPILOG = """example:
  imu-learn export --checkpoint models/euroc_adis16448.pt --out exported/euroc"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", required=True, type=Path, metavar="PT", help="imu_learn checkpoint (.pt)")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="folder for model.ts, model.onnx, model.json")
    p.add_argument("--window", type=int, default=200, help="time length of the example used for tracing (>= 2)")
    p.add_argument("--opset", type=int, default=17, help="ONNX opset (default 17)")


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    require_extra("export", "imu-learn export")
    from imu_learn.infer.exporters import export, summary

    card = export(args.checkpoint, args.out, args.window, args.opset)
    print(summary(card, args.out))
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn export ARGV``."""
    return run_command("export", argv)
