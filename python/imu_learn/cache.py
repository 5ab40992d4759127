"""The label cache: aligned sequences plus their label tables, on disk.

Layout (format version ``CACHE_VERSION``), one folder per dataset::

    <cache>/manifest.json          settings, source fingerprints, alignment reports, file list
    <cache>/<segment>.npz          t_ns, gyro, acc, p, v, q_wxyz         (N, ...)
                                   starts (W,), horizons (H,),
                                   dq_wxyz (W, H, 4), dv/dp (W, H, 3), dt (W, H)

Quaternions are w,x,y,z. Every file is written to a temporary name and renamed into place, so an
interrupted run leaves only complete files; the manifest is written last. A re-run skips
recordings whose cached files match their source fingerprint and settings (so an interrupted run
resumes), rebuilds stale ones, and refuses a cache written by another format version unless told
to rebuild.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any, Dict, List

import numpy as np

from imu_learn.errors import CacheError
from imu_learn.types import Sequence

CACHE_VERSION = 1
MANIFEST = "manifest.json"
SEQUENCE_KEYS = ("t_ns", "gyro", "acc", "p", "v", "q_wxyz")
LABEL_KEYS = ("starts", "horizons", "dq_wxyz", "dv", "dp", "dt")


def fingerprint(paths: List[Path], settings: Dict[str, Any]) -> str:
    """Changes when a source file's size or mtime changes, or any setting does."""
    h = hashlib.sha256(json.dumps(settings, sort_keys=True).encode())
    for p in sorted(paths):
        st = p.stat()
        h.update(f"{p.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
    return h.hexdigest()[:32]


def atomic_write_bytes(path: Path, write) -> None:
    """Write through ``write(fileobj)`` to a temp file beside ``path``, then rename over it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def write_segment(path: Path, seq: Sequence, labels: Dict[str, np.ndarray]) -> None:
    arrays = {k: getattr(seq, k) for k in SEQUENCE_KEYS}
    arrays.update({f"label_{k}": np.asarray(labels[k]) for k in LABEL_KEYS})
    atomic_write_bytes(path, lambda f: np.savez(f, **arrays))


def read_segment(path: Path, name: str) -> tuple:
    try:
        with np.load(path) as z:
            seq = Sequence(name=name, **{k: z[k] for k in SEQUENCE_KEYS})
            labels = {k: z[f"label_{k}"] for k in LABEL_KEYS}
    except (OSError, KeyError, ValueError) as e:
        raise CacheError(f"{path}: unreadable cache file ({e}); rebuild with --rebuild") from e
    return seq, labels


def read_manifest(folder: Path) -> Dict[str, Any]:
    path = folder / MANIFEST
    if not path.exists():
        raise CacheError(f"{folder}: no label cache here (no {MANIFEST}); build it with `just labels <dataset>`")
    try:
        manifest = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise CacheError(f"{path}: unreadable manifest ({e}); rebuild with --rebuild") from e
    if manifest.get("cache_version") != CACHE_VERSION:
        raise CacheError(
            f"{path}: cache format version {manifest.get('cache_version')!r}, this imu_learn reads "
            f"version {CACHE_VERSION}; rebuild with --rebuild"
        )
    return manifest


def write_manifest(folder: Path, manifest: Dict[str, Any]) -> None:
    data = json.dumps(manifest, indent=2, sort_keys=True).encode()
    atomic_write_bytes(folder / MANIFEST, lambda f: f.write(data))


def load_cache(folder: Path) -> List[tuple]:
    """All (Sequence, labels) pairs of a cache, in manifest order."""
    folder = Path(folder)
    manifest = read_manifest(folder)
    out = []
    for rec in manifest["recordings"]:
        for seg in rec["segments"]:
            out.append(read_segment(folder / seg["file"], seg["name"]))
    return out
