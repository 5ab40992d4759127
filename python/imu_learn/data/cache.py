"""The label cache: aligned sequences plus their label tables, on disk.

Layout (format version ``CACHE_VERSION``), one folder per dataset::

    <cache>/manifest.json          settings, source fingerprints, alignment reports, file list with
                                   the sha256 of every segment file, and its own sha256; per
                                   recording, ``source`` (format, ground-truth file, alignment
                                   options, topics) and ``source_fingerprint`` (those plus the size
                                   and mtime of every source file), which ``fit`` checks
    <cache>/manifest.partial.json  the same for the recordings an unfinished run has done
    <cache>/<rec>__<i>.<sha>.npz   t_ns, gyro, acc, p, v, q_wxyz         (N, ...)
                                   starts (W,), horizons (H,),
                                   dq_wxyz (W, H, 4), dv/dp (W, H, 3), dt (W, H)
    <cache>/.lock                  held (flock) by the ``labels`` run writing the folder

Quaternions are w,x,y,z. The aligned ground-truth states (p, v, q at every IMU stamp) are the
cumulative form of the labels: the increment from any sample k to any later j is a function of
the states at k and j alone (``labels::increment``), which is how training's batch sampler labels
windows at random starts from the cached sequences; the per-window tables serve fixed-stride users. Every file is written through :mod:`imu_learn.util.atomic`, so an interrupted
run leaves only complete files. Segment files are named by their content and the manifest is
replaced only when a run has finished, so until then readers see the previous complete cache; an
unfinished run's progress goes to ``manifest.partial.json``, which the next run resumes from.
Loading checks every segment file against the sha256 the manifest recorded, so a truncated or
modified file is refused with a :class:`CacheError` naming it rather than read as good labels;
``imu-learn labels`` rebuilds such a recording (saying so). A re-run skips recordings
whose cached files match their source fingerprint, settings and digests, rebuilds stale ones, and
refuses a cache written by another format version unless told to rebuild. Two ``labels`` runs on
one folder take turns (the second waits for the lock, saying so).
"""
from __future__ import annotations

import contextlib
import fcntl
import functools
import hashlib
import inspect
import io
import json
import logging
import re
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Optional, Tuple, TypeVar

import numpy as np

from imu_learn.data.types import Segment
from imu_learn.errors import CacheError
from imu_learn.util.atomic import atomic_write_bytes
from imu_learn.util.digest import file_sha256

logger = logging.getLogger(__name__)

# 2: the manifest records each segment file's sha256 and its own.
# 3: each recording records its ``source`` and ``source_fingerprint`` (what ``fit`` checks).
CACHE_VERSION = 3
MANIFEST = "manifest.json"
PROGRESS = "manifest.partial.json"  # an unfinished run's manifest, for resuming
SEGMENT_FILE = re.compile(r".+__\d+(\.[0-9a-f]{16})?\.npz")  # what write_segment names (older: no digest)
LOCK = ".lock"
DIGEST_KEY = "manifest_sha256"
SEQUENCE_KEYS = ("t_ns", "gyro", "acc", "p", "v", "q_wxyz")
LABEL_KEYS = ("starts", "horizons", "dq_wxyz", "dv", "dp", "dt")

F = TypeVar("F", bound=Callable[..., Any])


