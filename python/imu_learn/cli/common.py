"""What every ``imu-learn`` subcommand shares: the common flags, logging set-up, and the one error
wrapper (:func:`run_command`).

* A known error (:class:`imu_learn.errors.ImuError` and its subclasses, :class:`OSError` incl.
  FileNotFoundError / PermissionError) prints ``imu-learn <cmd>: error: <Class>: <message>`` on one
  line on stderr and exits 2; with ``--traceback`` it is re-raised instead.
* Ctrl-C prints ``imu-learn <cmd>: interrupted`` (and what was kept) and exits 130, also where it came
  out as an exception it caused (a Ctrl-C inside an import: RuntimeError, ImportError). SIGTERM (``timeout``,
  ``docker stop``, a batch scheduler) stops the same way, through the same clean-up, and exits 143
  (:func:`imu_learn.cli.interrupt.sigterm_as_interrupt`).
* Any other exception is a bug: it is never caught, Python prints its traceback.
* Logging of the library goes to stderr as ``imu-learn <cmd>: message`` (INFO; WARNING with
  ``--quiet``, which also turns the progress bars off). Results go to stdout.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import sys
from typing import Any, Callable, Dict, Iterator, List, NoReturn, Optional, Sequence, Union

from imu_learn.cli.interrupt import held_sigint, interrupts_not_lost, sigterm_as_interrupt
from imu_learn.data.formats import USER_CSV
from imu_learn.data.formats.csv_columns import ACC_UNITS, DEFAULT_COLUMNS, GYRO_UNITS, TIME_UNITS, CsvColumns
from imu_learn.errors import ImuError, one_line
from imu_learn.settings import DATA_ROOT_ENV
from imu_learn.util.extras import interrupted

EXIT_OK = 0
EXIT_ERROR = 2
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143  # 128 + SIGTERM
KNOWN_ERRORS = (ImuError, OSError)

# subcommand -> one-line help; each lives in imu_learn.cli.<name> (module imported only when run)
COMMANDS: Dict[str, str] = {
    "labels": "build the label cache of a dataset (parse, align, labels; Rust)",
    "fit": "train the refiner from a config (default: the shipped crops)",
    "evaluate": "fit every method on a train split, score it on a test split",
    "refine": "write refined IMU with a checkpoint, in the input's own format",
    "export": "export a checkpoint to TorchScript and ONNX",
    "fuse": "fusion experiments of a config: IMU with aiding in a GTSAM factor graph",
    "navigate": "navigate a recording with its aiding file (no ground truth)",
    "groundtruth": "check a recording's ground truth against its own IMU (frame, time offset, lever arm)",
    "calibrate": "a device profile (time offset, calibration, noise; Kalibr imu.yaml) from recordings",
    "checkpoint": "inspect (info) or strip a checkpoint",
}

Kept = Union[str, Callable[[], str]]


def prog(name: str) -> str:
    return f"imu-learn {name}"


class _StderrHandler(logging.Handler):
    """Writes to the current ``sys.stderr`` (not the one at set-up: tests swap it)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(self.format(record) + "\n")
            sys.stderr.flush()
        except Exception:  # pragma: no cover - logging must never raise
            self.handleError(record)


class _Format(logging.Formatter):
    def __init__(self, name: str) -> None:
        super().__init__()
        self.name = name

    def format(self, record: logging.LogRecord) -> str:
        level = "" if record.levelno < logging.WARNING else f"{record.levelname.lower()}: "
        return f"{prog(self.name)}: {level}{record.getMessage()}"


@contextlib.contextmanager
def logging_to_stderr(name: str, quiet: bool) -> Iterator[None]:
    """For the block: the ``imu_learn`` logger to stderr as ``imu-learn <name>: message``, INFO, or
    WARNING when quiet. The logger is left as it was afterwards (a command run from Python, e.g. a
    test, leaves no handler behind)."""
    log = logging.getLogger("imu_learn")
    handler = _StderrHandler()
    handler.setFormatter(_Format(name))
    level = log.level
    log.addHandler(handler)
    log.setLevel(logging.WARNING if quiet else logging.INFO)
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.setLevel(level)


def add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bars and no info messages (warnings and "
                                                                "errors still go to stderr)")
    p.add_argument("--traceback", action="store_true", help="re-raise a known error (full traceback) instead of "
                                                            "its one-line message")


def add_data_root(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--data-root", metavar="DIR", default=None,
                   help=f"the data root {what} are relative to (default: ${DATA_ROOT_ENV}, else the config's "
                        "data_root; this flag beats both)")


# The CsvColumns fields the options of a user's own IMU CSV set (--columns, --time-unit, ...).
_CSV_FIELDS = ("columns", "time_unit", "gyro_unit", "acc_unit", "skip_bad_lines")


