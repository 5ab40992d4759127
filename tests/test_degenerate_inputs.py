"""Empty and degenerate inputs: each gets its own typed error naming the file and what is
wrong, from the Python API and from every CLI (one line on stderr, non-zero exit, no traceback)."""
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

import imu_learn as il
from imu_learn.data.datasets import find_recordings
from imu_learn.errors import NoRecordingsError, TooShortError

torch.set_num_threads(1)

IMU_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
              "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n")
STATE_HEADER = "#time(ns),px,py,pz,qw,qx,qy,qz,vx,vy,vz,bwx,bwy,bwz,bax,bay,baz\n"
T0 = 1_403_636_580_000_000_000
DT = 5_000_000  # 200 Hz
IMU_REL = Path("mav0") / "imu0" / "data.csv"
GT_REL = Path("mav0") / "state_groundtruth_estimate0" / "data.csv"


def imu_rows(n, t0=T0):
    return "".join(f"{t0 + i * DT},0.01,0.02,0.03,0.1,0.2,9.81\n" for i in range(n))


def gt_rows(n, t0=T0):
    return "".join(f"{t0 + i * DT},0,0,0,1,0,0,0,0,0,0,0,0,0,0,0,0\n" for i in range(n))


def recording(folder, imu_text, gt_text):
    """An EuRoC-layout sequence folder holding exactly these IMU and ground-truth files."""
    for rel, text in ((IMU_REL, imu_text), (GT_REL, gt_text)):
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        (folder / rel).write_text(text)
    return folder


def good(folder, n=400, gt_t0=T0):
    return recording(folder, IMU_HEADER + imu_rows(n), STATE_HEADER + gt_rows(n, gt_t0))


# ---- reader level: empty, header only, one row ---------------------------------------------

@pytest.mark.parametrize("text, line, words", [
    (IMU_HEADER, 1, "has a header but no samples"),
    ("", 0, "is empty"),
    ("\n\n", 0, "is empty"),
    (IMU_HEADER + imu_rows(1), 2, "has only 1 sample"),
])
def test_imu_file_with_too_few_rows(tmp_path, text, line, words):
    f = tmp_path / "data.csv"
    f.write_text(text)
    with pytest.raises(il.TooFewRowsError) as e:
        il.read_imu(f)
    err = e.value
    assert isinstance(err, il.ParseError) and err.path == str(f) and err.line == line
    assert str(f) in str(err) and "IMU file" in str(err) and words in str(err), err
    assert "at least 2" in str(err)


@pytest.mark.parametrize("name, text, words", [
    ("gt.csv", STATE_HEADER, "ground-truth file has a header but no poses"),
    ("gt.csv", STATE_HEADER + gt_rows(1), "ground-truth file has only 1 pose"),
    ("gt.tum", "", "ground-truth file is empty"),
    ("gt.tum", "# t tx ty tz qx qy qz qw\n\n", "ground-truth file has a header but no poses"),
    ("gt.tum", "1403636580.0 0 0 0 0 0 0 1\n", "ground-truth file has only 1 pose"),
])
def test_groundtruth_file_with_too_few_rows(tmp_path, name, text, words):
    seq = good(tmp_path / "seq")
    gt = tmp_path / name
    gt.write_text(text)
    with pytest.raises(il.TooFewRowsError) as e:
        il.load_sequence(seq, groundtruth=gt)
    assert e.value.path == str(gt) and str(gt) in str(e.value) and words in str(e.value), e.value


def test_header_only_imu_through_load_sequence_names_the_file(tmp_path):
    """Before: read as an empty recording, then InvalidInputError 'no IMU samples' without a file."""
    seq = recording(tmp_path / "seq", IMU_HEADER, STATE_HEADER + gt_rows(400))
    with pytest.raises(il.TooFewRowsError, match="header but no samples") as e:
        il.load_sequence(seq)
    assert e.value.path == str(seq / IMU_REL)


# ---- alignment level: ground truth and IMU never overlap -----------------------------------

@pytest.mark.parametrize("shift_s, relation", [(-10, "ends 8.005 s before the IMU starts"),
                                               (10, "starts 8.005 s after the IMU ends")])
def test_groundtruth_outside_the_imu_span(tmp_path, shift_s, relation):
    seq = good(tmp_path / "seq", gt_t0=T0 + shift_s * 10**9)
    with pytest.raises(il.NoOverlapError) as e:
        il.load_sequence(seq)
    err, msg = e.value, str(e.value)
    assert isinstance(err, il.AlignmentError)
    assert err.path == str(seq / GT_REL) and err.imu_path == str(seq / IMU_REL)
    assert str(seq / GT_REL) in msg and str(seq / IMU_REL) in msg and "never overlap" in msg
    t0 = T0 * 1e-9
    assert f"{t0 + shift_s:.3f}-{t0 + shift_s + 1.995:.3f} s" in msg and f"{t0:.3f}-{t0 + 1.995:.3f} s" in msg
    assert relation in msg


