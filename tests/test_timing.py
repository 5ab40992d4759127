"""The timing floor (baselines/timing.py, traditional+timing, fit's floor ratios), closed forms:
an IMU delayed by a known tau gives tau back, undelayed data gives 0, resampling at 0 is the
identity bit for bit and at 0.5 the midpoint rule. What every method must do is
test_baselines_contract.py."""
import json

import numpy as np
import pytest

from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.timing import Timing, resample, shifted
from imu_learn.data.synthetic import DT, stamps
from imu_learn.data.types import Segment
from imu_learn.score.metrics import floor_ratios, simulate_sequence

SETTINGS = FitSettings(window=100, seed=0)


def rates(t: np.ndarray) -> np.ndarray:
    return np.stack([0.8 * np.sin(2.1 * t) + 0.3 * np.sin(7.3 * t), 0.6 * np.cos(3.3 * t),
                     0.5 * np.sin(1.7 * t + 0.4) + 0.2 * np.sin(11.0 * t)], 1)


def forces(t: np.ndarray) -> np.ndarray:
    return np.stack([0.5 * np.sin(1.1 * t), 0.4 * np.cos(2.3 * t), 9.81 + 0.3 * np.sin(0.9 * t)], 1)


def delayed(tau: float, seconds: float = 20.0, name: str = "s") -> Segment:
    """Ground truth whose exact zero-order-hold IMU is rates(t_i), forces(t_i); the recorded IMU is
    that signal ``tau`` samples late: rates(t_i - tau·dt)."""
    t_ns = stamps(seconds)
    t = (t_ns - t_ns[0]) * 1e-9
    gt = simulate_sequence(t_ns, rates(t), forces(t), name=name)
    return Segment(name, t_ns, rates(t - tau * DT), forces(t - tau * DT), gt.p, gt.v, gt.q_wxyz)


def test_resampling_at_zero_is_the_input_bit_for_bit():
    s = delayed(0.3, 2.0)
    for x in (s.gyro, s.acc):
        y = resample(s.t_ns, x, 0.0, DT * 1e9)
        np.testing.assert_array_equal(y, x)
        assert y is not x
    m = Timing()
    g, a = m.refine(s)
    np.testing.assert_array_equal(g, s.gyro)
    np.testing.assert_array_equal(a, s.acc)
    assert shifted(s, 0.0) is s


def test_half_a_sample_is_the_midpoint_rule():
    s = delayed(0.0, 2.0)
    g = resample(s.t_ns, s.gyro, 0.5, DT * 1e9)
    np.testing.assert_allclose(g[:-1], 0.5 * (s.gyro[:-1] + s.gyro[1:]), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(g[-1], s.gyro[-1])  # the end is held
    # a whole sample is the next sample
    np.testing.assert_allclose(resample(s.t_ns, s.gyro, 1.0, DT * 1e9)[:-1], s.gyro[1:], rtol=0, atol=1e-14)


@pytest.mark.parametrize("tau", [0.5, 1.3, -0.7, 2.2])
def test_a_known_delay_is_recovered(tau):
    m = Timing()
    log = m.fit([delayed(tau, name="train")], [delayed(tau, 8.0, name="val")], SETTINGS)
    assert abs(m.tau - tau) < 0.01, (m.tau, tau)
    assert log["tau_samples"] == [m.tau]
    assert log["train_loss"][1] < 0.01 * log["train_loss"][0]  # the shift explains the residuals
    # the shifted IMU is the exact one up to linear interpolation error (smooth rates)
    g, _ = m.refine(delayed(tau, 8.0))
    exact = rates((stamps(8.0) - stamps(8.0)[0]) * 1e-9)
    inner = slice(5, -5)
    assert np.abs(g[inner] - exact[inner]).max() < 1e-3


def test_undelayed_data_gives_zero():
    m = Timing()
    m.fit([delayed(0.0, name="train")], [delayed(0.0, 8.0, name="val")], SETTINGS)
    assert abs(m.tau) < 0.01


def test_validation_keeps_zero_when_the_offset_does_not_hold_there():
    """Selection on validation only: a training delay the validation data does not share is dropped."""
    m = Timing()
    log = m.fit([delayed(1.0, name="train")], [delayed(0.0, 8.0, name="val")], SETTINGS)
    assert abs(log["tau_fitted"][0] - 1.0) < 0.01
    assert m.tau == 0.0


def test_save_load_round_trip(tmp_path):
    m = Timing()
    m.fit([delayed(0.8, name="train")], [], SETTINGS)
    m.save(tmp_path / "timing.json")
    assert json.loads((tmp_path / "timing.json").read_text()) == {"method": "timing", "tau_samples": m.tau}
    m2 = Timing().load(tmp_path / "timing.json")
    assert m2.tau == m.tau
    with pytest.raises(ValueError, match="not 'timing'"):
        (tmp_path / "x.json").write_text(json.dumps({"method": "traditional", "tau_samples": 1.0}))
        Timing().load(tmp_path / "x.json")


def test_floor_ratios_pick_the_lower_floor_per_cell():
    def cell(r, t):
        return {"rot_deg": r, "trans_m": t}

    rows = {"raw": {"open_loop": {"10": cell(1.0, 0.10)}},
            "timing": {"open_loop": {"10": cell(0.5, 0.20)}},
            "model": {"open_loop": {"10": cell(0.4, 0.05)}}}
    got = floor_ratios(rows, ["raw", "timing"], "model")["open_loop"]["10"]
    assert got["rot"] == pytest.approx(0.8) and got["rot_floor"] == "timing"
    assert got["trans"] == pytest.approx(0.5) and got["trans_floor"] == "raw"


def test_fits_final_table_has_a_timing_row_and_judges_the_model_against_the_best_floor():
    """train.trainer's final table: raw, timing (offset fitted on the train split) and model rows, and
    model/floor ratios against the lower of raw and timing. The "model" here is the exact IMU."""
    pytest.importorskip("torch")
    from imu_learn.data.splits import Split
    from imu_learn.train.config import build_config
    from imu_learn.train.trainer import evaluate_table, format_table, timing_floor

    cfg = build_config({}, {"data.window": 100, "data.startup_bias_s": 2.0, "data.eval_stride": 20})
    test = delayed(0.7, 16.0, name="test")
    split = Split([delayed(0.7, name="train")], [delayed(0.7, 8.0, name="val")], [test], {})
    timing_seqs, tau = timing_floor(split, cfg)
    assert abs(tau - 0.7) < 0.01
    t = (test.t_ns - test.t_ns[0]) * 1e-9
    exact = Segment("test", test.t_ns, rates(t), forces(t), test.p, test.v, test.q_wxyz)
    res = evaluate_table([test], [exact], cfg, timing_seqs)
    res["timing_offset_samples"] = tau
    assert list(res["rows"]) == ["raw", "timing", "model"]
    for n in ("10", "200"):
        raw, tim = res["rows"]["raw"]["open_loop"][n], res["rows"]["timing"]["open_loop"][n]
        assert tim["rot_deg"] < 0.1 * raw["rot_deg"]  # the offset was the whole error
        vs = res["vs_floor"]["open_loop"][n]
        assert vs["rot_floor"] == "timing"
        assert vs["rot"] == pytest.approx(res["rows"]["model"]["open_loop"][n]["rot_deg"] / tim["rot_deg"])
    text = format_table(res, ["test"], cfg)
    assert "timing +0.70" in text and "model/floor" in text