def add_imu_input_options(p: argparse.ArgumentParser) -> None:
    """The options of a user's own IMU CSV, the same on every command that reads IMU; any of them
    (or ``--format csv-columns``) makes the input such a CSV. :func:`csv_layout` reads them back,
    :func:`imu_learn.data.formats.read_imu_source` / ``read_recording`` (``columns=``) read the file."""
    g = p.add_argument_group(
        "a user's own IMU CSV",
        f"any of these (or --format {USER_CSV}) reads --input as a CSV of your own; its delimiter\n"
        "(comma, semicolon, tab, spaces), header and # comments are found in the file; what is written\n"
        "back keeps its columns and units")
    g.add_argument("--columns", metavar="MAP", default=None,
                   help=f"the file's column order, each of t,gx,gy,gz,ax,ay,az once, _ skips a column "
                        f"(default {DEFAULT_COLUMNS}); columns after the last named are ignored")
    g.add_argument("--time-unit", choices=TIME_UNITS, default=None,
                   help="unit of the time column, integer or float text (default ns)")
    g.add_argument("--gyro-unit", choices=GYRO_UNITS, default=None, help="default rad/s")
    g.add_argument("--acc-unit", choices=ACC_UNITS, default=None, help="default m/s2 (g: 9.80665 m/s2)")
    g.add_argument("--skip-bad-lines", action="store_true", default=None,
                   help="skip a line too short for the map or with a value that is not a number (a logger's "
                        "truncated first or last line) instead of stopping; the count skipped is reported")


def csv_layout(args: argparse.Namespace) -> Optional[CsvColumns]:
    """The user's-CSV layout the options of :func:`add_imu_input_options` give (unset ones take
    CsvColumns' defaults), or None when none is given. Without --columns the default map is
    assumed (``columns_named=False``: a file with more columns than it names is refused)."""
    given = {k: getattr(args, k) for k in _CSV_FIELDS if getattr(args, k, None) is not None}
    return CsvColumns(**given, columns_named="columns" in given) if given else None


class OneLineParser(argparse.ArgumentParser):
    """argparse with its errors in one line (exit 2), as every other error of the CLI: the usage block
    of a command with thirty options hid the one line that said what was wrong."""

    def error(self, message: str) -> NoReturn:  # type: ignore[override]
        hint = ("; a value that starts with '-' is written --OPTION=VALUE (e.g. --gaps=-5:10)"
                if "expected one argument" in message else "")
        self.exit(2, f"{self.prog}: error: {message}{hint} ({self.prog} --help lists the options)\n")


def parser(name: str) -> argparse.ArgumentParser:
    mod = importlib.import_module(f"imu_learn.cli.{name}")
    p = OneLineParser(prog=prog(name), allow_abbrev=False, description=mod.DESCRIPTION,
                                epilog=getattr(mod, "EPILOG", None),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    mod.add_arguments(p)
    add_common(p)
    return p


def _end_progress() -> None:
    """Close the progress bars a stopped command left open (tqdm's, where it is loaded), so that the
    command's last line starts a line of its own instead of following a bar's text."""
    tqdm = sys.modules.get("tqdm")
    for bar in list(getattr(getattr(tqdm, "tqdm", None), "_instances", None) or ()):
        try:
            bar.close()
        except Exception:  # pragma: no cover - a bar that cannot close must not hide the message
            pass


def run_command(name: str, argv: Optional[Sequence[str]] = None, **hooks: Any) -> int:
    """Parse ``argv`` for subcommand ``name`` and run it under the one error rule (module doc)."""
    with sigterm_as_interrupt() as terminated, interrupts_not_lost():
        code = _run_command(name, argv, terminated, **hooks)
    return EXIT_TERMINATED if terminated and code == EXIT_INTERRUPTED else code


def _run_command(name: str, argv: Optional[Sequence[str]], terminated: List[int], **hooks: Any) -> int:
    try:
        with held_sigint():
            mod = importlib.import_module(f"imu_learn.cli.{name}")
    except KeyboardInterrupt:  # while its modules load (GTSAM, torch: seconds)
        sys.stderr.write(f"{prog(name)}: {'terminated (SIGTERM)' if terminated else 'interrupted'}\n")
        return EXIT_INTERRUPTED
    p = parser(name)
    argv = list(sys.argv[1:] if argv is None else argv)
    if getattr(mod, "OVERRIDES", False):  # --key.sub VALUE config overrides
        args, rest = p.parse_known_args(argv)
    else:
        args, rest = p.parse_args(argv), []
    kept: List[Kept] = []  # what the command has kept so far, said on Ctrl-C
    try:
        with logging_to_stderr(name, args.quiet):
            return int(mod.run(args, rest, kept.append, **hooks) or EXIT_OK)
    except KeyboardInterrupt:
        return _stopped(name, kept, terminated)
    except KNOWN_ERRORS as e:
        if interrupted(e):
            return _stopped(name, kept, terminated)
        if args.traceback:
            raise
        _end_progress()
        sys.stderr.write(f"{prog(name)}: error: {one_line(e)}\n")
        return EXIT_ERROR
    except Exception as e:
        # a Ctrl-C that landed in an import (a class's __set_name__, a C extension's initialisation)
        # comes out as another exception that it caused (RuntimeError, ImportError): an interrupt still
        if interrupted(e):
            return _stopped(name, kept, terminated)
        raise


def _stopped(name: str, kept: List[Kept], terminated: List[int]) -> int:
    """The one line of a Ctrl-C (or SIGTERM): what the command has kept, exit 130."""
    _end_progress()
    said = [k() if callable(k) else k for k in kept]
    said = [s for s in said if s]
    word = "terminated (SIGTERM)" if terminated else "interrupted"
    sys.stderr.write(f"{prog(name)}: {word}{'; ' + '; '.join(said) if said else ''}\n")
    return EXIT_INTERRUPTED
