"""A gyro unit the profile's own device contradicts stops refine before any work: rad/s columns declared
as deg/s read 57x too small, which the input checks alone cannot tell from a recording that barely turns,
but whose per-axis medians (the device's bias) then lie outside what the profile's training recordings
read and inside it in the other unit (:func:`imu_learn.infer.guard.unit_mistake`)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.cli.refine import main as refine_main
from imu_learn.infer import guard

REPO = Path(__file__).resolve().parent.parent
CROP = REPO / "datasets" / "euroc" / "MH_04_difficult" / "mav0" / "imu0" / "data.csv"
PROFILE = REPO / "models" / "profiles" / "euroc_adis16448" / "profile.json"
BIAS = np.array([-0.002, 0.021, 0.078])  # rad/s, EuRoC's ADIS16448 (about)


def training(n: int = 3, seed: int = 0):
    """Training statistics of ``n`` recordings of a device with gyro bias :data:`BIAS` turning at ~0.3 rad/s."""
    rng = np.random.default_rng(seed)
    recs = []
    for i in range(n):
        g = BIAS + 0.002 * i + 0.3 * rng.standard_normal((4000, 3))
        a = np.array([0.0, 0.0, 9.81]) + 0.5 * rng.standard_normal((4000, 3))
        recs.append((f"r{i}", None, g, a))
    return guard.training_inputs(recs)


def recording(seed: int = 7) -> np.ndarray:
    return BIAS + 0.3 * np.random.default_rng(seed).standard_normal((4000, 3))


def test_rad_s_columns_declared_deg_s_are_named_by_the_device_bias():
    g = recording() * math.pi / 180.0  # rad/s values read as deg/s, converted to "rad/s"
    line = guard.unit_mistake(training(), g, "deg/s", "profile P")
    assert line is not None and "drop --gyro-unit deg/s" in line and "axis z" in line


def test_deg_s_columns_read_as_rad_s_are_named_too():
    g = recording() * 180.0 / math.pi  # deg/s values read as rad/s
    line = guard.unit_mistake(training(), g, "rad/s", "profile P")
    assert line is not None and "add --gyro-unit deg/s" in line


def test_no_line_where_the_unit_fits_or_nothing_was_declared_or_another_device_is_unexplained():
    tr = training()
    assert guard.unit_mistake(tr, recording(), "rad/s", "P") is None  # the right unit
    assert guard.unit_mistake(tr, recording() * math.pi / 180.0, None, "P") is None  # the format fixes the unit
    assert guard.unit_mistake(None, recording() * math.pi / 180.0, "deg/s", "P") is None  # no statistics
    other = np.array([0.0, 0.0, -0.5]) + 0.3 * np.random.default_rng(1).standard_normal((4000, 3))
    assert guard.unit_mistake(tr, other, "deg/s", "P") is None  # outside as read, and outside x57.3 as well


def user_csv(path: Path, n: int = 4000) -> Path:
    """The shipped EuRoC crop as a user's CSV in its own units (ns, rad/s, m/s^2)."""
    t, g, a = core.read_asl_imu(str(CROP))
    rows = [f"{t[k]},{','.join(repr(float(x)) for x in (*g[k], *a[k]))}" for k in range(min(n, len(t)))]
    path.write_text("t,gx,gy,gz,ax,ay,az\n" + "\n".join(rows) + "\n")
    return path


def test_refine_refuses_rad_s_declared_deg_s_with_the_profile_and_writes_nothing(tmp_path, capsys):
    src = user_csv(tmp_path / "imu.csv")
    out = tmp_path / "out.csv"
    args = ["--profile", str(PROFILE), "--input", str(src), "--out", str(out), "--columns", "t,gx,gy,gz,ax,ay,az",
            "--time-unit", "ns"]
    assert refine_main(args + ["--gyro-unit", "deg/s"]) == 2
    err = capsys.readouterr().err
    assert "drop --gyro-unit deg/s" in err and "--force" in err, err
    assert not out.exists()
    assert refine_main(args) == 0  # declared right: refined
    assert out.is_file()


def test_force_applies_it_with_the_line_as_a_warning(tmp_path, capsys):
    src = user_csv(tmp_path / "imu.csv")
    out = tmp_path / "out.csv"
    assert refine_main(["--profile", str(PROFILE), "--input", str(src), "--out", str(out), "--columns",
                        "t,gx,gy,gz,ax,ay,az", "--time-unit", "ns", "--gyro-unit", "deg/s", "--force"]) == 0
    assert "(applied: --force)" in capsys.readouterr().err
    assert out.is_file()
