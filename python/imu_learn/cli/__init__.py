"""``imu-learn``: one console command with a subcommand per pipeline stage.

    imu-learn labels DATASET    build the label cache of a dataset
    imu-learn fit               train the refiner (default: the shipped crops)
    imu-learn evaluate          fit every method on a train split and score it on a test split
    imu-learn refine            write refined IMU in the input's own format
    imu-learn export            TorchScript / ONNX of a checkpoint
    imu-learn fuse              fusion experiments of a config (factor graph)
    imu-learn navigate          navigate a recording with its aiding file
    imu-learn groundtruth       check a recording's ground truth against its own IMU
    imu-learn calibrate         a device profile and Kalibr's imu.yaml from recordings
    imu-learn checkpoint        inspect (info) or strip a checkpoint

``python -m imu_learn.<stage>`` is the same as ``imu-learn <stage>``. Each subcommand lives in
``imu_learn.cli.<name>`` (its options and what it prints); :mod:`imu_learn.cli.common` holds the one
error rule, the logging set-up and the flags every subcommand has (``--quiet``, ``--traceback``).
"""
from __future__ import annotations

import signal
import sys
import threading

try:  # the command's start (typing, numpy, the core): a Ctrl-C here exits 130 in one line too
    from imu_learn.cli.interrupt import held_sigint

    with held_sigint():
        from typing import Any, List, Optional

        from imu_learn.cli.common import COMMANDS, EXIT_ERROR, EXIT_INTERRUPTED, EXIT_TERMINATED, run_command
        from imu_learn.cli.interrupt import exit_interrupted
except KeyboardInterrupt:
    sys.stderr.write("imu-learn: interrupted\n")
    raise SystemExit(130) from None


def usage() -> str:
    width = max(map(len, COMMANDS))
    rows = "\n".join(f"  {name:<{width}}  {text}" for name, text in COMMANDS.items())
    return (f"usage: imu-learn <command> [options]   (imu-learn <command> --help)\n\ncommands:\n{rows}\n\n"
            "every command: --quiet (no progress, no info), --traceback (full traceback of a known error);\n"
            "a known error is one line 'imu-learn <command>: error: <Class>: <message>', exit status 2;\n"
            "Ctrl-C exits 130. Data root: --data-root DIR or $IMU_LEARN_DATA; outputs: --out.\n")


def main(argv: Optional[List[str]] = None, **hooks: Any) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        sys.stdout.write(usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        sys.stderr.write(f"imu-learn: error: unknown command {name!r}\n{usage()}")
        return EXIT_ERROR
    return run_command(name, rest, **hooks)


def entry(argv: Optional[List[str]] = None) -> None:
    """The console command (``imu-learn``, ``python -m imu_learn.cli``, ``python -m imu_learn.<stage>`` with
    ``argv``): :func:`main`, then Ctrl-C ignored while the process exits. A Ctrl-C that came once the command
    had finished (its outputs complete and said so) made the exit 130 without a word, as if the run had
    failed (refine and labels, 0.1-0.8 s after their last line)."""
    code = main(argv)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        if code in (EXIT_INTERRUPTED, EXIT_TERMINATED):
            exit_interrupted(code)  # not finalised: a module a Ctrl-C cut short could crash it
    sys.exit(code)


__all__ = ["COMMANDS", "entry", "main", "usage"]
