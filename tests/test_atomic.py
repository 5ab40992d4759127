"""imu_learn.util.atomic, the one atomic-write helper: the old file or the new one, never half of one;
errors name the output; outputs get the permissions a plain open() would give."""
import errno
import os
import stat

import pytest

import faults
from imu_learn.util import atomic
from imu_learn.util.atomic import atomic_write_bytes, atomic_write_path, atomic_write_text


def listing(folder):
    return sorted(p.name for p in folder.iterdir())


def test_writes_and_replaces(tmp_path):
    p = tmp_path / "sub" / "x.txt"
    atomic_write_text(p, "één\n")
    assert p.read_text(encoding="utf-8") == "één\n"
    atomic_write_bytes(p, lambda f: f.write(b"new"))
    assert p.read_bytes() == b"new"
    atomic_write_path(p, lambda tmp: tmp.write_bytes(b"by path"))
    assert p.read_bytes() == b"by path"
    assert listing(p.parent) == ["x.txt"]


@pytest.mark.parametrize("exc", [RuntimeError("bug"), KeyboardInterrupt()])
def test_a_failure_midway_leaves_the_old_file_and_no_temporary(tmp_path, exc):
    p = tmp_path / "x.bin"
    p.write_bytes(b"old")

    def half_then_fail(f):
        f.write(b"partial")
        raise exc

    with pytest.raises(type(exc)):
        atomic_write_bytes(p, half_then_fail)
    assert p.read_bytes() == b"old"
    assert listing(tmp_path) == ["x.bin"]


def test_a_full_disk_names_the_output_not_the_temporary(tmp_path):
    p = tmp_path / "x.bin"
    p.write_bytes(b"old")

    def full(f):
        f.write(b"part")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # write() names no file

    with pytest.raises(OSError) as e:
        atomic_write_bytes(p, full)
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(p)
    assert p.read_bytes() == b"old" and listing(tmp_path) == ["x.bin"]


def test_a_message_naming_the_temporary_names_the_output(tmp_path):
    p = tmp_path / "x.csv"

    def rust_style(tmp):  # imu_core's writers raise OSError("<path>: ...") without an errno
        raise OSError(f"{tmp}: No space left on device (os error 28)")

    with pytest.raises(OSError, match=f"^{p}: No space left"):
        atomic_write_path(p, rust_style)
    assert listing(tmp_path) == []


def test_a_folder_that_refuses_new_files_names_the_output(tmp_path, monkeypatch):
    def refuse(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), f"{k['dir']}/.x.csv.abc.tmp")

    monkeypatch.setattr(atomic.tempfile, "mkstemp", refuse)
    with pytest.raises(OSError) as e:
        atomic_write_text(tmp_path / "x.csv", "a\n")
    assert e.value.errno == errno.EROFS and e.value.filename == str(tmp_path / "x.csv")


def test_real_read_only_and_full_file_systems(tmp_path):
    if not faults.can_mount():
        pytest.skip("needs a tmpfs mount (root in a sandbox that allows mount); the tests above simulate both")
    with faults.tmpfs(tmp_path / "fs", "64k") as fs:
        p = fs / "x.bin"
        atomic_write_bytes(p, lambda f: f.write(b"old" * 1000))
        with pytest.raises(OSError) as e:
            atomic_write_bytes(p, lambda f: f.write(b"\0" * 200_000))  # more than the 64k there are
        assert e.value.errno == errno.ENOSPC and e.value.filename == str(p)
        assert p.read_bytes() == b"old" * 1000 and listing(fs) == ["x.bin"]
        faults.remount(fs, "ro")
        with pytest.raises(OSError) as e:
            atomic_write_text(p, "new")
        assert e.value.errno == errno.EROFS and e.value.filename == str(p)
        assert p.read_bytes() == b"old" * 1000
        faults.remount(fs, "rw")


def test_permissions_are_what_open_would_give(tmp_path):
    mask = os.umask(0o027)
    try:
        atomic._umask.cache_clear()
        new = tmp_path / "new.txt"
        atomic_write_text(new, "x")
        assert stat.S_IMODE(new.stat().st_mode) == 0o640  # 0o666 less the umask, not mkstemp's 0o600
        kept = tmp_path / "kept.txt"
        kept.write_text("x")
        kept.chmod(0o604)
        atomic_write_text(kept, "y")
        assert stat.S_IMODE(kept.stat().st_mode) == 0o604  # a replaced file keeps its mode
    finally:
        os.umask(mask)
        atomic._umask.cache_clear()


def test_an_error_names_the_output_not_its_temporary():
    """One rule for atomic files and staged folders: an error's file names are the output's."""
    from pathlib import Path

    from imu_learn.util.atomic import named

    out, stage = Path("/o/run"), Path("/o/.run.x1.tmp")
    assert named(OSError(28, "No space left on device"), Path("/o/x.csv")).filename == "/o/x.csv"
    assert named(PermissionError(13, "Permission denied", "/o/.x.csv.ab.tmp"), Path("/o/x.csv")).filename == "/o/x.csv"
    e = named(FileNotFoundError(2, "No such file", str(stage / "tracks" / "a.tum")), out, stage)
    assert isinstance(e, FileNotFoundError) and e.filename == "/o/run/tracks/a.tum"
    e = named(OSError(18, "Invalid cross-device link", str(stage), None, "/elsewhere/run"), out, stage)
    assert (e.filename, e.filename2) == ("/o/run", "/elsewhere/run")
    assert str(named(OSError(f"cannot write {stage}/a.bag"), out, stage)) == "cannot write /o/run/a.bag"