def fingerprint(paths: List[Path], settings: Dict[str, Any]) -> str:
    """Changes when a source file's size or mtime changes, or any setting does."""
    h = hashlib.sha256(json.dumps(settings, sort_keys=True).encode())
    for p in sorted(paths):
        st = p.stat()
        h.update(f"{p.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
    return h.hexdigest()[:32]


def rebuild_hint(folder: Path, manifest: Optional[Dict[str, Any]] = None) -> str:
    dataset = ((manifest or {}).get("settings") or {}).get("dataset") or "<dataset>"
    return f"rebuild it with `imu-learn labels {dataset} --out {folder}`"


# ---------------------------------------------------------------------------------------------
# segment files


def write_segment(folder: Path, stem: str, seq: Segment, labels: Dict[str, np.ndarray]) -> Dict[str, str]:
    """Write one segment's arrays to ``<folder>/<stem>.<sha256 prefix>.npz``; returns the manifest's
    ``file`` and ``sha256`` for it. The name changes with the content, so a rebuild never
    overwrites a file the current manifest still lists: until the new manifest replaces it, the
    previous cache stays whole."""
    arrays = {k: getattr(seq, k) for k in SEQUENCE_KEYS}
    arrays.update({f"label_{k}": np.asarray(labels[k]) for k in LABEL_KEYS})
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    data = buf.getvalue()
    sha256 = hashlib.sha256(data).hexdigest()
    name = f"{stem}.{sha256[:16]}.npz"
    atomic_write_bytes(folder / name, lambda f: f.write(data))
    return {"file": name, "sha256": sha256}


def segment_problem(folder: Path, seg: Dict[str, Any]) -> Optional[str]:
    """Why the segment file of manifest entry ``seg`` cannot be trusted, or None when it can."""
    path = folder / seg["file"]
    if not path.is_file():
        return f"{path}: missing"
    if seg.get("sha256") != file_sha256(path):
        return f"{path}: truncated or modified (its sha256 is not the one the manifest recorded)"
    return None


def read_segment(folder: Path, seg: Dict[str, Any], manifest: Optional[Dict[str, Any]] = None,
                 with_labels: bool = True) -> tuple:
    """(Segment, labels) of manifest entry ``seg``, after checking the file against its sha256;
    labels is None when not ``with_labels`` (their arrays are then not read)."""
    path = folder / seg["file"]
    problem = segment_problem(folder, seg)
    if problem is not None:
        raise CacheError(f"{problem}; {rebuild_hint(folder, manifest)}")
    try:
        with np.load(path) as z:
            seq = Segment(name=seg["name"], **{k: z[k] for k in SEQUENCE_KEYS})
            labels = {k: z[f"label_{k}"] for k in LABEL_KEYS} if with_labels else None
    except (OSError, KeyError, ValueError) as e:
        raise CacheError(f"{path}: unreadable cache file ({e}); {rebuild_hint(folder, manifest)}") from e
    return seq, labels


def recording_problem(folder: Path, rec: Dict[str, Any]) -> Optional[str]:
    """The first segment of manifest recording ``rec`` whose file cannot be trusted, or None."""
    for seg in rec["segments"]:
        problem = segment_problem(folder, seg)
        if problem is not None:
            return problem
    return None


# ---------------------------------------------------------------------------------------------
# the manifest


def manifest_digest(manifest: Dict[str, Any]) -> str:
    body = {k: v for k, v in manifest.items() if k != DIGEST_KEY}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def _manifest_and_problem(path: Path) -> Tuple[Optional[Dict[str, Any]], Optional[str]]:
    """The manifest at ``path`` and why it cannot be trusted (None when it can); a manifest of
    another format version is a CacheError (rebuilding it is the user's call: ``--rebuild``)."""
    try:
        manifest = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        return None, f"{path}: unreadable manifest ({e})"
    if not isinstance(manifest, dict):
        return None, f"{path}: not a label cache manifest"
    if manifest.get("cache_version") != CACHE_VERSION:
        raise CacheError(
            f"{path}: cache format version {manifest.get('cache_version')!r}, this imu_learn reads "
            f"version {CACHE_VERSION}; rebuild with --rebuild"
        )
    if manifest.get(DIGEST_KEY) != manifest_digest(manifest):
        return manifest, f"{path}: modified after it was written (its sha256 does not match)"
    return manifest, None


def read_manifest(folder: Path) -> Dict[str, Any]:
    path = folder / MANIFEST
    if not path.exists():
        raise CacheError(f"{folder}: no label cache here (no {MANIFEST}); build it with `just labels <dataset>`")
    manifest, problem = _manifest_and_problem(path)
    if problem is not None or manifest is None:
        raise CacheError(f"{problem}; {rebuild_hint(folder, manifest)}")
    return manifest


def current_manifest(folder: Path) -> Tuple[Optional[Dict[str, Any]], Optional[str]]:
    """The complete manifest of ``folder`` (None when there is none yet) and why it cannot be
    trusted (None when it can); another format version is a CacheError."""
    path = Path(folder) / MANIFEST
    if not path.exists():
        return None, None
    return _manifest_and_problem(path)


def reusable_recordings(folder: Path, rebuild: bool, log: Callable[[str], None]) -> Dict[str, Dict[str, Any]]:
    """The entries of the manifest (and of an interrupted run's progress file, which is newer)
    in ``folder`` that a ``labels`` run may keep, by recording name: none with ``rebuild``; a
    damaged manifest is said through ``log`` and contributes none (its recordings are rebuilt)."""
    out: Dict[str, Dict[str, Any]] = {}
    for path in (folder / MANIFEST, folder / PROGRESS):
        if rebuild or not path.exists():
            continue
        manifest, problem = _manifest_and_problem(path)
        if problem is not None or manifest is None:
            log(f"{problem}; rebuilding what it lists")
            continue
        out.update({r["name"]: r for r in manifest["recordings"]})
    return out


def recording_reusable(folder: Path, rec: Dict[str, Any], log: Callable[[str], None]) -> bool:
    """Whether every segment file of manifest entry ``rec`` is there and unchanged; if not, the
    reason goes to ``log`` (the recording is rebuilt)."""
    problem = recording_problem(folder, rec)
    if problem is not None:
        log(f"{problem}; rebuilding {rec['name']}")
    return problem is None


def write_progress(folder: Path, manifest: Dict[str, Any]) -> None:
    """The recordings finished so far, beside (not over) the previous manifest: an interrupted run
    resumes from it while readers still see the previous complete cache."""
    _write_signed(folder / PROGRESS, manifest)


def write_manifest(folder: Path, manifest: Dict[str, Any]) -> None:
    """Commit a finished build: the manifest replaces the previous one, then the progress file and
    the segment files no manifest lists any more are removed."""
    _write_signed(folder / MANIFEST, manifest)
    (folder / PROGRESS).unlink(missing_ok=True)
    remove_unlisted_segments(folder, manifest)


def _write_signed(path: Path, manifest: Dict[str, Any]) -> None:
    signed = {**manifest, DIGEST_KEY: manifest_digest(manifest)}
    data = json.dumps(signed, indent=2, sort_keys=True).encode()
    atomic_write_bytes(path, lambda f: f.write(data))


def remove_unlisted_segments(folder: Path, manifest: Dict[str, Any]) -> None:
    listed = {seg["file"] for rec in manifest["recordings"] for seg in rec["segments"]}
    for path in folder.glob("*.npz"):
        if SEGMENT_FILE.fullmatch(path.name) and path.name not in listed:
            path.unlink(missing_ok=True)


def load_cache(folder: Path) -> List[tuple]:
    """All (Segment, labels) pairs of a cache, in manifest order; a truncated or modified file is
    a CacheError naming it."""
    folder = Path(folder)
    manifest = read_manifest(folder)
    out = []
    for rec in manifest["recordings"]:
        for seg in rec["segments"]:
            out.append(read_segment(folder, seg, manifest))
    return out


# ---------------------------------------------------------------------------------------------
# one writer at a time


@contextlib.contextmanager
def cache_lock(folder: Path, log: Optional[Callable[[str], None]] = None) -> Iterator[None]:
    """Hold the exclusive lock of cache ``folder`` (created if needed) for the block; when another
    process holds it, say so through ``log`` and wait for it. The kernel drops the lock when its
    holder exits, however it exits, so a killed run never leaves the folder locked."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / LOCK, "a+b") as f:  # "a": never truncates, so the lock file is no output
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            # a warning: said even with --quiet, a run that waits must say why
            (log or logger.warning)(f"{folder} is being written by another run; waiting for it to finish")
            fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)


def holding_cache_lock(folder_arg: str) -> Callable[[F], F]:
    """Decorator: run the function holding :func:`cache_lock` on its argument ``folder_arg``."""

    def wrap(build: F) -> F:
        signature = inspect.signature(build)

        @functools.wraps(build)
        def locked(*args: Any, **kwargs: Any) -> Any:
            folder = signature.bind(*args, **kwargs).arguments[folder_arg]
            with cache_lock(Path(folder)):
                return build(*args, **kwargs)

        return locked  # type: ignore[return-value]

    return wrap
