"""``imu-learn``: one console command with a subcommand per pipeline stage.

    imu-learn labels  DATASET   build the label cache of a dataset (imu_learn.data.labels)
    imu-learn fit               train the refiner (imu_learn.train.fit)
    imu-learn evaluate          fit every method on a train split and score it on a test split
    imu-learn refine            write refined IMU in the input's own format
    imu-learn export            TorchScript / ONNX of a checkpoint
    imu-learn fuse              fuse IMU with aiding in a factor graph
    imu-learn checkpoint        inspect or strip a checkpoint

``python -m imu_learn.<stage>`` is the same as ``imu-learn <stage>``.
"""
from __future__ import annotations

import importlib
import sys
from typing import List, Optional

# subcommand -> (module holding its main(argv), one-line help); modules are imported only when run.
COMMANDS = {
    "labels": ("imu_learn.data.labels", "build the label cache of a dataset (parse, align, labels; Rust)"),
    "fit": ("imu_learn.train.fit", "train the refiner from a config (default: the shipped crops)"),
    "evaluate": ("imu_learn.eval.run", "fit every method on a train split, score it on a test split"),
    "refine": ("imu_learn.infer.refine", "write refined IMU with a checkpoint, in the input's own format"),
    "export": ("imu_learn.infer.export", "export a checkpoint to TorchScript and ONNX"),
    "fuse": ("imu_learn.fuse.__main__", "fuse IMU with aiding in a GTSAM factor graph"),
    "checkpoint": ("imu_learn.train.checkpoint", "inspect (info) or strip a checkpoint"),
}


def usage() -> str:
    width = max(map(len, COMMANDS))
    rows = "\n".join(f"  {name:<{width}}  {text}" for name, (_, text) in COMMANDS.items())
    return f"usage: imu-learn <command> [options]   (imu-learn <command> --help)\n\ncommands:\n{rows}\n"


def main(argv: Optional[List[str]] = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        sys.stdout.write(usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        sys.stderr.write(f"imu-learn: error: unknown command {name!r}\n{usage()}")
        return 2
    module = importlib.import_module(COMMANDS[name][0])
    return int(module.main(rest) or 0)


if __name__ == "__main__":
    sys.exit(main())
