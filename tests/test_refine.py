"""imu_learn.infer.refiner: windowed refinement, stitching, and writing each format back unchanged but for the IMU."""
import csv
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from crops import whole_pass
from imu_learn import _imu_core as core
from imu_learn.cli.refine import main
from imu_learn.infer.checkpoint import save_checkpoint
from imu_learn.infer.refiner import refine_arrays
from imu_learn.infer.windowing import window_plan
from imu_learn.nn.model import ImuRefiner, ModelConfig

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
CROP = REPO / "datasets" / "euroc" / "V1_01_easy"
IMU_REL = Path("mav0") / "imu0" / "data.csv"


def random_model(causal=False, seed=0, memory=1.0):
    """Random weights with a non-zero head (so refinement changes the data); ``memory`` scales
    the recurrent weights, which lengthens how long the LSTM remembers."""
    torch.manual_seed(seed)
    _t, g, a = core.read_asl_imu(str(CROP / IMU_REL))
    raw = np.c_[g, a]
    m = ImuRefiner(ModelConfig(causal=causal), mean=torch.tensor(raw.mean(0)), std=torch.tensor(raw.std(0)))
    with torch.no_grad():
        torch.nn.init.normal_(m.head.weight, std=0.5)
        torch.nn.init.normal_(m.head.bias, std=0.1)
        for lstm in m.lstms:
            for name, p in lstm.named_parameters():
                if "weight_hh" in name:
                    p.mul_(memory)
    return m.eval()


@pytest.fixture(scope="module")
def imu():
    t, g, a = core.read_asl_imu(str(CROP / IMU_REL))
    return t, g, a




def sha(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def test_window_plan_tiles_the_sequence_and_keeps_centres():
    for n, w, o in [(2500, 1000, 200), (12000, 1000, 200), (1001, 1000, 200), (999, 1000, 200), (37, 10, 3), (50, 10, 0)]:
        plan = window_plan(n, w, o)
        assert plan[0][2] == 0 and plan[-1][3] == n
        for (s, e, kf, kt), nxt in zip(plan, plan[1:] + [None]):
            assert e - s == min(w, n) and s <= kf < kt <= e
            if nxt is not None:
                assert kt == nxt[2]
                # every kept sample is at least floor(overlap/2) from an inner window edge
                assert e - kt >= (e - nxt[0]) // 2 and nxt[2] - nxt[0] >= (e - nxt[0]) // 2
    assert window_plan(2500, 1000, 200) == [(0, 1000, 0, 900), (800, 1800, 900, 1650), (1500, 2500, 1650, 2500)]
    with pytest.raises(ValueError):
        window_plan(100, 10, 10)


def test_window_covering_everything_is_the_whole_sequence_forward_exactly(imu):
    _t, g, a = imu
    m = random_model()
    rg, ra = refine_arrays(m, g, a, window=len(g), overlap=0)
    np.testing.assert_array_equal(np.c_[rg, ra], whole_pass(m, g, a))
    assert np.abs(rg - g).max() > 1e-4 and np.abs(ra - a).max() > 1e-3  # the model does change the data


def test_stitched_windows_match_whole_sequence_at_the_centres(imu):
    """Bidirectional: approximate. A model with longer memory (recurrent weights x1.5) shows the
    rule working: no overlap leaves visible seams, overlap 200 (100 samples of context each side)
    matches the whole-sequence forward to float32 rounding."""
    _t, g, a = imu
    m = random_model(memory=1.5)
    ref = whole_pass(m, g, a)
    corr = np.abs(ref - np.c_[g, a]).max(0)
    diff = {}
    for ov in (0, 200):
        rg, ra = refine_arrays(m, g, a, window=1000, overlap=ov)
        diff[ov] = (np.abs(np.c_[rg, ra] - ref).max(0) / corr).max()
    # measured (torch 2.15 CPU): overlap 0 -> ~0.7 of the largest correction; overlap 200 -> ~1e-4
    # (float32 rounding of acc ~ 9.8 m/s^2 is ~1e-6)
    assert diff[0] > 0.05, diff
    assert diff[200] < 1e-3, diff


def test_causal_sequential_windows_equal_the_whole_causal_forward_exactly(imu):
    _t, g, a = imu
    m = random_model(causal=True)
    ref = whole_pass(m, g, a)
    for w in (1000, 333):
        rg, ra = refine_arrays(m, g, a, window=w, overlap=200)
        np.testing.assert_array_equal(np.c_[rg, ra], ref)


def test_zero_correction_returns_the_input_bit_for_bit(imu):
    _t, g, a = imu
    m = ImuRefiner(ModelConfig()).eval()  # zero head: the identity map
    rg, ra = refine_arrays(m, g, a)
    np.testing.assert_array_equal(rg, g)
    np.testing.assert_array_equal(ra, a)


@pytest.fixture()
def ckpt(tmp_path):
    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, random_model(), {"test": True}, epoch=1, step=10, best_metric=None)
    return path


