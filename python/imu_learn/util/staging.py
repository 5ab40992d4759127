"""A command's output folder written whole or not at all (:func:`staged_dir`).

Every file of a run is written into a staging folder beside the output folder ``OUT`` (same file
system: ``.OUT.<random>.staging``), and only once all are there is the staging folder put in
``OUT``'s place, with Ctrl-C held for those few renames (:func:`imu_learn.util.interrupts.held_interrupts`).
An error or a Ctrl-C before that removes the staging folder and leaves ``OUT`` as it was; after it,
``OUT`` holds this run's complete set of files. Never a mix of this run's files and the previous
run's.

How the staging folder goes in:

* ``OUT`` absent: renamed to ``OUT`` (one step).
* ``OUT`` holding only the command's own outputs (``owned``, e.g. a previous run's): the old folder
  is renamed aside, the staging folder renamed to ``OUT``, the old one removed (a process killed
  between the two renames leaves the old folder in ``.OUT.<random>.old/``).
* ``OUT`` also holding other files (``--out .``, a folder of the user's), or a mount point, or the
  working folder: those are kept; the previous run's outputs are moved aside and this run's moved
  in, entry by entry, with Ctrl-C held (a process killed in between can leave a mix).
"""
from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Collection, Iterator, Optional, Union

from .atomic import _fsync_dir, _umask, named
from .interrupts import held_interrupts

PathLike = Union[str, "os.PathLike[str]"]


def _target(out: Path) -> Path:
    """The folder ``out`` names, absolute (a symbolic link: the folder it points to, which is replaced)."""
    return out.resolve() if out.is_symlink() else Path(os.path.abspath(out))


def _own_file_system(target: Path) -> bool:
    """``target`` is a folder on another file system than its parent (a mount point): files cannot be
    renamed into it from beside it."""
    try:
        return target.is_dir() and (os.path.ismount(target) or target.stat().st_dev != target.parent.stat().st_dev)
    except OSError:
        return False


def _stage_beside(target: Path) -> Path:
    """A new, empty staging folder beside ``target`` (inside it when its parent is not writable or is on
    another file system)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    if _own_file_system(target):
        return Path(tempfile.mkdtemp(prefix=".", suffix=".staging", dir=target))
    try:
        return Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".staging", dir=target.parent))
    except PermissionError:
        if not target.is_dir():
            raise
        return Path(tempfile.mkdtemp(prefix=".", suffix=".staging", dir=target))


def _swappable(target: Path, stage: Path) -> bool:
    """Whether ``target`` as a whole may be renamed away: a plain folder beside ``stage``, not a
    mount point, not the working folder or one above it."""
    if stage.parent != target.parent or os.path.ismount(target):
        return False
    cwd, real = Path.cwd().resolve(), target.resolve()
    return cwd != real and real not in cwd.parents


def _swap(stage: Path, target: Path) -> None:
    holder = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old", dir=target.parent))
    try:
        os.rename(target, holder / target.name)
    except BaseException:  # a folder that cannot move (read-only): nothing aside, no holder left behind
        os.rmdir(holder)
        raise
    try:
        os.rename(stage, target)
    except BaseException:
        os.rename(holder / target.name, target)
        os.rmdir(holder)
        raise
    shutil.rmtree(holder, ignore_errors=True)


def _move_entries(stage: Path, target: Path, owned: Collection[str]) -> None:
    """The previous run's entries of ``target`` (``owned`` and this run's names) aside, this run's in;
    undone on an error."""
    names = sorted(os.listdir(stage))
    old = sorted((set(owned) | set(names)) & set(os.listdir(target)))
    holder = Path(tempfile.mkdtemp(prefix=".", suffix=".old", dir=target))
    aside, moved = [], []
    try:
        for name in old:
            os.rename(target / name, holder / name)
            aside.append(name)
        for name in names:
            os.rename(stage / name, target / name)
            moved.append(name)
    except BaseException:
        for name in moved:
            os.rename(target / name, stage / name)
        for name in aside:
            os.rename(holder / name, target / name)
        os.rmdir(holder)
        raise
    shutil.rmtree(holder, ignore_errors=True)
    os.rmdir(stage)


def _remove(stage: Path) -> None:
    """The staging folder gone (writable first: :func:`commit` gives it the output folder's mode)."""
    try:
        os.chmod(stage, 0o700)
    except OSError:
        pass
    shutil.rmtree(stage, ignore_errors=True)


def check_writable(out: PathLike) -> None:
    """Before any work: ``out`` is a folder that can be written (it, or where it would be created), else
    the error a staged write would end in, named now (a calibration or a fusion of minutes did its work
    first, then failed, leaving its temporary folders behind)."""
    target = _target(Path(out))
    if os.path.lexists(target) and not target.is_dir():
        raise NotADirectoryError(20, "exists and is not a folder (give --out a folder)", str(out))
    check_can_make(target, str(out), "give --out a folder you can write")


def check_can_make(path: Path, named: str, fix: str) -> None:
    """Before any work: ``path`` (a folder or a file) can be made, in it or in its nearest existing folder, else
    the PermissionError naming ``named`` and the ``fix``."""
    where = path if path.is_dir() else next((p for p in path.parents if p.is_dir()), None)
    if where is None or not os.access(where, os.W_OK | os.X_OK) or not can_create_in(where):
        raise PermissionError(13, f"cannot be written ({where} is not writable): {fix}", named)


def can_create_in(folder: Path) -> bool:
    """Whether a folder can be made in ``folder`` (and removed): what os.access cannot tell for root, a
    read-only file system or a kernel's (/proc)."""
    try:
        probe = tempfile.mkdtemp(prefix=".imu_learn_probe.", dir=folder)
    except OSError:
        return False
    try:
        os.rmdir(probe)
    except OSError:
        pass
    return True


def commit(stage: Path, out: Path, owned: Collection[str] = ()) -> None:
    """Put the staging folder ``stage`` in ``out``'s place (module docstring); ``owned``: the names
    of ``out``'s entries that a previous run wrote (replaced or removed; any other entry is kept)."""
    target = _target(out)
    if not os.path.lexists(target):
        os.rename(stage, target)
    elif not target.is_dir():
        raise NotADirectoryError(20, "exists and is not a folder (give --out a folder)", str(out))
    else:
        os.chmod(stage, target.stat().st_mode & 0o7777)
        if _swappable(target, stage) and set(os.listdir(target)) <= set(owned):
            _swap(stage, target)
        else:
            _move_entries(stage, target, owned)
    _fsync_dir(target.parent)


@contextmanager
def staged_dir(out: PathLike, owned: Collection[str] = (),
               on_commit: Optional[Callable[[], None]] = None) -> Iterator[Path]:
    """``with staged_dir(out, owned) as stage:`` write every output into ``stage``; at the block's
    end the folder ``out`` becomes exactly those outputs (plus any entry of ``out`` not ``owned``),
    all at once, and ``on_commit()`` is called (Ctrl-C held until it returns: one that came during
    the swap is raised after it). An exception or a Ctrl-C in the block removes ``stage`` and leaves
    ``out`` untouched."""
    out = Path(out)
    target = _target(out)
    if os.path.lexists(target) and not target.is_dir():
        raise NotADirectoryError(20, "exists and is not a folder (give --out a folder)", str(out))
    stage = _stage_beside(target)
    os.chmod(stage, 0o777 & ~_umask())
    try:
        yield stage
        with held_interrupts():
            commit(stage, out, owned)
            if on_commit is not None:
                on_commit()
    except OSError as e:
        _remove(stage)
        raise named(e, target, stage) from None
    except BaseException:
        _remove(stage)
        raise
