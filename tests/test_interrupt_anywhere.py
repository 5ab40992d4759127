"""A Ctrl-C that lands where Python does not raise it as a plain KeyboardInterrupt still stops a command
with exit 130 and its one line: inside a finaliser (``__del__``: dropped as "Exception ignored"), inside an
import (a class's ``__set_name__`` wraps it in a RuntimeError), and an interrupted process ends without
finalising the interpreter (a C extension's import cut short crashed it there: exit -6 or -2 after the
interrupted line, navigate's Ctrl-C while its plot imported matplotlib)."""
from __future__ import annotations

import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import imu_learn.cli.checkpoint as checkpoint_cli
from imu_learn.cli import main
from imu_learn.cli.interrupt import interrupts_not_lost

REPO = Path(__file__).resolve().parent.parent


class Finaliser:
    """An object whose finaliser is where the Ctrl-C lands."""

    def __del__(self) -> None:
        raise KeyboardInterrupt


def test_a_ctrl_c_in_a_finaliser_is_raised_again_in_the_code_that_runs_next():
    before = sys.unraisablehook
    with pytest.raises(KeyboardInterrupt), interrupts_not_lost():
        Finaliser()  # collected at once: its KeyboardInterrupt is "ignored" by Python
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:  # the command's own work, which the Ctrl-C must stop
            sum(range(1000))
    assert sys.unraisablehook is before  # the caller's hook again


def test_other_unraisable_exceptions_go_to_the_hook_that_was_there(monkeypatch):
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: seen.append(u.exc_type))

    class Broken:
        def __del__(self) -> None:
            raise ValueError("not an interrupt")

    with interrupts_not_lost():
        Broken()
    assert seen == [ValueError]


def test_a_ctrl_c_that_came_out_as_another_exception_is_an_interrupt(monkeypatch, capsys):
    def run(args, rest, keep):
        keep("nothing is written")
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:  # as Python's class creation wraps it
            raise RuntimeError("Error calling __set_name__ on 'x' instance 'locs' in 'Formatter'") from e

    monkeypatch.setattr(checkpoint_cli, "run", run)
    assert main(["checkpoint", "info", "x.pt"]) == 130
    assert capsys.readouterr().err == "imu-learn checkpoint: interrupted; nothing is written\n"


def test_a_plain_bug_is_still_a_traceback(monkeypatch):
    monkeypatch.setattr(checkpoint_cli, "run", lambda args, rest, keep: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        main(["checkpoint", "info", "x.pt"])


def test_an_interrupted_process_exits_130_at_once_with_its_exit_handlers_run(tmp_path):
    """entry(): the exit handlers run (a file one writes), the interpreter is not finalised (it would wait
    for a worker thread that sleeps a minute)."""
    marker = tmp_path / "atexit"
    script = textwrap.dedent(f"""
        import atexit, pathlib, threading, time
        import imu_learn.cli as cli
        atexit.register(lambda: pathlib.Path({str(marker)!r}).write_text("ran"))
        threading.Thread(target=time.sleep, args=(60,)).start()  # not a daemon: finalising waits for it
        cli.main = lambda argv=None: 130
        cli.entry()
    """)
    t = time.monotonic()
    p = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=50)
    assert (p.returncode, p.stderr) == (130, "")
    assert marker.read_text() == "ran" and time.monotonic() - t < 40