def test_cli_refines_an_asl_folder(tmp_path, ckpt, imu):
    src = tmp_path / "V1_01_easy"
    shutil.copytree(CROP, src)
    before = {p: sha(p) for p in src.rglob("*") if p.is_file()}
    out = tmp_path / "out"
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    r = subprocess.run(
        [sys.executable, "-m", "imu_learn.refine", "--checkpoint", str(ckpt), "--input", str(src), "--out", str(out),
         "--window", "1000", "--overlap", "200", "--device", "cpu", "--quiet"],
        capture_output=True, text=True, env=env, timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert {p: sha(p) for p in src.rglob("*") if p.is_file()} == before  # input untouched
    written = out / IMU_REL
    assert sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file()) == [IMU_REL, Path("summary.json")]
    orig_lines = (src / IMU_REL).read_text().splitlines()
    new_lines = written.read_text().splitlines()
    assert new_lines[0] == orig_lines[0]  # the original header line
    assert len(new_lines) == len(orig_lines)
    assert [line.split(",")[0] for line in new_lines] == [line.split(",")[0] for line in orig_lines]
    t, g, a = imu
    t2, g2, a2 = core.read_asl_imu(str(written))
    np.testing.assert_array_equal(t2, t)
    from imu_learn.infer.checkpoint import load_model

    rg, ra = refine_arrays(load_model(ckpt), g, a, window=1000, overlap=200)
    np.testing.assert_array_equal(g2, rg)  # shortest round-trip text: exact
    np.testing.assert_array_equal(a2, ra)
    assert np.abs(g2 - g).max() > 1e-4


