"""Ctrl-C while modules load: held until the import is whole, then raised as KeyboardInterrupt.

A KeyboardInterrupt raised inside a C extension's initialisation (numpy importing ``datetime``, torch,
GTSAM) can come out as an ImportError with a traceback; while :func:`held_sigint` is active a Ctrl-C
only sets a flag, and the interrupt is raised once the block has finished.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator, List


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
