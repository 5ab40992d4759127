"""``imu-learn refine`` on a user's own CSV and with a device profile: a Fetch crop rewritten with other
column names and order, deg/s, g and float seconds comes back with the same header, columns and
units, its values the refined ones (by a model, by a profile's floor, by a model carrying its
profile); the same options on ``imu-learn groundtruth``; a user's CSV needs its reference file."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from imu_learn import _imu_core as core
from imu_learn.calib.profile import Affine, Profile
from imu_learn.cli.groundtruth import main as groundtruth_main
from imu_learn.cli.refine import main as refine_main
from imu_learn.data.formats import read_imu_source, read_recording
from imu_learn.data.formats.csv_columns import STANDARD_GRAVITY, CsvColumns, read_csv_columns
from imu_learn.errors import InvalidInputError
from imu_learn.infer.checkpoint import load_model, save_checkpoint
from imu_learn.infer.refiner import refine_arrays
from imu_learn.nn.model import ImuRefiner, ModelConfig

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
EUROC = REPO / "datasets" / "euroc" / "MH_04_difficult"
GT = EUROC / "mav0" / "state_groundtruth_estimate0" / "data.csv"
FETCH_MODEL = REPO / "models" / "fetch_debias.pt"
IMU_REL = Path("mav0") / "imu0" / "data.csv"
USER = CsvColumns("t,_,gz,gy,gx,az,ay,ax", "s", "deg/s", "g")
USER_ARGS = ["--columns", USER.columns, "--time-unit", "s", "--gyro-unit", "deg/s", "--acc-unit", "g"]
HEADER = "time_s;temp_C;wz_dps;wy_dps;wx_dps;az_g;ay_g;ax_g;status"


def user_csv(path: Path, every: int = 2, n: int = 1200) -> Path:
    """The EuRoC crop's motion at 100 Hz (every other sample, as the Fetch robot records), exported
    as a user would: semicolons, other names and order, a text column, deg/s, g, float seconds, a
    comment and a trailing column the map leaves out."""
    t, g, a = core.read_asl_imu(str(EUROC / IMU_REL))
    t, g, a = t[: n * every : every], g[: n * every : every], a[: n * every : every]
    lines = ["# exported from the robot", HEADER]
    for k in range(len(t)):
        gd, ag = np.degrees(g[k][::-1]), a[k][::-1] / STANDARD_GRAVITY
        lines.append(";".join([f"{t[k] // 10**9}.{t[k] % 10**9:09d}", "31.5", *(repr(float(x)) for x in (*gd, *ag)),
                               "ok"]))
    path.write_text("\n".join(lines) + "\n")
    return path


def floor_profile(device: str = "fetch-imu", rate: float = 100.0) -> Profile:
    """A profile whose floor changes the data: scale, misalignment, biases and a time offset."""
    from imu_learn.baselines.traditional import TraditionalTiming

    rng = np.random.default_rng(3)
    m = TraditionalTiming()
    p = m.params
    p.M_g = np.eye(3) + 0.01 * rng.standard_normal((3, 3))
    p.b_g = 0.01 * rng.standard_normal(3)
    p.M_a = np.eye(3) + 0.01 * rng.standard_normal((3, 3))
    p.b_a = 0.1 * rng.standard_normal(3)
    p.cutoff_gyro, p.cutoff_acc = 20.0, None
    p.time_offset = 0.4
    fl = m.to_dict()
    return Profile(device=device, sample_rate_hz=rate, time_offset_s=0.4 / rate, time_offset_s_std=math.nan,
                   gyro=Affine(np.asarray(fl["M_g"]), np.asarray(fl["b_g"]), "rad/s"),
                   acc=Affine(np.asarray(fl["M_a"]), np.asarray(fl["b_a"]), "m/s^2"),
                   g_sensitivity=np.asarray(fl["G"]), gravity_mps2=9.81, gravity_mps2_std=math.nan, floor=fl)


def assert_kept_as_the_users(src: Path, out: Path, gyro: np.ndarray, acc: np.ndarray) -> None:
    """``out`` has ``src``'s comment, header, time and other columns as text, and holds ``gyro``,
    ``acc`` [rad/s, m/s^2] in the file's own units (deg/s, g)."""
    old, new = src.read_text().splitlines(), out.read_text().splitlines()
    assert new[:2] == old[:2] and len(new) == len(old)
    for a, b in zip(old[2:], new[2:]):
        fa, fb = a.split(";"), b.split(";")
        assert len(fb) == len(fa) and fb[:2] == fa[:2] and fb[-1] == fa[-1]
    back = read_csv_columns(out, *USER.args())
    np.testing.assert_allclose(back.gyro, gyro, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(back.acc, acc, rtol=1e-13, atol=1e-14)
    raw = np.array([[float(x) for x in line.split(";")[2:8]] for line in new[2:]])
    np.testing.assert_allclose(raw[:, :3], np.degrees(gyro[:, ::-1]), rtol=1e-13, atol=1e-12)  # deg/s, z y x
    np.testing.assert_allclose(raw[:, 3:], acc[:, ::-1] / STANDARD_GRAVITY, rtol=1e-13, atol=1e-14)  # g


def test_a_users_csv_refined_by_a_model_keeps_its_columns_and_units(tmp_path, capsys):
    src = user_csv(tmp_path / "mine.csv")
    before = src.read_bytes()
    out = tmp_path / "refined.csv"
    assert refine_main(["--checkpoint", str(FETCH_MODEL), "--input", str(src), "--out", str(out), "--quiet",
                        *USER_ARGS]) == 0
    assert src.read_bytes() == before
    raw = read_csv_columns(src, *USER.args())
    g, a = refine_arrays(load_model(FETCH_MODEL), raw.gyro, raw.acc)
    assert np.abs(g - raw.gyro).max() > 1e-5
    assert_kept_as_the_users(src, out, g, a)
    assert "100 Hz" in capsys.readouterr().out
    # a folder OUT gets the file's own name
    assert refine_main(["--checkpoint", str(FETCH_MODEL), "--input", str(src), "--out", str(tmp_path / "d"),
                        "--quiet", *USER_ARGS]) == 0
    assert (tmp_path / "d" / "mine.csv").read_bytes() == out.read_bytes()


def test_a_users_csv_through_a_profile_is_the_floor_without_torch(tmp_path, capsys):
    src = user_csv(tmp_path / "mine.csv")
    prof = floor_profile()
    prof.save(tmp_path / "profile.json")
    out = tmp_path / "floor.csv"
    assert refine_main(["--profile", str(tmp_path / "profile.json"), "--input", str(src), "--out", str(out),
                        *USER_ARGS]) == 0
    cap = capsys.readouterr()
    assert cap.err == "" and "floor of profile" in cap.out and "'fetch-imu', 100 Hz" in cap.out
    raw = read_csv_columns(src, *USER.args())
    g, a = prof.apply(raw.t_ns, raw.gyro, raw.acc)
    assert np.abs(g - raw.gyro).max() > 1e-4
    assert_kept_as_the_users(src, out, g, a)
    # the profile's rate is checked like a model's; the device named by the user is too
    assert refine_main(["--profile", str(tmp_path / "profile.json"), "--input", str(EUROC), "--out",
                        str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "200 Hz" in err and "100 Hz" in err
    assert refine_main(["--profile", str(tmp_path / "profile.json"), "--input", str(src), "--out",
                        str(tmp_path / "o2.csv"), "--imu-name", "other-imu", "--quiet", *USER_ARGS]) == 0
    assert "'other-imu'" in capsys.readouterr().err
    # no torch: the floor is numpy and scipy
    code = ("import sys; from imu_learn.cli.refine import main; "
            f"rc = main(['--profile', {str(tmp_path / 'profile.json')!r}, '--input', {str(src)!r}, '--out', "
            f"{str(tmp_path / 'o3.csv')!r}, '--quiet', *{USER_ARGS!r}]); "
            "assert rc == 0 and 'torch' not in sys.modules, sorted(m for m in sys.modules if 'torch' in m)[:3]")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "o3.csv").read_bytes() == out.read_bytes()


def test_a_model_carrying_its_profile_applies_it_first(tmp_path, capsys):
    src = user_csv(tmp_path / "mine.csv")
    prof = floor_profile()
    torch.manual_seed(0)
    model = ImuRefiner(ModelConfig(hidden=8, fc=8, layers=1))
    with torch.no_grad():
        torch.nn.init.normal_(model.head.weight, std=0.3)
    ck = tmp_path / "learned.pt"
    save_checkpoint(ck, model.eval(), {"data": {"window": 100}}, 1, 1, None,
                    record={"sample_rate_hz": 100.0, "device": "fetch-imu", "profile": prof.to_dict()})
    out = tmp_path / "learned.csv"
    assert refine_main(["--checkpoint", str(ck), "--input", str(src), "--out", str(out), "--quiet", *USER_ARGS]) == 0
    assert "after its profile" in capsys.readouterr().out
    raw = read_csv_columns(src, *USER.args())
    g0, a0 = prof.apply(raw.t_ns, raw.gyro, raw.acc)
    g, a = refine_arrays(load_model(ck), g0, a0)
    assert_kept_as_the_users(src, out, g, a)


def test_the_resolver_and_its_refusals(tmp_path, capsys):
    src = user_csv(tmp_path / "mine.csv")
    s = read_imu_source(src, columns=USER)
    assert (s.fmt, s.layout) == ("csv-columns", USER)
    assert read_imu_source(src, "csv-columns", columns=USER).layout == USER
    with pytest.raises(InvalidInputError, match="fetch format has its own layout"):
        read_imu_source(src, "fetch", columns=USER)
    with pytest.raises(InvalidInputError, match="only apply to ROS bags"):
        read_imu_source(src, imu_topic="/imu", columns=USER)
    with pytest.raises(InvalidInputError, match="--groundtruth"):
        read_recording(src, columns=USER)
    with pytest.raises(InvalidInputError, match="one file"):
        read_imu_source(tmp_path, columns=USER)
    # a bad map is one line naming it, exit 2
    assert refine_main(["--checkpoint", str(FETCH_MODEL), "--input", str(src), "--out", str(tmp_path / "o.csv"),
                        "--columns", "t,_,gz,gy,gx,az,ay"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "ax" in err


def test_groundtruth_reads_a_users_csv_as_its_own_layout(tmp_path, capsys):
    src = user_csv(tmp_path / "mine.csv", every=1, n=12001)  # 200 Hz, all of the crop
    assert groundtruth_main(["--input", str(EUROC)]) == 0
    own = capsys.readouterr().out.splitlines()
    assert groundtruth_main(["--input", str(src), "--groundtruth", str(GT), *USER_ARGS]) == 0
    mine = capsys.readouterr().out.splitlines()
    assert mine[1:-1] == own[1:-1]  # the same figures; only the names differ
    assert groundtruth_main(["--input", str(src), *USER_ARGS]) == 2
    assert "--groundtruth" in capsys.readouterr().err


def test_model_check_on_a_users_csv_is_the_folders(tmp_path):
    from imu_learn.infer.model_check import compare_with_raw

    src = user_csv(tmp_path / "mine.csv", every=1, n=12001)
    ckpt = REPO / "models" / "euroc_adis16448.pt"
    mine = compare_with_raw(ckpt, src, groundtruth=GT, columns=USER)
    own = compare_with_raw(ckpt, EUROC, "euroc", groundtruth=GT)
    assert mine["samples"] == own["samples"]
    for proto in own["ratio"]:
        for n in own["ratio"][proto]:
            assert mine["ratio"][proto][n] == pytest.approx(own["ratio"][proto][n], rel=1e-9)
