"""Ctrl-C while modules load: held until the import is whole, then raised as KeyboardInterrupt; SIGTERM
raised as Ctrl-C (:func:`sigterm_as_interrupt`); a Ctrl-C that landed in a ``__del__`` raised again
(:func:`interrupts_not_lost`); an interrupted process's exit (:func:`exit_interrupted`).

A KeyboardInterrupt raised inside a C extension's initialisation (numpy importing ``datetime``, torch,
GTSAM) can come out as an ImportError with a traceback; while :func:`held_sigint` is active a Ctrl-C
only sets a flag, and the interrupt is raised once the block has finished.
"""
from __future__ import annotations

import atexit
import os
import signal
import sys
import threading
from contextlib import contextmanager
from typing import Any, Iterator, List


@contextmanager
def held_sigint() -> Iterator[None]:
    """Defer SIGINT to the end of the block (main thread, Python's own handler in place); else a no-op."""
    if threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    caught: List[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if caught:
        raise KeyboardInterrupt


@contextmanager
def sigterm_as_interrupt() -> Iterator[List[int]]:
    """Within the block SIGTERM is raised as a Ctrl-C (SIGINT to this process), so the outputs' clean-up runs
    as for one, and Ctrl-C held while outputs go in holds it too; yields a list that gets SIGTERM's number
    once one came. Where SIGTERM is not at its default (a caller's handler) or off the main thread: as is."""
    came: List[int] = []
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGTERM) != signal.SIG_DFL:
        yield came
        return

    def as_sigint(signum: int, frame: Any) -> None:
        came.append(signum)
        signal.raise_signal(signal.SIGINT)

    signal.signal(signal.SIGTERM, as_sigint)
    try:
        yield came
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


REDELIVER_S = 0.01  # a Ctrl-C lost in a __del__ is sent again this much later (past the finaliser)


@contextmanager
def interrupts_not_lost() -> Iterator[None]:
    """Within the block a Ctrl-C that Python raised inside a finaliser (``__del__``: a progress bar
    collected as a function returns), where it is printed as "Exception ignored" and dropped while the
    command runs on to its end, is sent to this process again a moment later, so that it lands in the
    code that runs next (measured: navigate, Ctrl-C as the fusion ended, exit 0 after writing every
    output). Other unraisable exceptions go to the hook that was there."""
    previous = sys.unraisablehook

    def hook(unraisable: Any) -> None:
        if isinstance(unraisable.exc_type, type) and issubclass(unraisable.exc_type, KeyboardInterrupt):
            again = threading.Timer(REDELIVER_S, os.kill, (os.getpid(), signal.SIGINT))
            again.daemon = True
            again.start()
            return
        previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = previous


def exit_interrupted(code: int) -> None:
    """End an interrupted process with ``code`` (130, 143) now: stdio flushed and the exit handlers run,
    the interpreter not finalised. A Ctrl-C inside a C extension's import (matplotlib's, as a plot is
    written) can leave it half initialised, and finalising it then aborted the process or killed it by
    SIGINT (measured: exit -6, "Fatal Python error: PyThreadState_Get ... finalizing", and -2, after the
    line that said the run was interrupted)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # pragma: no cover - a closed or broken pipe: nothing more to say
            pass
    atexit._run_exitfuncs()
    os._exit(code)
