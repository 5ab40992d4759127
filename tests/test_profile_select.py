"""A device profile's terms chosen on held-out recordings (calib.select), on synthetic devices of known
errors: three recordings of rich motion (exact IMU under the zero-order hold, white noise added), seen
through a gyro and accelerometer with a bias only, or with a bias and a real scale error. Also the
rule itself on a table made by hand, and evaluate's ``profile:PATH`` method."""
from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from imu_learn.baselines.affine import TraditionalParams
from imu_learn.baselines.base import FitSettings
from imu_learn.core.integration import preintegrate
from imu_learn.core.quat import quat_conj, quat_rotate
from imu_learn.data import synthetic as syn
from imu_learn.data.splits import cut
from imu_learn.data.types import Segment
from imu_learn.errors import ConfigError
from imu_learn.eval.run import check_profiles
from imu_learn.score.metrics import simulate_sequence
from imu_learn.util.helper import Split

pytest.importorskip("torch")
from imu_learn.calib import select as sel  # noqa: E402  (torch)

BIAS_G, BIAS_A = np.array([0.01, -0.02, 0.015]), np.array([0.1, -0.05, 0.08])
SCALE_G, SCALE_A = np.diag([1.03, 0.97, 1.02]), np.diag([1.02, 0.98, 1.01])
OPTS = sel.SelectOptions(max_windows=200, startup_bias_s=5.0)
SETTINGS = FitSettings(horizons=(10, 200))


def smooth(rng: np.random.Generator, t: np.ndarray, amp: float) -> np.ndarray:
    """(N, 3): four sinusoids per axis, 0.2-2.5 Hz, amplitude up to ``amp``."""
    f, ph, a = rng.uniform(0.2, 2.5, (3, 4)), rng.uniform(0, 2 * np.pi, (3, 4)), rng.uniform(0.3, 1, (3, 4)) * amp / 2
    return np.stack([(a[i, :, None] * np.sin(2 * np.pi * f[i, :, None] * t + ph[i, :, None])).sum(0)
                     for i in range(3)], 1)


def recording(seed: int, M_g: np.ndarray, M_a: np.ndarray, seconds: float = 30.0) -> Segment:
    """Ground truth from the true IMU; the recorded IMU through w = M_g (w_m - b_g), a = M_a (a_m - b_a)."""
    rng = np.random.default_rng(seed)
    t_ns = syn.stamps(seconds)
    t = (t_ns - t_ns[0]) * 1e-9
    gyro = smooth(rng, t, 1.0)
    q = preintegrate(t_ns, gyro, np.zeros_like(gyro)).dq_wxyz
    acc = quat_rotate(quat_conj(q), np.tile([0.0, 0.0, 9.81], (len(t), 1))) + smooth(rng, t, 2.0)
    s = simulate_sequence(t_ns, gyro, acc, name=f"rec{seed}")
    g_m = gyro @ np.linalg.inv(M_g).T + BIAS_G + 1e-3 * rng.standard_normal(gyro.shape)
    a_m = acc @ np.linalg.inv(M_a).T + BIAS_A + 1e-2 * rng.standard_normal(acc.shape)
    return Segment(s.name, s.t_ns, g_m, a_m, s.p, s.v, s.q_wxyz)


def device(scale: bool):
    """(train, val, groups, val_groups): three recordings, each's last 15 % its validation block."""
    M_g, M_a = (SCALE_G, SCALE_A) if scale else (np.eye(3), np.eye(3))
    recs = [recording(i, M_g, M_a) for i in range(3)]
    names = [r.name for r in recs]
    return ([cut([r], 0.0, 0.85, r.name)[0] for r in recs], [cut([r], 0.85, 1.0, r.name)[0] for r in recs],
            names, names)


@pytest.fixture(scope="module")
def bias_only():
    return sel.select_levels(*device(False), SETTINGS, OPTS)


@pytest.fixture(scope="module")
def scaled():
    return sel.select_levels(*device(True), SETTINGS, OPTS)


