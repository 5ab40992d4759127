"""Work split between this process and one helper process, each side keeping its items' state.

Why a process and not a thread. calibrate's held-out selection fits and scores five folds; each is
thousands of short numpy calls and core calls between stretches of Python, so two threads of one
process take turns on the GIL and gained only 1.1-1.4x on two cores. A second process has its own
interpreter. The helper is a fresh interpreter (``python -c``, this process's ``sys.path``), not a
fork: a forked child of a process whose core has started rayon's pool would wait forever on that
pool's missing worker threads.

How. :class:`Split` assigns every other item to the helper (the helper starts while this process
works on its own first item, so its start-up overlaps). :meth:`Split.step` runs one module-level
function ``fn(item, state, *args)`` on every item, where ``state`` is that item's dict kept between
steps on the side that holds the item; arguments and results travel pickled, in frames, over two
pipes of their own (not its stdin and stdout: a site customisation that prints at start-up must not
be read as a reply), the items once. A command may start one helper for its whole run
(:func:`shared_helper`) so that its start-up overlaps the command's reading. The helper runs one
thread per pool (rayon, OpenMP, OpenBLAS), this interpreter's flags (-I, -E ...) and its own
session, so a Ctrl-C at the terminal reaches only this process, which ends the helper on the way
out (:meth:`Split.close`, also when the block is left by an exception).

Nothing depends on the helper: where it cannot start, dies or answers with something other than a
result or an exception of its own, this process runs the helper's items itself, replaying the
steps so far in order (the same functions on the same items: the same results). An exception raised
by ``fn`` in the helper is raised here, as it would have been had the item run here.
"""
from __future__ import annotations

import importlib
import os
import pickle
import queue
import struct
import subprocess
import sys
import threading
from contextlib import contextmanager
from typing import Any, BinaryIO, Callable, Dict, Iterator, List, Optional, Sequence, Tuple

from imu_learn.util.threads import ENV_KEYS, cores

Step = Tuple[Callable[..., Any], Tuple[Any, ...]]


def _helper_env() -> Dict[str, str]:
    """This process's environment with every pool of the helper at one thread (it runs one item at a
    time on its core), OpenMP's waiting threads passive."""
    env = dict(os.environ)
    env.update({k: "1" for k in ENV_KEYS})
    env["OMP_WAIT_POLICY"] = "PASSIVE"
    return env


MAGIC = b"IMUH"  # each message: MAGIC, its length (8 bytes, little-endian), the pickle
HEADER = struct.Struct("<4sQ")


def write_frame(f: BinaryIO, data: bytes) -> None:
    f.write(HEADER.pack(MAGIC, len(data)) + data)
    f.flush()


def read_frame(f: BinaryIO) -> bytes:
    """One message's pickle; EOFError at the end of input, OSError on anything that is not a frame."""
    head = f.read(HEADER.size)
    if len(head) < HEADER.size:
        raise EOFError("the other process closed its end")
    magic, n = HEADER.unpack(head)
    if magic != MAGIC:
        raise OSError(f"not a message from the other process ({head!r})")
    data = f.read(n)
    if len(data) < n:
        raise EOFError("the other process closed its end mid-message")
    return data


def _interpreter_flags() -> List[str]:
    """This interpreter's flags that a child should share (-I, -E, -s ...), as multiprocessing passes them."""
    try:
        return list(subprocess._args_from_interpreter_flags())  # type: ignore[attr-defined]
    except Exception:
        return ["-I"] if sys.flags.isolated else []


class _Helper:
    """The helper process. Messages and replies travel in frames (:func:`write_frame`) over two pipes
    of their own, not its stdin and stdout: whatever its start-up prints (a site customisation's
    banner) goes to stderr and can never be read as a reply."""

    def __init__(self) -> None:
        child_in, to_child = os.pipe()  # (read end, write end)
        from_child, child_out = os.pipe()
        # an interpreter that cannot import the package exits quietly (3): its items then run here
        code = (f"import sys\nsys.path[:0] = {list(sys.path)!r}\ntry:\n    from imu_learn.util.helper import serve\n"
                f"except Exception:\n    sys.exit(3)\nserve({child_in}, {child_out})")
        try:
            self.proc = subprocess.Popen([sys.executable, *_interpreter_flags(), "-c", code], stdin=subprocess.DEVNULL,
                                         stdout=sys.stderr.fileno() if _has_fileno(sys.stderr) else subprocess.DEVNULL,
                                         env=_helper_env(), start_new_session=True, pass_fds=(child_in, child_out))
        except BaseException:
            os.close(to_child)
            os.close(from_child)
            raise
        finally:
            os.close(child_in)
            os.close(child_out)
        self._out = os.fdopen(to_child, "wb")
        self._in = os.fdopen(from_child, "rb")
        self._queue: queue.Queue[Optional[bytes]] = queue.Queue()
        self._error: Optional[BaseException] = None
        self._writer = threading.Thread(target=self._write, daemon=True)
        self._writer.start()

    def _write(self) -> None:
        """The writer thread: each queued message in turn (a pipe holds 64 KiB, so a large message
        waits for the helper to read it; this process goes on meanwhile)."""
        while True:
            data = self._queue.get()
            if data is None:
                return
            try:
                write_frame(self._out, data)
            except (OSError, ValueError) as e:
                self._error = e
                return

    def send(self, msg: Any) -> None:
        if self._error is not None:
            raise OSError(f"the helper process stopped reading ({self._error})")
        self._queue.put(pickle.dumps(msg, protocol=pickle.HIGHEST_PROTOCOL))

    def receive(self) -> Tuple[str, Any]:
        reply = pickle.loads(read_frame(self._in))
        if not (isinstance(reply, tuple) and len(reply) == 2 and reply[0] in ("ok", "raised")):
            raise OSError(f"the helper process answered {type(reply).__name__}")
        return reply

    def close(self) -> None:
        self._queue.put(None)
        if self.proc.poll() is None:
            self.proc.kill()  # a writer blocked on a full pipe returns with an error
        for pipe in (self._out, self._in):
            try:
                pipe.close()
            except OSError:
                pass
        self.proc.wait()


