"""Outputs under failure: refine, labels, fit, evaluate and fuse, interrupted by a failing
writer (ENOSPC midway through a file), a signal, a full or a read-only file system, leave every
output either as it was or complete; damaged label caches and checkpoints are refused or rebuilt;
two labels runs on one cache take turns.

How each failure is made (see tests/faults.py): a failing writer is a monkeypatch, always; a
signal is sent to a real process stopped midway through writing an output; a full disk and a
read-only folder are a real tmpfs when this process may mount one (root in a sandbox that allows
it), else the read-only folder is ``chmod 0o555`` (not root) or a monkeypatched EROFS (root without
mount) and the full-disk case is left to the failing writer. Each such test prints the way it took.
"""
import contextlib
import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

import faults
from imu_learn import _imu_core as core
from imu_learn.baselines.base import Raw
from imu_learn.cli import labels as labels_cli
from imu_learn.cli import main as cli_main
from imu_learn.data import cache
from imu_learn.errors import CacheError
from imu_learn.infer.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from imu_learn.nn.model import ImuRefiner, ModelConfig

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
TESTS = Path(__file__).resolve().parent
CROP = REPO / "datasets" / "euroc" / "V1_01_easy"
IMU_REL = Path("mav0") / "imu0" / "data.csv"
ENV = dict(os.environ, OMP_NUM_THREADS="1", RAYON_NUM_THREADS="1", MKL_NUM_THREADS="1")
MOUNT = faults.can_mount()
PNG_END = b"IEND\xaeB`\x82"


# ---------------------------------------------------------------------------------------------
# checks shared by every command


def files(folder: Path) -> dict:
    """Every file under ``folder`` (relative name -> bytes), the labels lock file aside."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != cache.LOCK}


def temporaries(folder: Path) -> list:
    return [str(p.relative_to(folder)) for p in folder.rglob(".*.tmp")]


def assert_complete(path: Path) -> None:
    """``path`` parses as the kind of file its name says, to its end."""
    data, name = path.read_bytes(), path.name
    if name.endswith(".json"):
        json.loads(data)
    elif name.endswith(".png"):
        assert data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(PNG_END), name
    elif name.endswith(".pt") and name != "saver.pt":
        load_checkpoint(path)
    elif name.endswith(".pt"):
        torch.load(path, weights_only=True)
    elif name.endswith(".npz"):
        with np.load(path) as z:
            [z[k] for k in z.files]
    elif name.endswith(".tum"):
        assert len(core.read_tum(str(path))["t_ns"]) > 0
    elif name == "data.csv":
        assert len(core.read_asl_imu(str(path))[0]) > 0
    elif ".tfevents." in name:  # fit's TensorBoard log, appended record by record: whole records only
        assert_whole_records(data, name)
    else:  # csv, md, toml: every one of ours ends with a newline; a cut one almost never does
        assert data == b"" or data.endswith(b"\n"), name


def assert_whole_records(data: bytes, name: str) -> None:
    """TFRecord framing (u64 length, u32 crc, data, u32 crc) that ends exactly at the file's end."""
    at = 0
    while at < len(data):
        assert at + 12 <= len(data), name
        at += 12 + int.from_bytes(data[at:at + 8], "little") + 4
    assert at == len(data), name


def assert_intact(before: dict, folder: Path, untouched: str = "") -> None:
    """Every earlier file is still there, each file is the earlier one or a complete new one,
    ``untouched`` (the output being written when it failed) is byte-identical, and no temporary
    file is left for a reader to pick up."""
    now = files(folder)
    assert set(before) <= set(now), sorted(set(before) - set(now))
    for name, data in now.items():
        if before.get(name) != data:
            assert_complete(folder / name)
    if untouched:
        assert now[untouched] == before[untouched], f"{untouched} changed"
    assert temporaries(folder) == []


def assert_only_hidden_temporaries(folder: Path) -> None:
    """After a SIGKILL/SIGTERM (no clean-up runs) only ``.<name>.*.tmp`` files may be left over:
    no reader opens those."""
    for p in folder.rglob("*"):
        if p.is_file() and p.suffix == ".tmp":
            assert p.name.startswith("."), p


