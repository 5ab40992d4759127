"""The one atomic-write helper every output of imu_learn goes through.

An output is written to a temporary file beside its final path (same folder, so the rename never
crosses a file system), flushed and fsynced, then renamed over the final path with ``os.replace``.
A reader therefore sees either the previous complete file or the new complete file, never a half
written one: an exception, a signal that ends the process, or a full disk while writing leaves the
final path untouched and removes the temporary file (a ``SIGKILL`` can leave a ``.<name>.*.tmp``
beside it, which no reader ever opens).
"""
from __future__ import annotations

import functools
import os
import shutil
import stat
import tempfile
from pathlib import Path
from typing import BinaryIO, Callable, Optional, Union

PathLike = Union[str, "os.PathLike[str]"]


@functools.lru_cache(maxsize=1)
def _umask() -> int:
    # Read once: setting the umask to learn it is process-wide, so it is not done on every write.
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _output_mode(path: Path) -> int:
    """The permissions ``open(path, "w")`` would give: the old file's, else 0o666 less the umask
    (mkstemp's own 0o600 would make every output private to its writer)."""
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except OSError:
        return 0o666 & ~_umask()


def temp_beside(path: Path) -> Path:
    """A new, empty temporary file in ``path``'s folder (created, so the name is ours)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as e:  # a read-only or full folder: name the output, not a random temp name
        raise named(e, path) from None
    try:
        os.fchmod(fd, _output_mode(path))
    finally:
        os.close(fd)
    return Path(tmp)


def named(e: OSError, final: Path, tmp: Optional[Path] = None) -> OSError:
    """``e`` again, naming the output ``final`` instead of a temporary, so a one-line report says which
    output failed, not a temporary that is gone: without ``tmp`` (a temporary with a random name, or
    none: a write to a full disk raises without a file name) ``final`` alone; with ``tmp`` (a file, or
    a staging folder) every name under it moved under ``final`` (a file inside the staging folder named
    inside the output folder). The one rule for atomic files and staged folders."""
    def final_name(name: object) -> object:
        text = "" if name is None else str(name)
        if tmp is None or name is None:
            return str(final)
        return str(final) + text[len(str(tmp)):] if text.startswith(str(tmp)) else name

    if e.errno is None:  # e.g. imu_core's writers: the temporary's name is in the message
        message = str(e).replace(str(tmp), str(final)) if tmp is not None else str(e)
        return type(e)(message) if message != str(e) else e
    if e.filename2 is not None and tmp is not None:
        return type(e)(e.errno, e.strerror, final_name(e.filename), None, final_name(e.filename2))
    return type(e)(e.errno, e.strerror, final_name(e.filename))


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    # The rename is durable only once the folder's entry is on disk; not every OS lets us open a
    # folder for this (Windows), which costs durability, never correctness.
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_path(path: PathLike, fill: Callable[[Path], None]) -> None:
    """Let ``fill(tmp)`` write the whole output to ``tmp`` (by path: for writers such as h5py,
    scipy.io or torch.onnx that want a file name), then move it over ``path`` atomically."""
    path = Path(path)
    tmp = temp_beside(path)
    try:
        fill(tmp)
        _fsync_file(tmp)
        os.replace(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(e, OSError) and (e.filename is None or str(e.filename) == str(tmp)):
            raise named(e, path, tmp) from e
        raise
    _fsync_dir(path.parent)


def atomic_write_bytes(path: PathLike, write: Callable[[BinaryIO], object]) -> None:
    """Write through ``write(fileobj)`` (a binary file object) and move the result over ``path``."""

    def fill(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            write(f)

    atomic_write_path(path, fill)


def atomic_write_text(path: PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    data = text.encode("utf-8")
    atomic_write_bytes(path, lambda f: f.write(data))


def _fsync_tree(folder: Path) -> None:
    for dirpath, _dirs, files in os.walk(folder):
        for name in files:
            _fsync_file(Path(dirpath) / name)
        _fsync_dir(Path(dirpath))


def atomic_write_dir(path: PathLike, fill: Callable[[Path], None], replace: bool = False) -> None:
    """Let ``fill(tmp)`` create the folder ``tmp`` (it does not exist yet; its name is ``path``'s,
    inside a temporary folder beside ``path``) with the whole output, then rename it to ``path``.
    For outputs that are folders (a ROS 2 bag). A folder cannot replace another in one step, so an
    existing ``path`` is refused (``FileExistsError``) unless ``replace``: then the old folder is
    renamed aside first, removed once the new one is in place, and put back if writing fails. A
    reader sees the old folder, the new one or (between two renames) none, never a partial one."""
    path = Path(path)
    if path.exists() or path.is_symlink():
        if replace:
            _replace_dir(path, fill)
            return
        raise FileExistsError(17, "exists already (a folder output is never replaced; remove it first)", str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        holder = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    except OSError as e:
        raise named(e, path) from None
    try:
        tmp = holder / path.name  # the name a writer may embed in its files (rosbags names storage after it)
        fill(tmp)
        os.chmod(tmp, 0o777 & ~_umask())
        _fsync_tree(tmp)
        os.rename(tmp, path)  # fails rather than merging if path appeared meanwhile
    except BaseException as e:
        shutil.rmtree(holder, ignore_errors=True)
        if isinstance(e, OSError) and (e.filename is None or str(e.filename).startswith(str(holder))):
            raise named(e, path) from e
        raise
    os.rmdir(holder)
    _fsync_dir(path.parent)


def _replace_dir(path: Path, fill: Callable[[Path], None]) -> None:
    holder = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
    aside = holder / path.name
    os.rename(path, aside)
    try:
        atomic_write_dir(path, fill)
    except BaseException:
        os.rename(aside, path)
        os.rmdir(holder)
        raise
    shutil.rmtree(holder)