def _has_fileno(f: Any) -> bool:
    try:
        f.fileno()
        return True
    except (AttributeError, OSError, ValueError):
        return False


_shared: List[_Helper] = []  # the helper a command started for its whole run (:func:`shared_helper`)
_busy: List[bool] = [False]


@contextmanager
def shared_helper(preload: Sequence[str] = ()) -> Iterator[None]:
    """One helper process for the block (a command's run), started now so that its start-up overlaps
    the work before the first :class:`Split`: it imports the modules named in ``preload`` (those its
    steps live in) at once. Every Split in the block uses it (one at a time) and clears its items
    when done. None on one core."""
    if cores() < 2 or _shared:
        yield
        return
    try:
        h: Optional[_Helper] = _Helper()
        h.send(("import", list(preload)))
    except Exception:  # no helper where none can start (no pipes to pass: not POSIX): the work runs here
        h = None
    if h is not None:
        _shared.append(h)
    try:
        yield
    finally:
        if h is not None:
            if h in _shared:  # a Split that lost it (or left a reply unread) has removed and ended it
                _shared.remove(h)
            h.close()


class Split:
    """Items split between this process and one helper process (module doc); use as a context manager.

    The helper: the block's :func:`shared_helper` where one is running and free; else, with
    ``start``, one of its own (for work long enough to hide its start-up); else none. ``helper``
    True or False forces one (of its own where no shared one is free) or none. One core or fewer
    than two items: every item here."""

    def __init__(self, items: Sequence[Any], helper: Optional[bool] = None, start: bool = False) -> None:
        self.items = list(items)
        self.state: Dict[int, Dict[str, Any]] = {i: {} for i in range(len(self.items))}
        self.history: List[Step] = []
        shared = _shared[0] if _shared and not _busy[0] and helper is not False else None
        use = len(self.items) >= 2 and (helper if helper is not None else cores() >= 2 and (shared is not None or start))
        self.theirs: List[int] = list(range(1, len(self.items), 2)) if use else []
        self._helper: Optional[_Helper] = None
        self._shared = False
        self._pending = 0  # replies not read yet
        if use:
            try:
                self._helper, self._shared = (shared, True) if shared is not None else (_Helper(), False)
                _busy[0] = _busy[0] or self._shared
                self._helper.send(("items", {i: self.items[i] for i in self.theirs}))
            except Exception:  # it cannot start or the items cannot travel: every item here
                self._fallback()

    @property
    def mine(self) -> List[int]:
        """The items this process runs."""
        return [i for i in range(len(self.items)) if i not in self.theirs]

    def __enter__(self) -> Split:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self, drop: bool = False) -> None:
        """End the helper, or clear a shared one's items (their state goes with them). A shared helper
        with a reply not read (the block left between a step's request and its reply) or ``drop`` is
        ended too: the next Split must not read that reply as its own."""
        if self._helper is None:
            return
        h, self._helper = self._helper, None
        if self._shared:
            _busy[0] = False
            if not (drop or self._pending):
                try:
                    h.send(("reset",))
                    return
                except OSError:
                    pass
            if h in _shared:
                _shared.remove(h)
        h.close()

    def _fallback(self, replay: int = 0) -> None:
        """Run the helper's items here from now on, their state rebuilt by replaying the first
        ``replay`` steps."""
        self.close(drop=True)
        theirs, self.theirs = self.theirs, []
        for fn, args in self.history[:replay]:
            for i in theirs:
                fn(self.items[i], self.state[i], *args)

    def step(self, fn: Callable[..., Any], *args: Any, on_item: Callable[[int], None] = lambda i: None) -> List[Any]:
        """``fn(item, state, *args)`` on every item, results in item order. ``fn`` a module-level function
        (it travels by name), ``args`` picklable. ``on_item(i)`` is called here before each item this
        process runs (progress)."""
        return self.step_and_share(fn, args, on_item)[0]

    def step_and_share(self, fn: Callable[..., Any], args: Tuple[Any, ...], on_item: Callable[[int], None] = lambda i: None,
                       then: Optional[Callable[[Dict[int, Any]], Tuple[Callable[..., Any], List[Tuple[Any, ...]]]]] = None
                       ) -> Tuple[List[Any], List[Any]]:
        """:meth:`step`, then jobs shared by both sides: ``then(results of this process's items)`` gives
        ``(job_fn, jobs)``, and ``job_fn(*job)`` runs on every job, every other one in the helper after
        its items (the work this process's items left, e.g. their scores, shared so that the side with
        fewer items takes half of it). Returns (the step's results in item order, the jobs' in order)."""
        self.history.append((fn, args))
        out: Dict[int, Any] = {}
        if self._helper is not None:
            try:
                self._helper.send(("step", fn, args))
                self._pending += 1
            except (OSError, pickle.PicklingError, ValueError, AttributeError):
                self._fallback(len(self.history) - 1)
        for i in self.mine:
            on_item(i)
            out[i] = fn(self.items[i], self.state[i], *args)
        job_fn, jobs = then(dict(out)) if then is not None else (None, [])
        done: Dict[int, Any] = {}
        shared = [k for k in range(len(jobs)) if k % 2 == 1] if self._helper is not None else []
        if shared:
            try:
                self._helper.send(("jobs", job_fn, [jobs[k] for k in shared]))
                self._pending += 1
            except (OSError, pickle.PicklingError, ValueError, AttributeError):
                shared = []  # the step's reply is still read below
        for k in range(len(jobs)):
            if k not in shared:
                done[k] = job_fn(*jobs[k])
        if self._helper is not None:
            theirs = list(self.theirs)
            kind, value = self._reply()
            if kind == "ok":
                out.update(value)
            else:
                self._fallback(len(self.history) - 1)
                for i in theirs:
                    on_item(i)
                    out[i] = fn(self.items[i], self.state[i], *args)
            if shared:
                kind, value = self._reply() if self._helper is not None else ("lost", None)
                if kind == "ok":
                    done.update(zip(shared, value))
                else:
                    self._fallback(len(self.history))
                    done.update({k: job_fn(*jobs[k]) for k in shared})
        return [out[i] for i in range(len(self.items))], [done[k] for k in range(len(jobs))]

    def _reply(self) -> Tuple[str, Any]:
        """The helper's next reply: ("ok", value), or ("lost", None) where it cannot give one; an
        exception it raised is raised here."""
        assert self._helper is not None
        try:
            kind, value = self._helper.receive()
            self._pending -= 1
        except (OSError, EOFError, pickle.UnpicklingError, ValueError, AttributeError, ImportError):
            return "lost", None
        if kind == "raised":
            raise value
        return kind, value


