"""Ctrl-C while modules load: held until the import is whole, then raised as KeyboardInterrupt; SIGTERM
raised as Ctrl-C (:func:`sigterm_as_interrupt`).

A KeyboardInterrupt raised inside a C extension's initialisation (numpy importing ``datetime``, torch,
GTSAM) can come out as an ImportError with a traceback; while :func:`held_sigint` is active a Ctrl-C
only sets a flag, and the interrupt is raised once the block has finished.
"""
from __future__ import annotations

import signal
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