def test_cli_copy_folder_csv_output_and_refusals(tmp_path, ckpt, capsys):
    src = tmp_path / "seq"
    shutil.copytree(CROP, src)
    before = sha(src / IMU_REL)
    # --copy-folder: the whole sequence, IMU replaced
    out = tmp_path / "copy"
    assert main(["--checkpoint", str(ckpt), "--input", str(src), "--out", str(out), "--copy-folder", "--quiet"]) == 0
    assert (out / "groundtruth_pose.tum").read_bytes() == (src / "groundtruth_pose.tum").read_bytes()
    assert (out / "mav0" / "imu0" / "sensor.yaml").exists() and sha(out / IMU_REL) != before
    # a .csv input and a .csv output
    csv_out = tmp_path / "refined.csv"
    assert main(["--checkpoint", str(ckpt), "--input", str(src / IMU_REL), "--out", str(csv_out), "--quiet"]) == 0
    assert csv_out.read_bytes() == (out / IMU_REL).read_bytes()
    capsys.readouterr()
    # OUT == IN, as a folder and as the file itself: refused, input untouched
    for o in (src, src / IMU_REL):
        assert main(["--checkpoint", str(ckpt), "--input", str(src), "--out", str(o), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "input" in err
    assert main(["--checkpoint", str(ckpt), "--input", str(src), "--out", str(src / "x"), "--copy-folder"]) == 2
    capsys.readouterr()
    assert sha(src / IMU_REL) == before


def test_bad_checkpoint_is_one_line_exit_2(tmp_path, capsys):
    src = tmp_path / "seq"
    shutil.copytree(CROP, src)
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint at all")
    for ck in (bad, tmp_path / "missing.pt"):
        assert main(["--checkpoint", str(ck), "--input", str(src), "--out", str(tmp_path / "o")]) == 2
        cap = capsys.readouterr()
        assert cap.err.count("\n") == 1 and cap.err.startswith("imu-learn refine: error: "), cap.err
    assert not (tmp_path / "o").exists()
    # and through the real entry point
    r = subprocess.run(
        [sys.executable, "-m", "imu_learn.refine", "--checkpoint", str(bad), "--input", str(src), "--out",
         str(tmp_path / "o")], capture_output=True, text=True, env=dict(os.environ, OMP_NUM_THREADS="1"), timeout=120,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "checkpoint" in r.stderr


# ---- other formats, on small fixtures in their documented layouts ---------------------------


def _raw(n, seed=1):
    rng = np.random.default_rng(seed)
    return rng.normal(0, 0.3, (n, 3)), rng.normal([0, 0, 9.81], 0.5, (n, 3))


def test_kaist_keeps_every_other_column(tmp_path, ckpt):
    n = 300
    g, a = _raw(n)
    root = tmp_path / "urban"
    (root / "sensor_data").mkdir(parents=True)
    t_ns = 1_544_590_798_711_913_000 + np.arange(n, dtype=np.int64) * 10_000_000
    with open(root / "sensor_data" / "xsens_imu.csv", "w") as f:
        for i in range(n):
            row = [0, 0, 0.1, 0.995, 0.01, 0.02, 0.2, *g[i], *a[i], 0.11, 0.22, 0.33]
            f.write(f"{t_ns[i]}," + ",".join(f"{x:.9g}" for x in row) + "\n")
    before = (root / "sensor_data" / "xsens_imu.csv").read_text()
    out = tmp_path / "out"
    assert main(["--checkpoint", str(ckpt), "--input", str(root), "--out", str(out), "--quiet", "--window", "128",
                 "--overlap", "32"]) == 0
    assert (root / "sensor_data" / "xsens_imu.csv").read_text() == before
    new = list(csv.reader(open(out / "sensor_data" / "xsens_imu.csv")))
    old = list(csv.reader(before.splitlines()))
    assert len(new) == len(old) == n
    for r0, r1 in zip(old, new):
        assert len(r1) == 17 and r1[:8] == r0[:8] and r1[14:] == r0[14:]
    g0 = np.array([[float(x) for x in r[8:11]] for r in old])
    a0 = np.array([[float(x) for x in r[11:14]] for r in old])
    from imu_learn.infer.checkpoint import load_model

    rg, ra = refine_arrays(load_model(ckpt), g0, a0, window=128, overlap=32)
    _t, g1, a1 = core.read_kaist_imu(str(out / "sensor_data" / "xsens_imu.csv"))
    np.testing.assert_array_equal(g1, rg)
    np.testing.assert_array_equal(a1, ra)


def test_blackbird_hdf5_copy_with_imu_replaced(tmp_path, ckpt):
    h5py = pytest.importorskip("h5py")
    n = 256
    g, a = _raw(n, 2)
    src = tmp_path / "bb"
    src.mkdir()
    with h5py.File(src / "data.hdf5", "w") as f:
        f["ts"] = 1.5e9 + np.arange(n) * 0.01
        f["gyro_raw"] = g
        f["accel_raw"] = a
        f["gt_p"] = np.ones((n, 3))
        f["gyro_raw"].attrs["unit"] = "rad/s"
    before = sha(src / "data.hdf5")
    out = tmp_path / "out"
    assert main(["--checkpoint", str(ckpt), "--input", str(src), "--out", str(out), "--quiet"]) == 0
    assert sha(src / "data.hdf5") == before
    from imu_learn.infer.checkpoint import load_model

    rg, ra = refine_arrays(load_model(ckpt), g, a)
    with h5py.File(out / "data.hdf5", "r") as f:
        np.testing.assert_array_equal(f["gyro_raw"][:], rg)
        np.testing.assert_array_equal(f["accel_raw"][:], ra)
        np.testing.assert_array_equal(f["ts"][:], 1.5e9 + np.arange(n) * 0.01)
        np.testing.assert_array_equal(f["gt_p"][:], np.ones((n, 3)))
        assert f["gyro_raw"].attrs["unit"] == "rad/s"


def test_broad_mat_copy_with_imu_replaced(tmp_path, ckpt):
    scipy_io = pytest.importorskip("scipy.io")
    n = 256
    g, a = _raw(n, 3)
    q = np.tile([1.0, 0, 0, 0], (n, 1))
    q[10:20] = np.nan
    src = tmp_path / "01_trial.mat"
    scipy_io.savemat(src, {"imu_gyr": g, "imu_acc": a, "opt_quat": q, "opt_pos": np.zeros((n, 3)),
                           "sampling_rate": 286.0})
    before = sha(src)
    out = tmp_path / "out"
    assert main(["--checkpoint", str(ckpt), "--input", str(src), "--out", str(out), "--quiet"]) == 0
    assert sha(src) == before
    m = scipy_io.loadmat(out / "01_trial.mat")
    from imu_learn.infer.checkpoint import load_model

    rg, ra = refine_arrays(load_model(ckpt), g, a)
    np.testing.assert_array_equal(m["imu_gyr"], rg)
    np.testing.assert_array_equal(m["imu_acc"], ra)
    np.testing.assert_array_equal(m["opt_quat"], q)
    assert float(m["sampling_rate"].ravel()[0]) == 286.0
    # OUT == IN for a file input: refused
    assert main(["--checkpoint", str(ckpt), "--input", str(src), "--out", str(src), "--quiet"]) == 2
    assert sha(src) == before