def serve(inp_fd: int, out_fd: int) -> None:
    """The helper's loop, reading frames from ``inp_fd`` and writing replies to ``out_fd``: ("import",
    [module]) imports them; ("items", {i: item}) adds items; ("reset",) drops them; ("step", fn, args)
    runs ``fn`` on each and answers ("ok", {i: result}) or ("raised", the exception); ("jobs", fn,
    [args]) runs ``fn(*args)`` on each and answers ("ok", [result]) or ("raised", ...); end of input
    ends it."""
    inp, out = os.fdopen(inp_fd, "rb"), os.fdopen(out_fd, "wb")
    items: Dict[int, Any] = {}
    state: Dict[int, Dict[str, Any]] = {}
    while True:
        try:
            msg = pickle.loads(read_frame(inp))
        except Exception:  # the end of input, or a message it cannot load (a step's module not importable
            return  # here): it stops, and its items run in the process that sent it
        if msg[0] == "import":
            for name in msg[1]:
                try:
                    importlib.import_module(name)
                except Exception:  # a step that needs it fails to load, and its items run in the sender
                    pass
            continue
        if msg[0] == "reset":
            items.clear()
            state.clear()
            continue
        if msg[0] == "items":
            items.update(msg[1])
            state.update({i: {} for i in msg[1]})
            continue
        _, fn, args = msg
        try:
            if msg[0] == "jobs":
                reply: Tuple[str, Any] = ("ok", [fn(*job) for job in args])
            else:
                reply = ("ok", {i: fn(items[i], state[i], *args) for i in sorted(items)})
            data = pickle.dumps(reply, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as e:  # raised where the item would have run here
            try:
                data = pickle.dumps(("raised", e), protocol=pickle.HIGHEST_PROTOCOL)
            except Exception:
                data = pickle.dumps(("raised", RuntimeError(f"{type(e).__name__}: {e}")))
        try:
            write_frame(out, data)
        except OSError:
            return
