"""The thread pools of one process, sized together from one number.

A process here can run three pools at once: torch's intra-op pool (OpenMP; MKL inside torch follows
it), the BLAS under numpy/scipy (OpenBLAS), and rayon's pool in the Rust core. Each defaults to every
core. On a small machine (two cores) that oversubscribes the cores as soon as two of them work at
once, and OpenMP makes it much worse when another process is busy: every parallel region ends at a
barrier that waits for all its threads, so a region whose second thread has been descheduled waits
for a scheduler slice (milliseconds) instead of microseconds. A fit made of thousands of small
torch operations (the ``traditional`` floor, EuRoC's five flights and their refits) took 41-60 s
with two torch threads against 9-14 s with one, on two cores beside other engineers' builds (load
5.5-7); with one thread it slows only by the share of the CPU it gets (its CPU time stays the same
with a busy loop beside it). So such fits run with one torch thread (:func:`thread_limits`).

What can be changed when:

* torch's intra-op threads and OpenBLAS's threads: at any time (:func:`thread_limits`, restored on
  exit); torch's inter-op pool only before its first use (unused by the fits here).
* rayon's pool: sized once, from ``RAYON_NUM_THREADS``, when the core first uses it; OpenMP's
  spin policy (``OMP_WAIT_POLICY``) and every ``*_NUM_THREADS`` default: read once when each runtime
  starts. :func:`thread_env` writes them for a process about to start (a child process, a
  benchmark, a job script); in a running process they only reach runtimes that have not started.
"""
from __future__ import annotations

import ctypes
import os
import sys
from contextlib import contextmanager
from typing import Any, Dict, Iterator, List, Optional, Tuple

ENV_KEYS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "RAYON_NUM_THREADS")


def cores() -> int:
    """The cores this process may run on (its CPU affinity; at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def clamp(threads: Optional[int]) -> int:
    """``threads`` within 1 .. :func:`cores` (None: every core)."""
    n = cores()
    return n if threads is None else max(1, min(int(threads), n))


def thread_env(threads: int, env: Optional[Dict[str, str]] = None) -> Dict[str, str]:
    """``env`` (default: a copy of ``os.environ``) with every pool's size set to ``threads`` (clamped
    to the cores) and OpenMP's waiting threads passive (they sleep at once instead of spinning on a
    core another process could use). For a process about to start: ``subprocess.run(...,
    env=thread_env(2))``. Values already in ``env`` are kept (the user's choice wins)."""
    out = dict(os.environ if env is None else env)
    n = str(clamp(threads))
    for key in ENV_KEYS:
        out.setdefault(key, n)
    out.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    return out


def _openblas_setters() -> List[Tuple[Any, Any]]:
    """(set, get) ``openblas_[sg]et_num_threads`` of every OpenBLAS this process has loaded (numpy's and
    scipy's ``scipy_openblas`` builds prefix and suffix the names; get None where absent), found
    through /proc/self/maps; empty where there is none or no such file (not Linux). What
    threadpoolctl does for OpenBLAS, without the dependency. The maps are read again only once modules
    were imported since (a library loads with a module: numpy's, scipy's)."""
    loaded = len(sys.modules)
    if _SCANNED and _SCANNED[0][0] == loaded:
        return _SCANNED[0][1]
    try:
        with open("/proc/self/maps") as f:
            paths = {p for p in (line.split()[-1] for line in f) if "openblas" in os.path.basename(p).lower() and ".so" in p}
    except OSError:
        return []
    out = []
    for path in sorted(paths):
        if path in _LIBS:
            out += _LIBS[path]
            continue
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        _LIBS[path] = []
        for name in ("openblas_set_num_threads", "scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                     "openblas_set_num_threads64_"):
            fn = getattr(lib, name, None)
            if fn is not None:
                fn.argtypes, fn.restype = [ctypes.c_int], None
                getter = getattr(lib, name.replace("set_num_threads", "get_num_threads"), None)
                if getter is not None:
                    getter.argtypes, getter.restype = [], ctypes.c_int
                _LIBS[path].append((fn, getter))
                break
        out += _LIBS[path]
    _SCANNED[:] = [(loaded, out)]
    return out


_LIBS: Dict[str, List[Tuple[Any, Any]]] = {}  # path -> its (set, get), looked up once
_SCANNED: List[Tuple[int, List[Tuple[Any, Any]]]] = []  # (modules loaded, the setters then): the last scan


@contextmanager
def thread_limits(threads: int, blas: bool = True) -> Iterator[int]:
    """Within the block, torch's intra-op pool (when torch is imported) and, with ``blas``, every loaded
    OpenBLAS run ``threads`` threads (clamped to the cores); both are restored on exit. Yields the
    number used."""
    n = clamp(threads)
    torch = sys.modules.get("torch")
    before_torch = torch.get_num_threads() if torch is not None else None
    blas_fns = _openblas_setters() if blas else []
    before_blas = [get() if get is not None else None for _, get in blas_fns]
    try:
        if torch is not None and before_torch != n:
            torch.set_num_threads(n)
        for set_, _ in blas_fns:
            set_(n)
        yield n
    finally:
        if torch is not None and before_torch is not None and torch.get_num_threads() != before_torch:
            torch.set_num_threads(before_torch)
        for (set_, _), old in zip(blas_fns, before_blas):
            if old is not None and old > 0:
                set_(old)