def beaten(selection: sel.Selection, sensor: str) -> list:
    """Every held-out cell where a level simpler than the chosen one beats it by more than the tolerance."""
    levels = sel.GYRO_LEVELS if sensor == "gyro" else sel.ACC_LEVELS
    chosen = getattr(selection, sensor)
    table = selection.figures[sensor]
    out = []
    for simpler in levels[:levels.index(chosen)]:
        for fold, cells in table[chosen].items():
            for cell, v in cells.items():
                if cell.startswith(sel.CELLS[sensor]) and v > (1 + sel.WORSE) * table[simpler][fold][cell]:
                    out.append((simpler, fold, cell))
    return out


def test_a_device_with_only_a_bias_selects_the_bias(bias_only):
    assert (bias_only.gyro, bias_only.acc) == ("bias", "bias"), bias_only.steps
    assert bias_only.kind == "leave one recording out" and len(bias_only.folds) == 3


def test_a_device_with_a_scale_error_selects_scale_or_affine(scaled):
    assert scaled.gyro in ("scale", "affine"), scaled.steps["gyro"]
    assert scaled.acc in ("scale", "affine"), scaled.steps["acc"]
    # the scale pays on the held-out recordings: 20 s of rotation at 3 % off, against the bias level
    t = scaled.figures["gyro"]
    assert all(t[scaled.gyro][f]["aoe_deg"] < 0.5 * t["bias"][f]["aoe_deg"] for f in t["bias"])


def test_the_chosen_level_is_never_beaten_by_a_simpler_one(bias_only, scaled):
    for s in (bias_only, scaled):
        for sensor in ("gyro", "acc"):
            assert beaten(s, sensor) == []
            assert all(math.isfinite(v) for cells in s.figures[sensor][getattr(s, sensor)].values()
                       for v in cells.values())


def selections(monkeypatch, split_class) -> tuple:
    """The bias-only device's selection with its folds split by ``split_class`` (a helper process forced),
    and with every fold in this process."""
    data = device(False)
    out = []
    for make in (lambda items, **kw: split_class(items, helper=True), lambda items, **kw: Split(items, helper=False)):
        monkeypatch.setattr(sel, "Split", make)
        out.append(sel.select_levels(*data, SETTINGS, OPTS))
    return tuple(out)


def test_the_folds_split_with_a_helper_process_give_the_figures_of_one_process(monkeypatch):
    """The folds on two processes (the default on two cores) and all in this one: the same table."""
    split, alone = selections(monkeypatch, Split)
    assert split.figures == alone.figures and split.folds == alone.folds
    assert (split.gyro, split.acc, split.steps) == (alone.gyro, alone.acc, alone.steps)


class LosesItsHelper(Split):
    """A Split whose helper process is killed while it works on its folds (once this process has made
    its folds' scoring jobs): its folds end up run, and scored, here."""

    def step_and_share(self, fn, args, on_item=lambda i: None, then=None):
        def kill_then(done):
            if self._helper is not None:
                self._helper.proc.kill()
                self._helper.proc.wait()
            return then(done)

        return super().step_and_share(fn, args, on_item, kill_then)


def test_a_helper_lost_mid_selection_leaves_the_same_figures(monkeypatch):
    lost, alone = selections(monkeypatch, LosesItsHelper)
    assert lost.figures == alone.figures and (lost.gyro, lost.acc) == (alone.gyro, alone.acc)


def test_the_rule_on_a_table_by_hand():
    """bias gains 50 % on fold a; scale gains 3 % on fold a but is 2 % worse on fold b than bias:
    beaten, skipped; affine gains 3 % and 2 % over bias, no worse than any simpler level (the skipped
    scale included): chosen; g-sensitivity gains 0.5 % only: not enough; lowpass is 0.3 % worse than
    affine in one cell (within the tolerance) and 1.5 % better in the other: chosen."""
    def row(a: float, b: float):
        return {"a": {"rot_deg n=10": a, "open_trans_m n=10": 9.0}, "b": {"rot_deg n=10": b}}

    table = {"offset": row(2.0, 1.0), "bias": row(1.0, 1.0), "scale": row(0.97, 1.02), "affine": row(0.97, 0.98),
             "g_sensitivity": row(0.97, 0.98 * 0.995), "lowpass": row(0.97 * 1.003, 0.98 * 0.985)}
    chosen, steps = sel.choose(sel.GYRO_LEVELS, table, sel.CELLS["gyro"])
    assert chosen == "lowpass"
    assert [s["chosen"] for s in steps] == [True, False, True, False, True]
    table["lowpass"]["a"]["rot_deg n=10"] = 0.97 * 1.006  # 0.6 % worse than affine: beaten
    assert sel.choose(sel.GYRO_LEVELS, table, sel.CELLS["gyro"])[0] == "affine"
    assert steps[1]["worst_vs_simpler"]["fold"] == "b" and steps[1]["worst_vs_simpler"]["ratio"] == pytest.approx(1.02)