def test_no_overlap_from_arrays_is_typed_without_paths():
    t = T0 + np.arange(10, dtype=np.int64) * DT
    z = np.zeros((10, 3))
    q = np.tile([1.0, 0, 0, 0], (10, 1))
    with pytest.raises(il.NoOverlapError, match="ground truth covers .* the IMU .* never overlap") as e:
        il.align(il.ImuData(t, z, z), il.GroundTruth(t + 10**12, z, q))
    assert e.value.path is None and e.value.imu_path is None


def test_recording_shorter_than_a_segment_names_both_files(tmp_path):
    seq = good(tmp_path / "seq", n=50)  # 0.245 s; segments under min_segment_s = 1 s are dropped
    with pytest.raises(il.AlignmentError) as e:
        il.load_sequence(seq)
    msg = str(e.value)
    assert e.value.path == str(seq / GT_REL) and e.value.imu_path == str(seq / IMU_REL)
    assert str(seq / IMU_REL) in msg and "the longest has 50" in msg and "min_segment_s" in msg


# ---- window level: labels and the fit/evaluate split -----------------------------------------

def test_labels_refuse_a_recording_shorter_than_one_window(tmp_path):
    from imu_learn.data.label_builder import build_cache

    seq = good(tmp_path / "data" / "seq", n=250)  # 1.245 s: aligns, but holds no 300-sample window
    with pytest.raises(TooShortError) as e:
        build_cache("euroc", tmp_path / "data", tmp_path / "cache", window=300, progress=False)
    err = e.value
    assert err.path == str(seq) and (err.samples, err.needed) == (250, 301)
    assert str(seq) in str(err) and "250 samples" in str(err) and "--window" in str(err)


def fit_config(tmp_path, short_root, short_name):
    """A fit config training on one (degenerate) recording, validating and testing on the crop."""
    cfg = tmp_path / "fit.toml"
    crop = Path(__file__).resolve().parent.parent / "datasets" / "euroc" / "MH_01_easy"
    cfg.write_text(f"""
[data]
window = 300
[data.split]
train = ["{short_name}"]
val = ["MH_01_easy[0:0.5]"]
test = ["MH_01_easy[0.5:1]"]
[[data.roots]]
path = "{short_root}"
format = "euroc"
[[data.roots]]
path = "{crop}"
format = "euroc"
""")
    return cfg


def test_split_refuses_a_recording_shorter_than_one_window(tmp_path):
    from imu_learn.data.splits import make_split
    from imu_learn.train.config import build_config, read_toml

    seq = good(tmp_path / "data" / "short", n=250)
    cfg = build_config(read_toml(fit_config(tmp_path, tmp_path / "data", "short")), {})
    with pytest.raises(TooShortError) as e:
        make_split(cfg.data)
    msg = str(e.value)
    assert e.value.path == str(seq) and "data.split.train" in msg and str(seq) in msg
    assert "250 samples" in msg and "301" in msg and "lower data.window" in msg


# ---- folder level: a dataset folder with no recordings ---------------------------------------

@pytest.mark.parametrize("dataset, looked_for", [("euroc", "mav0"), ("blackbird", "data.hdf5"), ("broad", ".mat"),
                                                 ("kaist", "xsens_imu.csv")])
def test_dataset_folder_without_recordings(tmp_path, dataset, looked_for):
    (tmp_path / "notes.txt").write_text("nothing here")
    with pytest.raises(NoRecordingsError) as e:
        find_recordings(dataset, tmp_path)
    assert isinstance(e.value, il.InvalidInputError) and e.value.path == str(tmp_path)
    assert str(tmp_path) in str(e.value) and "no " + dataset in str(e.value) and looked_for in str(e.value)


# ---- refine: a recording shorter than the refiner's window still refines ---------------------

@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    from imu_learn.infer.checkpoint import save_checkpoint
    from imu_learn.nn.model import ImuRefiner, ModelConfig

    torch.manual_seed(0)
    model = ImuRefiner(ModelConfig(hidden=8, fc=8), mean=torch.zeros(6), std=torch.ones(6))
    path = tmp_path_factory.mktemp("ckpt") / "model.pt"
    save_checkpoint(path, model, {"test": True}, epoch=1, step=1, best_metric=None)
    return path


def test_refine_a_recording_shorter_than_its_window(tmp_path, checkpoint):
    """The window is how refine chunks a long recording, not something the model needs: a shorter
    recording is one window of its own length (refine.py's stitching rule), as a user expects."""
    from imu_learn.cli.refine import main

    seq = good(tmp_path / "seq", n=50)
    out = tmp_path / "out"
    assert main(["--checkpoint", str(checkpoint), "--input", str(seq), "--out", str(out), "--quiet",
                 "--window", "1000", "--device", "cpu"]) == 0
    t, _g, _a = il._imu_core.read_asl_imu(str(out / IMU_REL))
    assert len(t) == 50


# ---- every CLI: one line on stderr, non-zero exit, no traceback ------------------------------

def one_error_line(err):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert re.match(r"imu-learn [a-z]+: error: [A-Za-z]+Error: ", lines[0]), err
    return lines[0]


def run_cli(module, *args):
    r = subprocess.run([sys.executable, "-m", f"imu_learn.{module}", *map(str, args)], capture_output=True, text=True,
                       env=dict(os.environ, OMP_NUM_THREADS="1", RAYON_NUM_THREADS="1"), timeout=300)
    return r.returncode, one_error_line(r.stderr)