def one_error_line(err: str, *must: str) -> str:
    """The error is one line, the last (progress lines before it are fine), with no traceback."""
    lines = [x for x in err.strip().splitlines() if x.strip()]
    errors = [x for x in lines if "error:" in x]
    assert len(errors) == 1 and lines[-1] == errors[0] and "Traceback" not in err, err
    for m in must:
        assert m in errors[0], (m, errors[0])
    return errors[0]


def faulty_cli(pattern: str, nth: int, action: str, marker: Path, module: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(TESTS / "faults.py"), pattern, str(nth), action, str(marker), "--",
                             module, *map(str, args)], cwd=REPO, env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def signal_midway(proc: subprocess.Popen, marker: Path, sig: int, timeout: float = 120) -> str:
    """Wait until ``proc`` stopped midway through its output (``marker`` written), send ``sig``;
    returns its stderr."""
    deadline = time.time() + timeout
    try:
        while not marker.exists():
            assert proc.poll() is None, proc.communicate()[1]
            assert time.time() < deadline, "the fault never fired"
            time.sleep(0.05)
        proc.send_signal(sig)
        return proc.communicate(timeout=60)[1]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


@pytest.fixture()
def out_dir(tmp_path):
    """The output folder: a tmpfs of its own when we may mount one (so it can be filled or made
    read-only for real), else a plain folder."""
    folder = tmp_path / "out"
    if MOUNT:
        with faults.tmpfs(folder):
            yield folder
    else:
        folder.mkdir()
        yield folder


@contextlib.contextmanager
def read_only(folder: Path, monkeypatch):
    """``folder`` read-only for the block, by the strongest means this process has."""
    if MOUNT:
        faults.remount(folder, "ro")
        print("read-only: tmpfs remounted ro")
        try:
            yield
        finally:
            faults.remount(folder, "rw")
    elif os.geteuid() != 0:
        dirs = [folder, *(p for p in folder.rglob("*") if p.is_dir())]
        for d in dirs:
            d.chmod(0o555)
        print("read-only: chmod 0o555 (not root)")
        try:
            yield
        finally:
            for d in dirs:
                d.chmod(0o755)
    else:  # root without mount: chmod does not stop root, so the file system's answer is simulated
        import imu_learn.util.atomic

        def refuse(*a, **k):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(k.get("dir", "?")) + "/.x.tmp")

        monkeypatch.setattr(imu_learn.util.atomic.tempfile, "mkstemp", refuse)
        print("read-only: monkeypatched EROFS (root, mount not allowed)")
        yield
        monkeypatch.undo()


def needs_mount():
    if not MOUNT:
        pytest.skip("a real full disk needs a tmpfs mount (root in a sandbox that allows mount); "
                    "the failing-writer tests cover the same path by monkeypatching")


# ---------------------------------------------------------------------------------------------
# refine


def tiny_refiner(seed: int) -> ImuRefiner:
    torch.manual_seed(seed)
    _t, g, a = core.read_asl_imu(str(CROP / IMU_REL))
    raw = np.c_[g, a]
    m = ImuRefiner(ModelConfig(hidden=8, fc=8, layers=1), mean=torch.tensor(raw.mean(0)), std=torch.tensor(raw.std(0)))
    with torch.no_grad():
        torch.nn.init.normal_(m.head.weight, std=0.5)  # a visible correction, different per seed
    return m.eval()


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp("models")
    for seed in (1, 2):
        save_checkpoint(d / f"m{seed}.pt", tiny_refiner(seed), {"test": True}, epoch=1, step=1, best_metric=None)
    return d / "m1.pt", d / "m2.pt"


def refine_args(ckpt: Path, out: Path) -> list:
    return ["--checkpoint", ckpt, "--input", CROP, "--out", out, "--device", "cpu", "--quiet", "--window", "1000"]


def refine(ckpt: Path, out: Path) -> int:
    from imu_learn.cli.refine import main

    return main([str(a) for a in refine_args(ckpt, out)])


def test_refine_failing_writer_keeps_the_previous_output(models, out_dir, capsys):
    assert refine(models[0], out_dir) == 0
    before = files(out_dir)
    with faults.installed(faults.Fault("*data.csv*")) as fault:
        assert refine(models[1], out_dir) == 2
    assert fault.fired
    one_error_line(capsys.readouterr().err, str(out_dir / IMU_REL))
    assert_intact(before, out_dir, untouched=str(IMU_REL))