def test_the_floor_at_the_bias_level_fits_the_biases_alone():
    train, val, groups, _ = device(False)
    floor = sel.fit_at_levels(train, val, SETTINGS, ("bias", "bias"), 0.0, OPTS)
    p = floor.params
    assert np.array_equal(p.M_g, np.eye(3)) and np.array_equal(p.G, np.zeros((3, 3))) and np.array_equal(p.M_a, np.eye(3))
    assert p.cutoff_gyro is None and p.cutoff_acc is None
    assert np.abs(p.b_g - BIAS_G).max() < 1e-3 and np.abs(p.b_a - BIAS_A).max() < 2e-2, (p.b_g, p.b_a)


def test_the_spread_at_the_chosen_levels_is_that_of_each_recordings_bias():
    """A profile's standard deviations at the chosen levels: each recording refitted alone at them, the
    standard error of their mean (the oracle: the biases each recording was given, here 4-8 mrad/s apart
    on the gyro, 0.1 m/s^2 on the accelerometer); the terms the levels hold at their prior get none."""
    train, val, groups, val_groups = device(False)
    d_g = np.array([[0.004, -0.006, 0.0], [-0.004, 0.0, 0.008], [0.0, 0.006, -0.008]])
    d_a = np.array([[0.1, 0.0, -0.1], [0.0, -0.1, 0.0], [-0.1, 0.1, 0.1]])
    moved = lambda segs: [Segment(x.name, x.t_ns, x.gyro + d_g[i], x.acc + d_a[i], x.p, x.v, x.q_wxyz)  # noqa: E731
                          for i, x in enumerate(segs)]
    std = sel.level_spread(moved(train), moved(val), groups, val_groups, SETTINGS, ("bias", "bias"), 0.0,
                           TraditionalParams.unknown(), OPTS)
    np.testing.assert_allclose(std.b_g, d_g.std(0, ddof=1) / math.sqrt(3), atol=5e-4)
    np.testing.assert_allclose(std.b_a, d_a.std(0, ddof=1) / math.sqrt(3), atol=1e-2)
    assert np.all(np.isnan(std.M_g)) and np.all(np.isnan(std.G)) and np.all(np.isnan(std.M_a))


def test_evaluate_scores_a_profile_as_it_ships(tmp_path):
    """``profile:PATH`` applies the profile's floor exactly as Profile.apply; a malformed one is refused."""
    from floors import set_floor
    from imu_learn.baselines.affine import Floor
    from imu_learn.baselines.registry import is_method, load_method_class
    from imu_learn.calib.profile import Profile
    from imu_learn.errors import ProfileError

    m = set_floor(cutoffs=(20.0, None))
    path = tmp_path / "profile.json"
    path.write_text(json.dumps({"floor": m.to_dict()}))
    s = recording(7, np.eye(3), np.eye(3), seconds=5.0)
    name = f"profile:{path}"
    assert is_method(name) and not is_method("profile:")
    method = load_method_class(name)()
    g, a = method.refine(s)
    fp = Floor.from_dict(m.to_dict()).params  # the derived fields agree with the floor (a profile checks it)
    p = Profile.from_dict({"format": "imu-learn device profile", "version": 1, "device": "x", "sample_rate_hz": 200.0,
                           "time_offset_s": 0.0, "time_offset_s_std": None,
                           "gyroscope": {"unit": "rad/s", "matrix": fp.M_g.tolist(), "bias": fp.b_g.tolist(),
                                         "matrix_std": np.eye(3).tolist(), "bias_std": [0, 0, 0]},
                           "accelerometer": {"unit": "m/s^2", "matrix": fp.M_a.tolist(), "bias": fp.b_a.tolist(),
                                             "matrix_std": np.eye(3).tolist(), "bias_std": [0, 0, 0]},
                           "g_sensitivity_rad_s_per_mps2": fp.G.tolist(), "gravity_mps2": 9.81,
                           "gravity_mps2_std": None, "floor": m.to_dict()})
    g2, a2 = p.apply(s.t_ns, s.gyro, s.acc)
    assert np.array_equal(g, g2) and np.array_equal(a, a2) and not np.allclose(g, s.gyro)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"floor": {**m.to_dict(), "M_g": [[1, 0], [0, 1]]}}))
    with pytest.raises(ProfileError, match="floor.M_g"):
        load_method_class(f"profile:{bad}")()


