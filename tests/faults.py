"""Fault injection for the outputs-under-failure tests: a write that fails or stops midway, a small
or read-only file system.

:class:`Fault` breaks the ``nth`` file opened for writing whose name matches a pattern (``*last.pt*``
matches ``last.pt`` and its temporary ``.last.pt.1a2b.tmp`` alike, so it fires whether or not the
code writes atomically): half of the first write reaches the file, then it raises ``ENOSPC`` (a full
disk), or stops there until a signal arrives (``pause``), or until a release file appears
(``hold``). It sees every Python-level write (``open``, ``io.open``, pathlib) and routes the
writers that bypass Python's files (imu_core's Rust writers, ``torch.save`` and polars given a
path) through them. Run as a script it installs a fault and runs a module as ``python -m`` would::

    python tests/faults.py PATTERN NTH ACTION MARKER -- imu_learn.fit --out ...
"""
from __future__ import annotations

import builtins
import contextlib
import errno
import fnmatch
import io
import os
import runpy
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterator, Optional

_real_open = builtins.open
WRITE_MODES = set("wax+")


class Fault:
    def __init__(self, pattern: str, nth: int = 1, action: str = "enospc", marker: Optional[Path] = None) -> None:
        assert action in ("enospc", "pause", "hold")
        self.pattern, self.nth, self.action = pattern, nth, action
        self.marker = Path(marker) if marker else None
        self.seen = 0
        self.fired: Optional[str] = None  # the file it broke

    def matches(self, file: Any) -> bool:
        return isinstance(file, (str, os.PathLike)) and fnmatch.fnmatch(Path(file).name, self.pattern)

    def open(self, file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        f = _real_open(file, mode, *args, **kwargs)
        if WRITE_MODES & set(mode) and self.matches(file):
            self.seen += 1
            if self.seen == self.nth:
                return _BrokenFile(f, self, str(file))
        return f

    def trigger(self, name: str) -> None:
        self.fired = name
        if self.marker is not None:
            self.marker.write_text(name)
        if self.action == "enospc":
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # as write() raises it: no file name
        if self.action == "pause":
            time.sleep(600)  # a signal ends this
        else:  # hold: until the test says go
            release = Path(str(self.marker) + ".go")
            while not release.exists():
                time.sleep(0.05)


class _BrokenFile:
    """A file object whose first write stops halfway and triggers the fault."""

    def __init__(self, f: Any, fault: Fault, name: str) -> None:
        self._f, self._fault, self._name, self._done = f, fault, name, False

    def write(self, data: Any) -> int:
        if self._done or len(data) < 2:
            return self._f.write(data)
        self._done = True
        half = len(data) // 2
        self._f.write(data[:half])
        self._f.flush()
        self._fault.trigger(self._name)
        return half + self._f.write(data[half:])  # only after "hold"

    def __enter__(self) -> _BrokenFile:
        return self

    def __exit__(self, *exc: Any) -> None:
        self._f.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._f, name)


def _through_python(write_to_path: Callable[..., Any], fault: Fault) -> Callable[..., Any]:
    """A writer that takes a path as its first argument, made to write through ``fault.open``."""

    def wrapped(path: Any, *args: Any, **kwargs: Any) -> Any:
        if not isinstance(path, (str, os.PathLike)):
            return write_to_path(path, *args, **kwargs)
        with tempfile.TemporaryDirectory() as d:
            scratch = Path(d) / Path(path).name
            out = write_to_path(str(scratch), *args, **kwargs)
            data = scratch.read_bytes()
        with fault.open(path, "wb") as f:
            f.write(data)
        return out

    return wrapped


@contextlib.contextmanager
def installed(fault: Fault) -> Iterator[Fault]:
    """``fault`` on every writer of this process for the block."""
    import polars
    import torch

    from imu_learn import _imu_core as core
    def through_fault(save: Callable[..., Any]) -> Callable[..., Any]:
        # A writer given a path serialises to memory, then writes through the failing file.
        def wrapped(obj: Any, target: Any = None, *args: Any, **kwargs: Any) -> Any:
            if isinstance(target, (str, os.PathLike)):
                buf = io.BytesIO()
                save(obj, buf, *args, **kwargs)
                with fault.open(target, "wb") as out:
                    out.write(buf.getvalue())
                return None
            return save(obj, target, *args, **kwargs)

        return wrapped

    torch_save, write_csv = through_fault(torch.save), through_fault(polars.DataFrame.write_csv)

    patches = [(builtins, "open", fault.open), (io, "open", fault.open), (torch, "save", torch_save),
               (polars.DataFrame, "write_csv", write_csv)]
    for name in ("write_asl_imu", "write_tum"):
        patches.append((core, name, _through_python(getattr(core, name), fault)))
    old = [(obj, name, getattr(obj, name)) for obj, name, _ in patches]
    for obj, name, new in patches:
        setattr(obj, name, new)
    try:
        yield fault
    finally:
        for obj, name, value in old:
            setattr(obj, name, value)


# ---------------------------------------------------------------------------------------------
# file systems


def can_mount() -> bool:
    """Whether this process may mount a tmpfs (root, and a sandbox that allows it)."""
    if os.geteuid() != 0:
        return False
    with tempfile.TemporaryDirectory() as d:
        if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", d], capture_output=True).returncode:
            return False
        subprocess.run(["umount", d], check=True)
    return True


@contextlib.contextmanager
def tmpfs(folder: Path, size: str = "64m") -> Iterator[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)], check=True)
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=True)


def remount(folder: Path, options: str) -> None:
    subprocess.run(["mount", "-o", f"remount,{options}", str(folder)], check=True)


def shrink_to_used(folder: Path, spare_bytes: int) -> None:
    """Resize the tmpfs at ``folder`` to what it holds now plus ``spare_bytes``."""
    st = os.statvfs(folder)
    used = (st.f_blocks - st.f_bfree) * st.f_frsize
    remount(folder, f"size={used + spare_bytes}")


def main(argv: list) -> None:
    sep = argv.index("--")
    pattern, nth, action, marker = argv[:sep]
    module, args = argv[sep + 1], argv[sep + 2:]
    sys.argv = [module, *args]
    with installed(Fault(pattern, int(nth), action, Path(marker))):
        runpy.run_module(module, run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main(sys.argv[1:])