@pytest.fixture()
def degenerate(tmp_path):
    """One dataset folder per degenerate case, each holding one recording (or none)."""
    root = tmp_path / "cases"
    recording(root / "header_only" / "seq", IMU_HEADER, STATE_HEADER + gt_rows(400))
    recording(root / "one_row" / "seq", IMU_HEADER + imu_rows(1), STATE_HEADER + gt_rows(400))
    recording(root / "gt_one_row" / "seq", IMU_HEADER + imu_rows(400), STATE_HEADER + gt_rows(1))
    good(root / "no_overlap" / "seq", gt_t0=T0 + 10 * 10**9)
    good(root / "short" / "seq", n=250)
    (root / "empty").mkdir(parents=True)
    return root


CASES = {  # case -> (class name, words of the message)
    "header_only": ("TooFewRowsError", "header but no samples"),
    "one_row": ("TooFewRowsError", "only 1 sample"),
    "gt_one_row": ("TooFewRowsError", "only 1 pose"),
    "no_overlap": ("NoOverlapError", "never overlap"),
    "short": ("TooShortError", "250 samples"),
    "empty": ("NoRecordingsError", "no euroc recordings found"),
}


def expected_path(root, case):
    if case == "empty":
        return root / "empty"
    if case == "short":
        return root / "short" / "seq"
    return root / case / "seq" / (GT_REL if case in ("gt_one_row", "no_overlap") else IMU_REL)


def assert_cli_error(rc, err, degenerate, case):
    """One error line naming the case's class, its file and what is wrong; a non-zero exit."""
    line = one_error_line(err)
    cls, words = CASES[case]
    assert rc != 0 and cls in line and str(expected_path(degenerate, case)) in line and words in line, line


@pytest.mark.parametrize("case", list(CASES))
def test_labels_cli(degenerate, tmp_path, case, capsys):
    from imu_learn.cli.labels import main

    rc = main(["euroc", "--dataset-dir", str(degenerate / case), "--out", str(tmp_path / "cache"), "--quiet",
               "--window", "300"])
    line = one_error_line(capsys.readouterr().err)
    assert rc != 0 and str(expected_path(degenerate, case)) in line and CASES[case][1] in line, line


@pytest.mark.parametrize("case", list(CASES))
def test_fit_cli(degenerate, tmp_path, case, capsys):
    from imu_learn.cli.fit import main

    rc = main(["--config", str(fit_config(tmp_path, degenerate / case, "seq")), "--out", str(tmp_path / "run"),
               "--quiet"])
    assert_cli_error(rc, capsys.readouterr().err, degenerate, case)


@pytest.mark.parametrize("case", ["header_only", "no_overlap", "short", "empty"])
def test_evaluate_cli(degenerate, tmp_path, case, capsys):
    from imu_learn.cli.evaluate import main

    ev = tmp_path / "eval.toml"
    ev.write_text(f'name = "t"\nbase = "{fit_config(tmp_path, degenerate / case, "seq")}"\nmethods = ["raw"]\n')
    rc = main(["--config", str(ev), "--out", str(tmp_path / "report"), "--quiet"])
    assert_cli_error(rc, capsys.readouterr().err, degenerate, case)


@pytest.mark.parametrize("case", ["header_only", "one_row", "gt_one_row", "no_overlap"])
def test_fuse_cli(degenerate, tmp_path, case, capsys):
    from imu_learn.cli.fuse import main

    cfg = tmp_path / "fuse.toml"
    cfg.write_text(f'name = "t"\ninputs = ["raw"]\nseeds = [0]\n[[recordings]]\npath = "{degenerate / case / "seq"}"\n'
                   'format = "euroc"\n[[scenarios]]\nname = "gnss"\nkind = "position"\n')
    rc = main(["--config", str(cfg), "--out", str(tmp_path / "fused")])
    assert_cli_error(rc, capsys.readouterr().err, degenerate, case)


@pytest.mark.parametrize("case", ["header_only", "one_row"])
def test_refine_cli(degenerate, tmp_path, checkpoint, case, capsys):
    from imu_learn.cli.refine import main

    rc = main(["--checkpoint", str(checkpoint), "--input", str(degenerate / case / "seq"), "--out",
               str(tmp_path / "out"), "--device", "cpu", "--quiet"])
    line = one_error_line(capsys.readouterr().err)
    assert rc != 0 and "TooFewRowsError" in line and str(expected_path(degenerate, case)) in line
    assert CASES[case][1] in line, line


def test_cli_entry_points_print_no_traceback(degenerate, tmp_path):
    """The same through ``python -m`` (what a user runs), not only main()."""
    rc, line = run_cli("labels", "euroc", "--dataset-dir", degenerate / "header_only", "--out", tmp_path / "c", "--quiet")
    assert rc != 0 and "header but no samples" in line
    rc, line = run_cli("labels", "euroc", "--dataset-dir", degenerate / "empty", "--out", tmp_path / "c", "--quiet")
    assert rc != 0 and "no euroc recordings found" in line