@pytest.mark.slow  # the floor's full fit and the selection at calibrate's window budget (about 2 min)
def test_calibrate_with_select_writes_the_floor_at_the_chosen_levels_and_the_selection(tmp_path):
    """calibrate's floor step with ``select``: the bias-only device's profile holds the biases alone, its
    matrices at the identity with no standard deviation, and profile.json the selection behind it."""
    from imu_learn.calib.profile import Profile
    from imu_learn.calib.run import CalibInputs, floor_profile

    train, val, groups, val_groups = device(False)
    inp = CalibInputs(train, val, groups, val_groups, settings=SETTINGS, device="synthetic")
    prof, _, _ = floor_profile(inp, lambda s: None, uncertainty=False, select=True)
    sel_entry = prof.selection
    assert (sel_entry["gyro"], sel_entry["acc"]) == ("bias", "bias") and "refitted" in sel_entry["floor"]
    assert np.array_equal(prof.gyro.matrix, np.eye(3)) and np.array_equal(prof.g_sensitivity, np.zeros((3, 3)))
    std = sel.masked_std(TraditionalParams(np.ones((3, 3)), np.ones(3), np.ones((3, 3)), np.ones((3, 3)), np.ones(3)),
                         ("scale", "bias"))
    assert np.array_equal(np.isfinite(std.M_g), np.eye(3, dtype=bool)) and np.all(np.isnan(std.G))
    assert np.all(np.isnan(std.M_a)) and np.all(np.isfinite(std.b_g)) and np.all(np.isfinite(std.b_a))
    assert np.abs(prof.gyro.bias - BIAS_G).max() < 1e-3
    path = tmp_path / "profile.json"
    prof.save(path)
    back = Profile.load(path)
    assert back.selection["gyro"] == "bias" and set(back.selection["held_out_figures"]["gyro"]) == set(sel.GYRO_LEVELS)


GYRO_ONLY = sel.SelectOptions(max_windows=200, startup_bias_s=5.0, gyro_only=True)


@pytest.mark.parametrize("scale", [False, True])
def test_a_reference_without_accelerations_selects_the_gyroscope_on_rotation_alone(scale):
    """A reference that cannot resolve accelerations (a 20 Hz VO): the gyroscope's levels up to
    g-sensitivity on the rotation cells, the accelerometer not selected; the scaled device's scale
    is found, the bias-only device's bias kept, and no simpler level beats the chosen one in a cell."""
    s = sel.select_levels(*device(scale), SETTINGS, GYRO_ONLY)
    assert s.gyro in (("scale", "affine") if scale else ("bias",)), s.steps["gyro"]
    assert s.acc == "not selected" and s.figures["acc"] == {} and set(s.figures["gyro"]) == set(sel.GYRO_ONLY_LEVELS)
    t = s.figures["gyro"]
    levels = list(sel.GYRO_ONLY_LEVELS)
    for simpler in levels[:levels.index(s.gyro)]:
        for fold, cells in t[s.gyro].items():
            for cell, v in cells.items():
                if cell.startswith(sel.GYRO_ONLY_CELLS):
                    assert v <= (1 + sel.WORSE) * t[simpler][fold][cell], (simpler, fold, cell)
    d = s.to_dict()
    assert d["levels"]["acc"] == [] and d["cells"]["gyro"] == ["rot_deg", "aoe_deg"]