def test_refine_ctrl_c_midway_through_its_imu_writes_both_files_then_stops(models, tmp_path):
    """Ctrl-C while the refined IMU is written: the write and the summary beside it finish (Ctrl-C held for
    them), then exit 130 saying both are this run's. Before, the Ctrl-C between the two left this run's
    data.csv beside the previous run's summary.json (a new user's SIGINT to a real process found it)."""
    out = tmp_path / "out"
    assert refine(models[0], out) == 0
    before = files(out)
    marker = tmp_path / "fired"
    proc = faulty_cli("*data.csv*", 1, "hold", marker, "imu_learn.refine", *refine_args(models[1], out))
    try:
        deadline = time.time() + 120
        while not marker.exists():
            assert proc.poll() is None, proc.communicate()[1]
            assert time.time() < deadline, "the fault never fired"
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        time.sleep(0.5)
        Path(str(marker) + ".go").write_text("")
        err = proc.communicate(timeout=60)[1]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    assert "are this run's, complete" in err.strip().splitlines()[-1], err
    now = files(out)
    assert now[str(IMU_REL)] != before[str(IMU_REL)]
    assert json.loads(now["summary.json"])["checkpoint"] == str(models[1])  # the summary of this run's data
    assert temporaries(out) == []


def test_refine_killed_midway_keeps_the_previous_output_then_reruns(models, tmp_path):
    out = tmp_path / "out"
    assert refine(models[0], out) == 0
    before = files(out)
    proc = faulty_cli("*data.csv*", 1, "pause", tmp_path / "fired", "imu_learn.refine", *refine_args(models[1], out))
    signal_midway(proc, tmp_path / "fired", signal.SIGKILL)
    assert proc.returncode != 0
    assert files(out) == before | {k: v for k, v in files(out).items() if k.endswith(".tmp")}
    assert_only_hidden_temporaries(out)
    assert refine(models[1], out) == 0
    assert_complete(out / IMU_REL)
    assert files(out)[str(IMU_REL)] != before[str(IMU_REL)]


def test_refine_read_only_output(models, out_dir, capsys, monkeypatch):
    assert refine(models[0], out_dir) == 0
    before = files(out_dir)
    with read_only(out_dir, monkeypatch):
        assert refine(models[1], out_dir) == 2
    one_error_line(capsys.readouterr().err, str(out_dir / IMU_REL))
    assert_intact(before, out_dir, untouched=str(IMU_REL))


