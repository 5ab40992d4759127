"""A profile.json is applied only as calibrate could have written it: its derived fields agree with its floor
(a hand-edited profile whose blocks were swapped was applied as one thing and read as another), its floor
inside calibrate's plausibility limits (refine refuses, --force applies with a warning), and evaluate's
``profile:`` method gets refine's checks (the reader, the limits, the rate)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from imu_learn.calib.profile import Profile
from imu_learn.cli.refine import main as refine_main
from imu_learn.data.types import Segment
from imu_learn.errors import ImplausibleProfileError, InvalidInputError, ProfileError
from imu_learn.eval.run import check_profiles

REPO = Path(__file__).resolve().parent.parent
EUROC = REPO / "models" / "profiles" / "euroc_adis16448" / "profile.json"
FETCH = REPO / "models" / "profiles" / "fetch_debias" / "profile.json"
CROP = REPO / "datasets" / "euroc" / "MH_04_difficult"


def edited(tmp_path: Path, name: str, edit) -> Path:
    d = json.loads(EUROC.read_text())
    edit(d)
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(d))
    return path


def swap_blocks(d):
    d["gyroscope"], d["accelerometer"] = d["accelerometer"], d["gyroscope"]


def swap_biases(d):  # both sides, consistently: the floor's gyro bias becomes the acc's 0.12
    f = d["floor"]
    f["b_g"], f["b_a"] = f["b_a"], f["b_g"]
    d["gyroscope"]["bias"], d["accelerometer"]["bias"] = f["b_g"], f["b_a"]


def test_derived_fields_that_disagree_with_the_floor_are_refused(tmp_path):
    with pytest.raises(ProfileError, match="field 'gyroscope.bias' disagrees with 'floor.b_g'"):
        Profile.load(edited(tmp_path, "swapped", swap_blocks))
    Profile.load(EUROC)  # as shipped: consistent


def test_refine_refuses_an_implausible_floor_unless_forced(tmp_path, capsys):
    path = edited(tmp_path, "implausible", swap_biases)
    base = ["--profile", str(path), "--input", str(CROP)]
    assert refine_main(base + ["--out", str(tmp_path / "out")]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "ImplausibleProfileError" in err[0] and "field 'gyroscope.bias'" in err[0], err
    assert "--force" in err[0] and not (tmp_path / "out").exists()
    assert refine_main(base + ["--out", str(tmp_path / "forced"), "--force"]) == 0
    assert "applied (--force)" in capsys.readouterr().err


def test_evaluate_profile_method_gets_refines_checks(tmp_path):
    t = np.arange(0, 20_000_000_000, 5_000_000, dtype=np.int64)  # 200 Hz
    z = np.zeros((len(t), 3))
    seg = Segment("MH_04_difficult", t, z, z + [0.0, 0.0, 9.81], z, z, np.tile([1.0, 0, 0, 0], (len(t), 1)))
    check_profiles([f"profile:{EUROC}"], ["MH_04_difficult"], [seg])  # its rate, plausible: scored
    with pytest.raises(InvalidInputError, match="is for 100 Hz"):
        check_profiles([f"profile:{FETCH}"], ["MH_04_difficult"], [seg])
    with pytest.raises(ImplausibleProfileError, match="gyroscope.bias"):
        check_profiles([f"profile:{edited(tmp_path, 'implausible', swap_biases)}"], ["MH_04_difficult"], [seg])
    with pytest.raises(ProfileError, match="disagrees"):
        check_profiles([f"profile:{edited(tmp_path, 'swapped', swap_blocks)}"], ["MH_04_difficult"], [seg])


def test_apply_refuses_stamps_it_would_resample_wrongly():
    """Profile.apply on arrays: float seconds (truncated to int64 they were all 0 or 1), repeated or
    reversed stamps and rows that do not match them gave finite, wrong output (up to 2 rad/s off);
    each is now refused naming the argument. Right stamps give the same bits as before."""
    prof = Profile.load(EUROC)
    n = 400
    t = np.arange(n, dtype=np.int64) * 5_000_000
    rng = np.random.default_rng(0)
    g, a = rng.standard_normal((n, 3)), rng.standard_normal((n, 3)) + [0.0, 0.0, 9.81]
    out = prof.apply(t, g, a)
    assert np.array_equal(out[0], prof.floor.apply(t, g, a)[0])
    for bad, says in ((t * 1e-9, "integer nanoseconds"), (np.r_[t[:10], t[9:-1]], r"t_ns\[10\]"),
                      (t[::-1].copy(), r"t_ns\[1\]")):
        with pytest.raises(InvalidInputError, match=says):
            prof.apply(bad, g, a)
    with pytest.raises(InvalidInputError, match=r"gyro must be \(400, 3\)"):
        prof.apply(t, g[:, :2], a)