def test_select_floor_keeps_the_sources_accelerometer_for_a_reference_without_accelerations():
    """calibrate's step for such a reference: the gyroscope refitted at its chosen level, the
    accelerometer (matrix, bias, standard deviations) exactly the source's fit's where the source did not
    fit it from positions (nothing to choose its level on; the level from positions:
    tests/test_acc_positions.py)."""
    from imu_learn.calib.profile import FloorFit
    from imu_learn.calib.sources import CalibInputs, Source

    class VoLike(Source):
        def floor_terms(self):
            return {"cutoffs_hz": (None,), "held": ("acc",)}

        def match_kernel(self, inp):
            return np.full(3, 1 / 3)  # a reference 3 IMU samples apart: its triangle

    train, val, groups, val_groups = device(False)
    inp = CalibInputs(train, val, groups, val_groups, settings=SETTINGS, source=VoLike())
    assert sel.skip_reason(inp) is None and sel.gyro_only(inp)
    M_a, b_a = np.diag([1.01, 0.99, 1.0]), np.array([0.3, -0.2, 0.1])
    full = sel.floor_of((np.r_[np.full(9, 1e-3), BIAS_G, np.full(9, 1e-4)], None), (np.zeros(12), None), 0.0)
    full = full.with_params(M_a=M_a, b_a=b_a)
    ones = TraditionalParams(np.ones((3, 3)), np.ones(3), np.ones((3, 3)), np.full((3, 3), 2.0), np.full(3, 2.0))
    fit, entry = sel.select_floor(inp, FloorFit(full, {}, ones, []), opts=GYRO_ONLY)
    p = fit.floor.params
    assert entry["gyro"] == "bias" and entry["acc"] == "the floor's fit (bias and matrix); the accelerometer from the reference's positions not fitted"
    assert "source's" in entry["floor"]
    assert np.array_equal(p.M_a, M_a) and np.array_equal(p.b_a, b_a) and p.cutoff_acc is None and p.cutoff_gyro is None
    assert np.array_equal(p.M_g, np.eye(3)) and np.array_equal(p.G, np.zeros((3, 3)))
    assert np.abs(p.b_g - BIAS_G).max() < 1e-3
    assert np.all(np.isnan(fit.std.M_g)) and np.all(np.isfinite(fit.std.b_g)) and np.all(fit.std.M_a == 2.0)


def test_evaluate_refuses_a_profile_fitted_on_a_test_recording_and_warns_on_another_device(tmp_path, caplog):
    """As --checkpoint is: a profile whose sources hold a test recording is refused before any fit; a test
    recording unlike the IMU the profile was fitted on (refine's guard: the EuRoC profile on a TUM-VI room, or
    here on a level synthetic IMU whose gravity is along z, not EuRoC's -x) gets one warning."""
    shipped = json.loads((Path(__file__).resolve().parent.parent / "models/profiles/euroc_adis16448/profile.json")
                         .read_text())
    path = tmp_path / "profile.json"
    path.write_text(json.dumps({**shipped, "sources": [{"recording": "/data/euroc/V1_01_easy"}]}))
    s = recording(7, np.eye(3), np.eye(3), seconds=5.0)
    with pytest.raises(ConfigError, match="fitted on V1_01_easy, a test recording here"):
        check_profiles(["raw", f"profile:{path}"], ["V1_01_easy"], [s])
    with caplog.at_level(logging.WARNING, logger="imu_learn.eval.run"):
        check_profiles([f"profile:{path}"], ["MH_04_difficult"], [s])
    assert caplog.text.count("looks unlike the IMU profile") == 1
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="imu_learn.eval.run"):
        check_profiles(["raw", "timing"], ["V1_01_easy"], [s])  # no profile: nothing to check
    assert not caplog.records
    # a test recording under another name (a user's CSV of it): its stamps give it away
    t0, t1 = int(s.t_ns[0]), int(s.t_ns[-1])
    renamed = {"recording": "my_imu.csv", "train": [{"t0_ns": t0, "t1_ns": t0 + (t1 - t0) * 8 // 10}],
               "val": [{"t0_ns": t0 + (t1 - t0) * 8 // 10, "t1_ns": t1}]}
    path.write_text(json.dumps({**shipped, "sources": [renamed]}))
    with pytest.raises(ConfigError, match="fitted on my_imu.csv, whose stamps are test recording"):
        check_profiles([f"profile:{path}"], ["MH_04_difficult"], [s])
    later = {**renamed, "train": [{"t0_ns": t1 + 10**9, "t1_ns": t1 + 10**10}], "val": []}
    path.write_text(json.dumps({**shipped, "sources": [later]}))
    check_profiles([f"profile:{path}"], ["MH_04_difficult"], [s])  # other stamps: scored