def test_refine_real_full_disk(models, out_dir, capsys):
    needs_mount()
    assert refine(models[0], out_dir) == 0
    before = files(out_dir)
    faults.shrink_to_used(out_dir, len(before[str(IMU_REL)]) // 2)  # room for half a new copy
    assert refine(models[1], out_dir) == 2
    assert "No space left" in one_error_line(capsys.readouterr().err, str(out_dir / IMU_REL))
    assert_intact(before, out_dir, untouched=str(IMU_REL))


# ---------------------------------------------------------------------------------------------
# labels


def labels_args(out: Path, *more: str) -> list:
    return ["euroc", "--dataset-dir", str(REPO / "datasets" / "euroc"), "--out", str(out), "--quiet",
            "--window", "100", "--stride", "50", *more]


def cache_arrays(folder: Path) -> list:
    return [({k: getattr(s, k) for k in cache.SEQUENCE_KEYS}, lab) for s, lab in cache.load_cache(folder)]


def assert_same_arrays(a: list, b: list) -> None:
    assert len(a) == len(b)
    for (sa, la), (sb, lb) in zip(a, b):
        for k in sa:
            np.testing.assert_array_equal(sa[k], sb[k])
        for k in la:
            np.testing.assert_array_equal(la[k], lb[k])


@pytest.fixture(scope="module")
def reference_cache(tmp_path_factory):
    out = tmp_path_factory.mktemp("labels") / "ref"
    assert labels_cli.main(labels_args(out)) == 0
    return cache_arrays(out)


@pytest.mark.parametrize("pattern,nth", [("*.npz*", 2), ("*manifest.json*", 1)])
def test_labels_failing_writer_keeps_the_previous_cache(out_dir, reference_cache, capsys, pattern, nth):
    assert labels_cli.main(labels_args(out_dir)) == 0
    before = files(out_dir)
    with faults.installed(faults.Fault(pattern, nth)) as fault:
        assert labels_cli.main(labels_args(out_dir, "--rebuild")) == 2
    assert fault.fired
    one_error_line(capsys.readouterr().err, str(out_dir))
    assert_intact(before, out_dir, untouched=cache.MANIFEST)
    assert_same_arrays(cache_arrays(out_dir), reference_cache)  # the previous cache, whole
    # the next run finishes, and drops the files no manifest lists any more
    assert labels_cli.main(labels_args(out_dir)) == 0
    listed = {s["file"] for r in cache.read_manifest(out_dir)["recordings"] for s in r["segments"]}
    assert {p.name for p in out_dir.glob("*.npz")} == listed
    assert not (out_dir / cache.PROGRESS).exists()


def test_labels_sigterm_midway_then_resume(tmp_path, reference_cache):
    out = tmp_path / "out"
    marker = tmp_path / "fired"
    # stopped while writing the progress after the second recording, then SIGTERM
    proc = faulty_cli(f"*{cache.PROGRESS}*", 2, "pause", marker, "imu_learn.labels", *labels_args(out))
    signal_midway(proc, marker, signal.SIGTERM)
    assert proc.returncode == 143  # SIGTERM stops as Ctrl-C does, clean-up included
    assert temporaries(out) == []
    assert not (out / cache.MANIFEST).exists()  # nothing finished: no manifest, not a partial one
    progress = json.loads((out / cache.PROGRESS).read_text())
    assert [r["name"] for r in progress["recordings"]] == ["MH_01_easy"]
    for p in out.glob("*.npz"):
        assert_complete(p)
    assert_only_hidden_temporaries(out)
    with pytest.raises(CacheError, match="no label cache"):
        cache.load_cache(out)
    assert labels_cli.main(labels_args(out)) == 0
    m = cache.read_manifest(out)
    assert m["recordings"][0]["seconds"] == progress["recordings"][0]["seconds"]  # resumed, not redone
    assert_same_arrays(cache_arrays(out), reference_cache)


def test_labels_read_only_cache(out_dir, capsys, monkeypatch):
    assert labels_cli.main(labels_args(out_dir)) == 0
    before = files(out_dir)
    with read_only(out_dir, monkeypatch):
        assert labels_cli.main(labels_args(out_dir, "--rebuild")) == 2
    one_error_line(capsys.readouterr().err, str(out_dir))
    assert_intact(before, out_dir, untouched=cache.MANIFEST)


def test_labels_real_full_disk(out_dir, reference_cache, capsys):
    needs_mount()
    assert labels_cli.main(labels_args(out_dir)) == 0
    before = files(out_dir)
    faults.shrink_to_used(out_dir, 8192)
    assert labels_cli.main(labels_args(out_dir, "--rebuild")) == 2
    assert "No space left" in one_error_line(capsys.readouterr().err, str(out_dir))
    assert_intact(before, out_dir, untouched=cache.MANIFEST)
    assert_same_arrays(cache_arrays(out_dir), reference_cache)


def test_two_labels_runs_on_one_cache_take_turns(tmp_path, reference_cache):
    out = tmp_path / "out"
    marker = tmp_path / "holding"
    # The first run stops inside the lock (halfway through its first progress file) until released.
    first = faulty_cli(f"*{cache.PROGRESS}*", 1, "hold", marker, "imu_learn.labels", *labels_args(out))
    second = None
    try:
        deadline = time.time() + 120
        while not marker.exists():
            assert first.poll() is None and time.time() < deadline, first.communicate()[1]
            time.sleep(0.05)
        second = subprocess.Popen([sys.executable, "-m", "imu_learn.labels", *labels_args(out, "--rebuild")],
                                  cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        waiting = second.stderr.readline()  # it says it waits, and does
        assert "waiting" in waiting, waiting
        assert second.poll() is None
        Path(str(marker) + ".go").touch()
        assert first.wait(120) == 0, first.communicate()[1]
        assert second.wait(120) == 0, second.communicate()[1]
    finally:
        for p in (first, second):
            if p is not None and p.poll() is None:
                p.kill()
            if p is not None:
                p.communicate()
    assert_same_arrays(cache_arrays(out), reference_cache)
    assert temporaries(out) == []


@pytest.mark.parametrize("damage", ["truncate a segment", "flip a segment byte", "edit the manifest"])
def test_damaged_cache_is_refused_then_rebuilt_by_labels(tmp_path, reference_cache, capsys, damage):
    out = tmp_path / "c"
    assert labels_cli.main(labels_args(out)) == 0
    seg = sorted(out.glob("*.npz"))[0]
    if damage == "truncate a segment":
        seg.write_bytes(seg.read_bytes()[:-100])
        culprit = seg
    elif damage == "flip a segment byte":
        data = bytearray(seg.read_bytes())
        data[len(data) // 2] ^= 0x01
        seg.write_bytes(bytes(data))
        culprit = seg
    else:
        m = json.loads((out / cache.MANIFEST).read_text())
        m["recordings"][0]["segments"][0]["windows"] += 1
        (out / cache.MANIFEST).write_text(json.dumps(m))
        culprit = out / cache.MANIFEST
    with pytest.raises(CacheError) as e:
        cache.load_cache(out)
    assert str(culprit) in str(e.value) and "imu-learn labels euroc --out" in str(e.value)
    capsys.readouterr()
    assert labels_cli.main(labels_args(out)) == 0
    err = capsys.readouterr().err
    assert str(culprit) in err and "rebuilding" in err
    assert_same_arrays(cache_arrays(out), reference_cache)


# ---------------------------------------------------------------------------------------------
# fit

FIT_TINY = ["--quiet", "--data.window", "50", "--data.batch_size", "8", "--data.val_stride", "200",
            "--data.eval_stride", "50", "--model.hidden", "8", "--model.fc", "8", "--model.layers", "1",
            "--optim.steps_per_epoch", "4", "--optim.lr", "1e-3", "--seed", "7", "--threads", "1",
            "--model.start", "raw"]  # the checkpoint writes of a run from raw IMU (no profile, no epoch 0)


def fit(*args: str) -> int:
    from imu_learn.cli import fit as fit_mod
    return fit_mod.main([str(a) for a in args])


def fit_new(run: Path, epochs: int) -> list:
    return ["--out", str(run), *FIT_TINY, "--optim.epochs", str(epochs)]


def fit_resume(run: Path, epochs: int) -> list:
    return ["--resume", str(run), "--quiet", "--optim.epochs", str(epochs)]


def test_fit_failing_writer_keeps_the_previous_checkpoint(out_dir, capsys):
    run = out_dir / "run"
    assert fit(*fit_new(run, 1)) == 0
    before = files(run)
    with faults.installed(faults.Fault("*last.pt*")) as fault:
        assert fit(*fit_resume(run, 2)) == 2
    assert fault.fired
    one_error_line(capsys.readouterr().err, str(run / "last.pt"))
    assert_intact(before, run, untouched="last.pt")
    assert fit(*fit_resume(run, 2)) == 0
    assert load_checkpoint(run / "last.pt")["epoch"] == 2


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_fit_signal_midway_through_a_checkpoint_then_resume(tmp_path, sig):
    run = tmp_path / "run"
    marker = tmp_path / "fired"
    # stopped halfway through epoch 2's last.pt (epoch 1's is complete); SIGTERM is held as Ctrl-C is while a
    # checkpoint is written: that write is let go on (hold, then released) and the run stops after it
    action = "hold" if sig == signal.SIGTERM else "pause"
    proc = faulty_cli("*last.pt*", 2, action, marker, "imu_learn.fit", *fit_new(run, 3))
    if sig == signal.SIGTERM:  # released only once the signal is in (released before, it met another moment)
        release = Path(str(marker) + ".go")
        send = proc.send_signal
        proc.send_signal = lambda s: (send(s), time.sleep(0.5), release.write_text(""))
    signal_midway(proc, marker, sig)
    assert proc.returncode == (143 if sig == signal.SIGTERM else -sig)
    for p in run.iterdir():
        if p.is_file() and not p.name.endswith(".tmp"):
            assert_complete(p)
    assert load_checkpoint(run / "last.pt")["step"] == (8 if sig == signal.SIGTERM else 4)
    assert_only_hidden_temporaries(run)
    assert fit(*fit_resume(run, 3)) == 0
    assert load_checkpoint(run / "last.pt")["step"] == 12
    assert (run / "results.json").is_file()


def test_fit_read_only_run_folder(out_dir, capsys, monkeypatch):
    run = out_dir / "run"
    assert fit(*fit_new(run, 1)) == 0
    before = files(run)
    with read_only(out_dir, monkeypatch):
        assert fit(*fit_resume(run, 2)) == 2
    one_error_line(capsys.readouterr().err, str(run))
    assert_intact(before, run, untouched="last.pt")


def flip_tensor_byte(path: Path) -> None:
    """Change one byte inside a tensor's data (not the zip's structure, not the pickle)."""
    import struct
    import zipfile

    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as z:
        info = next(i for i in z.infolist() if "/data/" in i.filename and i.file_size >= 16)
    n, extra = struct.unpack("<HH", data[info.header_offset + 26:info.header_offset + 30])
    data[info.header_offset + 30 + n + extra + 5] ^= 0x10
    path.write_bytes(bytes(data))


def test_checkpoint_with_a_flipped_tensor_byte_is_refused(tmp_path, models, capsys):
    path = tmp_path / "m.pt"
    path.write_bytes(models[0].read_bytes())
    flip_tensor_byte(path)
    # torch's own reader takes it (its zip reader checks no CRC): only the digest tells
    torch.load(path, weights_only=True)
    with pytest.raises(CheckpointError, match="truncated or modified"):
        load_checkpoint(path)


def test_fit_resume_on_a_tampered_last_pt_refuses_in_one_line(tmp_path, capsys):
    run = tmp_path / "run"
    assert fit(*fit_new(run, 1)) == 0
    flip_tensor_byte(run / "last.pt")
    before = files(run)
    capsys.readouterr()
    assert fit(*fit_resume(run, 2)) == 2
    one_error_line(capsys.readouterr().err, "CheckpointError", str(run / "last.pt"))
    assert files(run) == before  # refused, not restarted from scratch


def test_checkpoints_written_before_digests_still_load(tmp_path):
    """A checkpoint saved before digests existed (no ``digest`` entry) loads, with its weights."""
    for path in sorted((REPO / "models").glob("*.pt")):
        state = load_checkpoint(path)
        old = {k: v for k, v in state.items() if k != "digest"}
        file = tmp_path / path.name
        torch.save(old, file)
        loaded = load_checkpoint(file)
        assert "digest" not in loaded
        assert all(torch.equal(loaded["model"][k], v) for k, v in state["model"].items())


# ---------------------------------------------------------------------------------------------
# evaluate


class SavingRaw(Raw):
    """The raw IMU with a fitted file to save: exercises evaluate's saving of fitted methods."""

    name = "saver"

    def save(self, path):
        torch.save({"fitted": torch.arange(4.0)}, path)

    def load(self, path):
        torch.load(path, weights_only=True)
        return self


EVAL_ARGS = ["--config", str(REPO / "configs" / "eval_default.toml"), "--quiet", "--fit.threads", "1",
             "--eval.stride", "200", "--eval.noise_floor", "never", "--eval.curve_count", "2",
             "--eval.horizons", "[10]", "--eval.airimu_s", "[1.0]"]


def evaluate(out: Path, methods: str = "raw,saver") -> int:
    from imu_learn.cli import evaluate as ev_cli
    return ev_cli.main([*EVAL_ARGS, "--methods", methods, "--out", str(out)])


@pytest.fixture()
def saver(monkeypatch):
    from imu_learn.eval import run as ev
    monkeypatch.setitem(ev.REGISTRY, "saver", SavingRaw)


@pytest.mark.parametrize("pattern", ["*saver.pt*", "*integration_error_open_loop.png*", "*report.md*"])
def test_evaluate_failing_writer_keeps_the_previous_report(out_dir, saver, capsys, pattern):
    assert evaluate(out_dir) == 0
    before = files(out_dir)
    with faults.installed(faults.Fault(pattern)) as fault:
        assert evaluate(out_dir) == 2
    name = Path(fault.fired).name
    final = next(n for n in before if Path(n).name == name or name.startswith(f".{Path(n).name}."))
    one_error_line(capsys.readouterr().err, str(out_dir / final))
    assert_intact(before, out_dir, untouched=final)


def test_evaluate_sigint_midway_then_rerun(tmp_path):
    out = tmp_path / "out"
    marker = tmp_path / "fired"
    proc = faulty_cli("*report.md*", 1, "pause", marker, "imu_learn.evaluate", *EVAL_ARGS, "--methods", "raw",
                      "--out", out)
    err = signal_midway(proc, marker, signal.SIGINT)
    assert proc.returncode == 130, err
    assert not (out / "report.md").exists()
    for p in out.rglob("*"):
        if p.is_file():
            assert_complete(p)
    assert temporaries(out) == []
    assert evaluate(out, "raw") == 0
    assert_complete(out / "report.md")


def test_evaluate_rerun_interrupted_while_writing_its_report_leaves_the_previous_report_whole(tmp_path):
    """A report of raw and timing, then a rerun of raw alone stopped by Ctrl-C once its CSVs are written (in result.json): every
    file of the previous report byte for byte (a new user's SIGINT found the rerun's CSVs beside the previous
    report.md, which named a method they lack), and the line says so. Rerun to the end: the new report alone."""
    out = tmp_path / "out"
    assert evaluate(out, "raw,timing") == 0
    report = lambda: {k: v for k, v in files(out).items() if not k.startswith("methods")}  # noqa: E731
    before = report()
    marker = tmp_path / "fired"
    proc = faulty_cli("*result.json*", 1, "pause", marker, "imu_learn.evaluate", *EVAL_ARGS, "--methods", "raw",
                      "--out", out)
    err = signal_midway(proc, marker, signal.SIGINT)
    assert proc.returncode == 130, err
    assert "the report is the previous run's, whole" in err.strip().splitlines()[-1], err
    assert report() == before
    assert [p for p in out.iterdir() if p.name.endswith(".staging")] == []
    assert evaluate(out, "raw") == 0
    assert b"timing" not in report()["relative_pose.csv"] and set(report()) == set(before)


def test_evaluate_read_only_report_folder(out_dir, saver, capsys, monkeypatch):
    assert evaluate(out_dir) == 0
    before = files(out_dir)
    with read_only(out_dir, monkeypatch):
        assert evaluate(out_dir) == 2
    one_error_line(capsys.readouterr().err, str(out_dir))
    assert_intact(before, out_dir)


# ---------------------------------------------------------------------------------------------
# fuse


def fuse_config(path: Path, sigma_m: float) -> Path:
    path.write_text(f"""name = "t"
data_root = "{REPO / 'datasets'}"
seeds = [0]
inputs = ["raw"]

[[recordings]]
path = "euroc/MH_04_difficult"
format = "euroc"
groundtruth = "euroc/MH_04_difficult/mav0/state_groundtruth_estimate0/data.csv"

[[scenarios]]
name = "gnss"
kind = "position"
rate_hz = 1.0
sigma_m = {sigma_m}
""")
    return path


def fuse(config: Path, out: Path) -> int:
    pytest.importorskip("gtsam")
    from imu_learn.cli.fuse import main

    return main(["--config", str(config), "--out", str(out)])


@pytest.mark.parametrize("pattern", ["*results.json*", "*_smoothed.tum*", "*.png*"])
def test_fuse_failing_writer_keeps_the_previous_results(tmp_path, out_dir, capsys, pattern):
    assert fuse(fuse_config(tmp_path / "a.toml", 0.1), out_dir) == 0
    before = files(out_dir)
    with faults.installed(faults.Fault(pattern)) as fault:
        assert fuse(fuse_config(tmp_path / "b.toml", 0.2), out_dir) == 2  # another aiding: every run redone
    name = Path(fault.fired).name
    final = next(n for n in before if Path(n).name == name or name.startswith(f".{Path(n).name}."))
    one_error_line(capsys.readouterr().err, str(out_dir / final))
    assert_intact(before, out_dir, untouched=final)


def test_fuse_sigterm_midway_then_rerun(tmp_path):
    pytest.importorskip("gtsam")
    out = tmp_path / "out"
    marker = tmp_path / "fired"
    config = fuse_config(tmp_path / "a.toml", 0.1)
    proc = faulty_cli("*_smoothed.tum*", 1, "pause", marker, "imu_learn.cli", "fuse", "--config", config, "--out", out)
    signal_midway(proc, marker, signal.SIGTERM)
    assert proc.returncode == 143  # SIGTERM stops as Ctrl-C does, clean-up included
    assert temporaries(out) == []
    assert not (out / "results.json").exists()  # the run had not finished
    assert not (out / "trajectories" / "MH_04_difficult_gnss_raw_s0_smoothed.tum").exists()
    assert_complete(out / "trajectories" / "MH_04_difficult_gnss_raw_s0_causal.tum")
    assert_only_hidden_temporaries(out)
    assert fuse(config, out) == 0
    for p in out.rglob("*"):
        if p.is_file() and not p.name.endswith(".tmp"):
            assert_complete(p)


def test_fuse_read_only_report_folder(tmp_path, out_dir, capsys, monkeypatch):
    assert fuse(fuse_config(tmp_path / "a.toml", 0.1), out_dir) == 0
    before = files(out_dir)
    with read_only(out_dir, monkeypatch):
        assert fuse(fuse_config(tmp_path / "b.toml", 0.2), out_dir) == 2
    one_error_line(capsys.readouterr().err, str(out_dir))
    assert_intact(before, out_dir)


def test_fuse_unreadable_results_are_redone_with_a_message(tmp_path, capsys):
    out = tmp_path / "out"
    config = fuse_config(tmp_path / "a.toml", 0.1)
    assert fuse(config, out) == 0
    good = json.loads((out / "results.json").read_text())
    (out / "results.json").write_text((out / "results.json").read_text()[:100])
    capsys.readouterr()
    assert fuse(config, out) == 0
    out_text = capsys.readouterr().out
    assert str(out / "results.json") in out_text and "done again" in out_text
    assert json.loads((out / "results.json").read_text())["runs"].keys() == good["runs"].keys()


@pytest.mark.parametrize("command", ["calibrate", "navigate"])
def test_an_out_that_cannot_be_written_is_refused_before_any_work(tmp_path, capsys, command):
    """calibrate and navigate named a file or a read-only --out only when their outputs went in, after the
    work (8-28 s on the helpers' runs), leaving their staging folders behind; now before reading anything
    (the inputs here do not even exist)."""
    from imu_learn.cli import main

    afile = tmp_path / "afile"
    afile.write_text("mine\n")
    extra = ["--aiding", str(tmp_path / "none.pos")] if command == "navigate" else []
    assert main([command, "--input", str(tmp_path / "nowhere"), *extra, "--out", str(afile)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "NotADirectoryError" in err[0] and "exists and is not a folder" in err[0], err
    assert afile.read_text() == "mine\n" and sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


@pytest.mark.parametrize("edit, field", [
    (lambda s: s.pop("model"), "field 'model' (the weights) is missing"),
    (lambda s: s.update(model_args={**s["model_args"], "hidden": 7}), "its model_args do not rebuild its weights"),
    (lambda s: s["model"].update({k: torch.full_like(v, float("nan"))
                                  for k, v in list(s["model"].items()) if "weight" in k}), "holds NaN"),
    (lambda s: s["model"].update(std=torch.zeros_like(s["model"]["std"])), "field 'model.std'"),
])
def test_a_checkpoint_edited_without_its_digest_is_refused_naming_the_field(tmp_path, capsys, edit, field):
    """A checkpoint saved again without its digest (so nothing vouches for it) whose weights are missing,
    NaN, unnormalised or do not fit its model_args: one line naming the field, at load, for every command
    (it ended in a traceback, exit 1, or in NaN output blamed on the recording)."""
    state = load_checkpoint(REPO / "models" / "euroc_adis16448.pt")
    state = {k: (dict(v) if isinstance(v, dict) else v) for k, v in state.items() if k != "digest"}
    edit(state)
    path = tmp_path / "edited.pt"
    torch.save(state, path)
    with pytest.raises(CheckpointError, match=field.replace("(", r"\(").replace(")", r"\)")):
        load_checkpoint(path)
    capsys.readouterr()
    assert cli_main(["checkpoint", "info", str(path)]) == 2
    one_error_line(capsys.readouterr().err, "CheckpointError", str(path))


def test_a_text_file_or_a_cut_copy_given_as_checkpoint_says_what_it_is(tmp_path, capsys):
    text = tmp_path / "notes.pt"
    text.write_text("hello world\n")
    cut = tmp_path / "cut.pt"
    cut.write_bytes((REPO / "models" / "euroc_adis16448.pt").read_bytes()[:1000])
    for path, words in ((text, "not a torch file: it holds text"), (cut, "truncated: the torch archive has no end")):
        with pytest.raises(CheckpointError, match=words):
            load_checkpoint(path)
