"""Ctrl-C held where it must not land: inside a C++ library's call back into Python, or in the
middle of a swap of outputs.

Python runs a signal handler between two bytecodes of the main thread, wherever they are. While
GTSAM optimises a graph with Python factors (``gtsam.CustomFactor``) those bytecodes are the
factors' error functions, called from C++: the default handler raises ``KeyboardInterrupt`` there,
pybind11 turns it into a C++ exception thrown through GTSAM's frames, and it is either lost (GTSAM
catches it and the run goes on: measured, a Ctrl-C during ``navigate --nhc`` ended in a normal exit
49 s later) or the process aborts. Within :func:`held_interrupts` a Ctrl-C only sets a flag: a
Python loop outside the C++ calls polls it (:func:`check`, which raises ``KeyboardInterrupt`` from
plain Python code), and the block raises it on exit when nothing polled it (a block that must run
to its end, e.g. renames that swap an output folder in, holds it until then).
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Any, Iterator, List

_held: List[int] = []  # one entry per Ctrl-C received while held and not yet acted on


def _hold(signum: int, frame: Any) -> None:
    _held.append(signum)


def holding() -> bool:
    """Whether a Ctrl-C is being held now (a :func:`held_interrupts` block is active in this process)."""
    return signal.getsignal(signal.SIGINT) is _hold


@contextmanager
def held_interrupts() -> Iterator[None]:
    """Within the block a Ctrl-C (SIGINT) is held: :func:`check` raises it, and the block's end
    raises ``KeyboardInterrupt`` when one came and was not raised yet. Nested blocks hold with the
    outer one (only the outermost raises at its end). Nothing changes outside the main thread, or
    where SIGINT is not Python's default handler (ignored, or a caller's own handler)."""
    if threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    _held.clear()
    old = signal.signal(signal.SIGINT, _hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
        if _held:
            _held.clear()
            raise KeyboardInterrupt


def check() -> None:
    """Raise ``KeyboardInterrupt`` when a Ctrl-C is being held (call it from a Python loop between
    the C++ calls: a sample fed to the graph, an iteration)."""
    if _held:
        _held.clear()
        raise KeyboardInterrupt
