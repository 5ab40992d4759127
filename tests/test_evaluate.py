"""Evaluation (imu_learn.eval.run): metrics with known answers, the command end to end, its errors."""
import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from imu_learn.baselines.base import Method, PosePrediction, Raw
from imu_learn.baselines.noise_floor import NOISE_FLOOR_NAME, synthesize_imu
from imu_learn.cli import evaluate as ev_cli
from imu_learn.data.synthetic import AXIS, DT, G, axis_angle, moving, qmul, spin
from imu_learn.data.types import Segment
from imu_learn.errors import ConfigError, InvalidInputError
from imu_learn.eval import run as ev
from imu_learn.infer.checkpoint import save_checkpoint
from imu_learn.nn.model import ImuRefiner, ModelConfig
from imu_learn.score.metrics import with_imu

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
EVAL_DEFAULT = REPO / "configs" / "eval_default.toml"
BIAS_S = 2.0  # start-up bias seconds in the synthetic cases


def flying(seconds=20.0):
    """``synthetic.moving`` (quadratic position, so trapezoid-consistent) with the IMU synthesised
    from its ground truth (exact under the zero-order hold)."""
    seq = moving(seconds)
    gyro, acc = synthesize_imu(seq, G)
    return with_imu(seq, gyro, acc, "flying")


# ---------------------------------------------------------------------------------------------
# building blocks


def test_rotation_angle():
    ident = np.array([1.0, 0.0, 0.0, 0.0])
    for a in (0.0, 1e-7, 0.25, 1.0, 3.0, np.pi):
        q = axis_angle(AXIS, a)
        assert ev.rotation_angle(ident, q) == pytest.approx(a, abs=1e-12)
        assert ev.rotation_angle(ident, -q) == pytest.approx(a, abs=1e-12)  # sign of q irrelevant
        assert ev.rotation_angle(q, ident) == pytest.approx(a, abs=1e-12)  # symmetric
    # more than π one way is less than π the other
    assert ev.rotation_angle(ident, axis_angle(AXIS, 1.5 * np.pi)) == pytest.approx(0.5 * np.pi, abs=1e-12)
    # relative: the angle of q_gt⁻¹ q_hat, whatever the common rotation in front
    base = axis_angle([0.3, -1.0, 0.2], 2.2)
    q_hat = qmul(base, axis_angle([1.0, 1.0, 0.0], 0.4))
    assert ev.rotation_angle(base, q_hat) == pytest.approx(0.4, abs=1e-12)
    # batched
    qs = axis_angle(AXIS, np.array([0.1, 0.2, 0.3]))
    np.testing.assert_allclose(ev.rotation_angle(np.tile(ident, (3, 1)), qs), [0.1, 0.2, 0.3], atol=1e-12)


def _seq_of_length(n):
    return spin(seconds=(n - 1) / 200.0)


@pytest.mark.parametrize("length,n,stride,first", [(100, 10, 7, 5), (100, 10, 1, 0), (101, 20, 10, 0),
                                                   (50, 49, 1, 0), (50, 10, 3, 39), (300, 1, 50, 17)])
def test_window_starts(length, n, stride, first):
    seq = _seq_of_length(length)
    assert len(seq) == length
    s = ev.window_starts(seq, n, stride, first)
    assert s.dtype == np.int64 and s.size > 0
    assert s[0] == first
    assert np.all(np.diff(s) == stride)
    assert s[-1] + n <= length - 1  # the end sample exists
    assert s[-1] + stride + n > length - 1  # and no window that would fit is missing


def test_window_starts_exact_fit_and_none():
    seq = _seq_of_length(50)
    np.testing.assert_array_equal(ev.window_starts(seq, 49, 5, 0), [0])  # k + n == last sample: kept
    assert ev.window_starts(seq, 50, 1, 0).size == 0  # would need sample 50
    assert ev.window_starts(seq, 10, 1, 40).size == 0  # 40 + 10 = 50: past the end
    np.testing.assert_array_equal(ev.window_starts(seq, 10, 4, 39), [39])


def test_horizon_plan_seconds_to_samples():
    e = ev.EvalSettings(horizons=[10, 7], airimu_s=[0.5, 2.0], curve_min_s=0.05, curve_max_s=5.0, curve_count=3)
    assert ev.curve_seconds(e) == pytest.approx([0.05, 0.5, 5.0], rel=1e-12)
    e.curve_count = 2  # (log-spaced 0.5 is 0.49999999999999994, a second key for the same 100 samples)
    plan = ev.horizon_plan(spin(seconds=6.0), e)
    assert plan["rate_hz"] == pytest.approx(200.0, rel=1e-12)
    assert plan["by_s"] == {0.05: 10, 0.5: 100, 1.0: 200, 2.0: 400, 5.0: 1000}
    assert plan["n"] == [7, 10, 100, 200, 400, 1000]
    # another rate: 100 Hz (every other sample); short horizons never become 0 samples
    s = spin(seconds=6.0)
    s100 = Segment("s", s.t_ns[::2], s.gyro[::2], s.acc[::2], s.p[::2], s.v[::2], s.q_wxyz[::2])
    plan = ev.horizon_plan(s100, ev.EvalSettings(horizons=[10], airimu_s=[0.003], curve_min_s=0.05,
                                                   curve_max_s=5.0, curve_count=2))
    assert plan["rate_hz"] == pytest.approx(100.0, rel=1e-12)
    assert plan["by_s"] == {0.003: 1, 0.05: 5, 1.0: 100, 5.0: 500}
    assert ev.seconds_to_samples(0.0149, 200.0) == 3 and ev.seconds_to_samples(1e-6, 200.0) == 1


def test_pose_errors_known_offsets():
    seq = spin(seconds=2.0)
    starts = np.array([0, 10, 20])
    j = starts + 5
    q_hat = qmul(seq.q_wxyz[j], axis_angle([0.0, 1.0, 0.0], 0.01))
    pred = PosePrediction(q_hat, seq.p[j] + np.array([0.0, 0.3, 0.4]), seq.v[j] - np.array([1.0, 0.0, 0.0]))
    e = ev.pose_errors(seq, starts, 5, pred)
    np.testing.assert_allclose(e["rot_rad"], 0.01, atol=1e-12)
    np.testing.assert_allclose(e["trans_m"], 0.5, atol=1e-12)
    np.testing.assert_allclose(e["vel_mps"], 1.0, atol=1e-12)
    e = ev.pose_errors(seq, starts, 5, PosePrediction(q_hat, None, None))  # rotation-only
    assert np.all(np.isnan(e["trans_m"])) and np.all(np.isnan(e["vel_mps"])) and e["rot_rad"].shape == (3,)


# ---------------------------------------------------------------------------------------------
# evaluate_sequence: known answers


def _check_windows(out, seq, horizons, stride):
    first = ev.index_at(seq, BIAS_S)
    assert first == 400
    assert set(out) == {(v, n) for v in ev.VARIANTS for n in horizons}
    for (_, n), e in out.items():
        np.testing.assert_array_equal(e["starts"], np.arange(first, len(seq) - n, stride))
        assert len(e["rot_rad"]) == len(e["trans_m"]) == len(e["vel_mps"]) == len(e["starts"]) > 0


@pytest.mark.parametrize("make", [spin, flying], ids=["closed-form", "synthesized"])
def test_perfect_imu_has_zero_error(make):
    seq = make()
    out, bias = ev.evaluate_sequence(Raw(), seq, [1, 10, 200], 7, BIAS_S, G)
    _check_windows(out, seq, [1, 10, 200], 7)
    for key, e in out.items():
        assert e["rot_rad"].max() < 1e-9, key
        assert e["trans_m"].max() < 1e-9, key
        assert e["vel_mps"].max() < 1e-9, key
    assert np.abs(bias["gyro"]).max() < 1e-9 and np.abs(bias["acc"]).max() < 1e-8
    assert bias["fitted_on"] == "refined output"


@pytest.mark.parametrize("rate", [0.0, 0.7])
def test_constant_gyro_bias_closed_form(rate):
    """Gyro bias b along the rotation axis (stationary, or spinning about that axis): the open-loop
    rotation error over n samples is exactly |b| n dt; with the start-up bias removed, ~0."""
    seq = spin(rate=rate)
    b = 0.013 * AXIS
    biased = with_imu(seq, seq.gyro + b, seq.acc)
    horizons = [1, 10, 50, 200]
    out, bias = ev.evaluate_sequence(Raw(), biased, horizons, 10, BIAS_S, G)
    _check_windows(out, seq, horizons, 10)
    for n in horizons:
        np.testing.assert_allclose(out[("open_loop", n)]["rot_rad"], 0.013 * n * DT, rtol=1e-9, atol=1e-13)
        assert out[("bias_removed", n)]["rot_rad"].max() < 1e-9
        assert out[("bias_removed", n)]["trans_m"].max() < 1e-9
        assert out[("bias_removed", n)]["vel_mps"].max() < 1e-9
    np.testing.assert_allclose(bias["gyro"], b, atol=1e-10)
    np.testing.assert_allclose(bias["acc"], 0.0, atol=1e-8)
    # rotation errors in the open loop grow with the horizon, so the variants really differ
    assert out[("open_loop", 200)]["rot_rad"].min() > 0.01


def test_start_up_bias_uses_only_the_first_seconds():
    """A gyro bias that appears only after the start-up seconds is not seen by the fit (bias ~0,
    both variants equal); one present from the start is fitted and removed."""
    seq = spin()
    first = ev.index_at(seq, BIAS_S)
    gyro = seq.gyro.copy()
    gyro[first + 1:] += np.array([0.0, 0.02, 0.0])
    out, bias = ev.evaluate_sequence(Raw(), with_imu(seq, gyro, seq.acc), [10], 10, BIAS_S, G)
    assert np.abs(bias["gyro"]).max() < 1e-9
    np.testing.assert_allclose(out[("bias_removed", 10)]["rot_rad"], out[("open_loop", 10)]["rot_rad"], atol=1e-12)
    assert out[("open_loop", 10)]["rot_rad"].min() > 1e-4


def test_accelerometer_bias_is_removed_in_the_bias_variant():
    seq = flying()
    ba = np.array([0.05, -0.03, 0.08])
    out, bias = ev.evaluate_sequence(Raw(), with_imu(seq, seq.gyro, seq.acc + ba), [200], 10, BIAS_S, G)
    np.testing.assert_allclose(bias["acc"], ba, atol=1e-7)
    np.testing.assert_allclose(bias["gyro"], 0.0, atol=1e-9)
    # open loop: a body-frame bias rotated into the world; |Δp| = |½ ba T²| for a pure
    # accelerometer bias only when the body does not rotate, so just bound it from below
    T = 200 * DT
    assert out[("open_loop", 200)]["trans_m"].max() > 0.1 * 0.5 * np.linalg.norm(ba) * T * T
    assert out[("bias_removed", 200)]["trans_m"].max() < 1e-7
    assert out[("open_loop", 200)]["rot_rad"].max() < 1e-9


def test_accelerometer_bias_closed_form_without_rotation():
    """At rest without rotation, an accelerometer bias a gives |a| n dt of velocity error and
    ½ |a| (n dt)² of position error (zero-order hold, exact)."""
    seq = spin(rate=0.0)
    a = np.array([0.02, -0.04, 0.01])
    out, _ = ev.evaluate_sequence(Raw(), with_imu(seq, seq.gyro, seq.acc + a), [10, 200], 10, BIAS_S, G)
    for n in (10, 200):
        np.testing.assert_allclose(out[("open_loop", n)]["vel_mps"], np.linalg.norm(a) * n * DT, rtol=1e-9)
        np.testing.assert_allclose(out[("open_loop", n)]["trans_m"], 0.5 * np.linalg.norm(a) * (n * DT) ** 2, rtol=1e-9)
        assert out[("bias_removed", n)]["trans_m"].max() < 1e-9


class _Oracle(Method):
    """A regressor (overrides predict) that returns the ground-truth end state; records its input."""

    name = "oracle"

    def __init__(self, with_position=True):
        self.with_position = with_position
        self.seen = []

    def predict(self, seq, starts, n, gravity=9.81):
        self.seen.append(seq.gyro.copy())
        j = np.asarray(starts, dtype=np.int64) + n
        if not self.with_position:
            return PosePrediction(seq.q_wxyz[j], None)
        return PosePrediction(seq.q_wxyz[j], seq.p[j], seq.v[j])


class _RotationOnly(Raw):
    name = "rotation-only"
    rotation_only = True


def test_regressors_and_rotation_only_methods():
    seq = spin()
    b = 0.01 * AXIS
    biased = with_imu(seq, seq.gyro + b, seq.acc)
    oracle = _Oracle()
    assert not ev.is_refiner(oracle) and ev.is_refiner(Raw()) and ev.is_refiner(_RotationOnly())
    out, bias = ev.evaluate_sequence(oracle, biased, [10], 10, BIAS_S, G)
    assert bias["fitted_on"] == "raw input"
    for e in out.values():
        assert e["rot_rad"].max() < 1e-12 and e["trans_m"].max() < 1e-12 and e["vel_mps"].max() < 1e-12
    # the regressor saw the raw input (open loop) and the raw input less the fitted bias
    assert len(oracle.seen) == 2
    np.testing.assert_array_equal(oracle.seen[0], biased.gyro)
    np.testing.assert_allclose(oracle.seen[1], seq.gyro, atol=1e-9)
    out, _ = ev.evaluate_sequence(_Oracle(with_position=False), biased, [10], 10, BIAS_S, G)
    assert all(np.isnan(e["trans_m"]).all() and np.isnan(e["vel_mps"]).all() for e in out.values())
    out, _ = ev.evaluate_sequence(_RotationOnly(), biased, [10], 10, BIAS_S, G)
    assert all(np.isnan(e["trans_m"]).all() and np.isnan(e["vel_mps"]).all() for e in out.values())
    np.testing.assert_allclose(out[("open_loop", 10)]["rot_rad"], 0.01 * 10 * DT, rtol=1e-9)


def test_too_short_for_the_start_up_bias_is_a_typed_error():
    seq = spin(seconds=0.005)  # 2 samples
    with pytest.raises(InvalidInputError):
        ev.evaluate_sequence(Raw(), seq, [1], 1, BIAS_S, G)


# ---------------------------------------------------------------------------------------------
# the command, end to end on the shipped crops

# V1_01 against its pose-only groundtruth_pose.tum here (the default run uses the ASL state, which
# has velocity): pose-only test ground truth is what brings in the noise-floor row.
E2E_ARGS = ["--config", str(EVAL_DEFAULT), "--methods", "raw,traditional", "--quiet",
            "--fit.threads", "1", "--fit.steps", "2", "--eval.stride", "50",
            "--data.roots", '[{path = "datasets/euroc/MH_01_easy"}, {path = "datasets/euroc/V1_01_easy"}]']


def _read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def e2e(tmp_path_factory):
    out = tmp_path_factory.mktemp("eval") / "report"
    rc = ev_cli.main(E2E_ARGS + ["--out", str(out)])
    torch.set_num_threads(1)
    return rc, out


def test_end_to_end_writes_the_report(e2e):
    rc, out = e2e
    assert rc == 0
    for name in ("report.md", "relative_pose.csv", "airimu_figures.csv", "integration_error.csv",
                 "errors_all_horizons.csv", "startup_bias.csv", "quoted_paper_table2.csv", "result.json"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    pngs = sorted(out.glob("*.png"))
    assert {p.name for p in pngs} == {"integration_error_open_loop.png", "integration_error_bias_removed.png"}
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    md = (out / "report.md").read_text()
    for s in ("## Protocol", "paper Table II analogue", "start-up bias removed", "open loop", "V1\\_01\\_easy",
              "Quoted figures", "raw", "traditional", "ground truth (noise floor)"):
        assert s in md, s
    result = json.loads((out / "result.json").read_text())
    assert result["methods"] == ["raw", "traditional", NOISE_FLOOR_NAME]  # EuRoC crops: pose-only ground truth
    assert result["test_sequences"] == ["V1_01_easy"] and result["stride"] == 50 and result["startup_bias_s"] == 10.0
    assert {k: v["status"] for k, v in result["records"].items() if k != NOISE_FLOOR_NAME} == {
        "raw": "fitted", "traditional": "fitted"}
    # the fit saw the train split only
    assert [e["recording"] for e in result["split"]["train"]] == ["MH_01_easy"]


def test_end_to_end_csv_rows(e2e):
    rc, out = e2e
    assert rc == 0
    rows = _read_csv(out / "relative_pose.csv")
    seen = {(r["method"], r["variant"], r["sequence"], int(r["n"])) for r in rows}
    for m in ("raw", "traditional", NOISE_FLOOR_NAME):
        for v in ("open_loop", "bias_removed"):
            for n in (10, 50, 200):
                assert (m, v, "V1_01_easy", n) in seen and (m, v, "average", n) in seen, (m, v, n)
    for r in rows:
        for k in ("trans_m", "rot_rad", "rot_deg", "vel_mps", "horizon_s"):
            assert math.isfinite(float(r[k])), (r, k)
        assert int(r["windows"]) > 0
        assert float(r["rot_deg"]) == pytest.approx(math.degrees(float(r["rot_rad"])), rel=1e-9)
    raw = {(r["variant"], int(r["n"])): r for r in rows if r["method"] == "raw" and r["sequence"] == "V1_01_easy"}
    # 50 s of windows from 10 s on every 50 samples at 200 Hz
    assert 190 <= int(raw[("open_loop", 10)]["windows"]) <= 200
    assert float(raw[("open_loop", 10)]["horizon_s"]) == pytest.approx(0.05, rel=1e-3)
    # the raw EuRoC gyro has a start-up bias: removing it helps over 1 s
    assert float(raw[("bias_removed", 200)]["rot_rad"]) < float(raw[("open_loop", 200)]["rot_rad"])
    floor = [r for r in rows if r["method"] == NOISE_FLOOR_NAME]
    assert max(float(r["rot_rad"]) for r in floor) < 1e-9 and max(float(r["vel_mps"]) for r in floor) < 1e-9
    # per-horizon table and the other CSVs
    allh = _read_csv(out / "errors_all_horizons.csv")
    assert {r["variant"] for r in allh} == {"open_loop", "bias_removed"}
    assert all(math.isfinite(float(r["rot_rad"])) and math.isfinite(float(r["trans_m"])) for r in allh)
    air = _read_csv(out / "airimu_figures.csv")
    assert {(r["method"], r["variant"]) for r in air} >= {("raw", "open_loop"), ("raw", "bias_removed")}
    assert all(math.isfinite(float(r["pos_1s_m"])) and math.isfinite(float(r["rot_1s_deg"])) for r in air)
    curve = _read_csv(out / "integration_error.csv")
    assert len({float(r["horizon_s"]) for r in curve}) == 12
    bias = _read_csv(out / "startup_bias.csv")
    assert {r["method"] for r in bias} == {"raw", "traditional", NOISE_FLOOR_NAME}
    assert all(math.isfinite(float(r[f"gyro_bias_{a}"])) for r in bias for a in "xyz")


def test_end_to_end_reuse(e2e, capsys):
    rc, out = e2e
    assert rc == 0
    before = _read_csv(out / "relative_pose.csv")
    capsys.readouterr()
    rc = ev_cli.main(E2E_ARGS + ["--out", str(out), "--reuse"])
    torch.set_num_threads(1)
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    # the fit record and the fitted parameters are separate files (the record must not overwrite them)
    jsons = [json.loads(p.read_text()) for p in (out / "methods").glob("traditional*.json")]
    records = [j for j in jsons if "fit_settings" in j]
    assert len(records) == 1 and records[0]["file"], jsons
    assert "M_g" in json.loads(Path(records[0]["file"]).read_text())
    assert "refitting" not in cap.err
    result = json.loads((out / "result.json").read_text())
    assert result["records"]["raw"]["status"] == "reused"
    assert result["records"]["traditional"]["status"] == "reused"
    assert "reused" in (out / "report.md").read_text()
    # the loaded traditional model gives the same numbers as the freshly fitted one
    after = _read_csv(out / "relative_pose.csv")
    key = lambda r: (r["method"], r["variant"], r["sequence"], r["n"])  # noqa: E731
    b, a = {key(r): r for r in before}, {key(r): r for r in after}
    assert b.keys() == a.keys()
    for k in b:
        assert float(a[k]["rot_rad"]) == pytest.approx(float(b[k]["rot_rad"]), rel=1e-9, abs=1e-15), k
        assert float(a[k]["trans_m"]) == pytest.approx(float(b[k]["trans_m"]), rel=1e-9, abs=1e-15), k
    # summary on stdout names every method
    for m in ("raw", "traditional", NOISE_FLOOR_NAME):
        assert m in cap.out


# ---------------------------------------------------------------------------------------------
# command-line errors: status 2 and one line naming the problem


def _error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("imu-learn evaluate: error:"), err
    return err[0]


def test_cli_unknown_method(capsys, tmp_path):
    assert ev_cli.main(["--config", str(EVAL_DEFAULT), "--methods", "raw,no-such-method", "--out", str(tmp_path)]) == 2
    line = _error_line(capsys)
    assert "unknown method" in line and "no-such-method" in line
    assert not any(tmp_path.iterdir())  # nothing was run


def test_cli_unknown_override_key(capsys, tmp_path):
    assert ev_cli.main(["--config", str(EVAL_DEFAULT), "--methods", "raw", "--eval.no_such_key", "3",
                    "--out", str(tmp_path)]) == 2
    line = _error_line(capsys)
    assert "eval.no_such_key" in line and "unknown key" in line
    assert ev_cli.main(["--methods", "raw", "--nonsense", "1", "--out", str(tmp_path)]) == 2
    assert "nonsense" in _error_line(capsys)


def test_cli_bad_override_value(capsys, tmp_path):
    assert ev_cli.main(["--config", str(EVAL_DEFAULT), "--eval.noise_floor", "sometimes", "--out", str(tmp_path)]) == 2
    assert "eval.noise_floor" in _error_line(capsys)


def test_cli_missing_checkpoint(capsys, tmp_path):
    missing = tmp_path / "nope" / "best.pt"
    assert ev_cli.main(["--config", str(EVAL_DEFAULT), "--methods", "raw", "--checkpoint", str(missing),
                    "--out", str(tmp_path / "out")]) == 2
    line = _error_line(capsys)
    assert str(missing) in line and "No such file" in line


def test_cli_missing_config(capsys, tmp_path):
    assert ev_cli.main(["--config", str(tmp_path / "absent.toml")]) == 2
    assert "absent.toml" in _error_line(capsys)


class _FakeCheckpoint:
    path = Path("runs/x/best.pt")

    def __init__(self, train, val):
        self._s = {"train": train, "val": val, "test": []}

    def splits(self):
        return self._s


def test_checkpoint_whose_split_contains_a_test_recording_is_refused():
    ck = _FakeCheckpoint(["MH_01_easy[0:0.8]", "MH_03_medium"], ["MH_01_easy[0.8:1]"])
    ev.check_checkpoint_split(ck, ["V1_01_easy", "V1_02_medium[0:0.5]"])  # disjoint: fine
    with pytest.raises(ConfigError, match=r"train split uses MH_03_medium"):
        ev.check_checkpoint_split(ck, ["V1_01_easy", "MH_03_medium"])
    # a different part of the same recording is still that recording
    with pytest.raises(ConfigError, match=r"MH_01_easy"):
        ev.check_checkpoint_split(ck, ["MH_01_easy[0.9:1]"])
    with pytest.raises(ConfigError, match=r"val split uses V2_01_easy"):
        ev.check_checkpoint_split(_FakeCheckpoint(["MH_01_easy"], ["V2_01_easy[0:0.2]"]), ["V2_01_easy"])


def test_a_checkpoint_made_for_another_rate_is_refused_before_any_fit():
    """A 100 Hz model on 200 Hz test recordings (refine's rule); 5 % off passes, a model of unknown rate
    is not checked."""
    t200 = np.arange(2000, dtype=np.int64) * 5_000_000
    z = np.zeros((2000, 3))
    seg = Segment("V1_01_easy", t200, z, z, z, z, np.tile([1.0, 0, 0, 0], (2000, 1)))
    ck = _FakeCheckpoint([], [])
    ck.sample_rate_hz = 100.0
    with pytest.raises(ConfigError, match=r"made for 100 Hz, but test recording V1_01_easy is sampled at 200 Hz"):
        ev.check_checkpoint_rate(ck, [seg])
    ck.sample_rate_hz = 196.0
    ev.check_checkpoint_rate(ck, [seg])
    ck.sample_rate_hz = None
    ev.check_checkpoint_rate(ck, [seg])


def test_cli_refuses_a_checkpoint_trained_on_the_test_recording(capsys, tmp_path):
    model = ImuRefiner(ModelConfig(hidden=8, layers=1, fc=8))
    ck = tmp_path / "best.pt"
    save_checkpoint(ck, model, {"data": {"window": 50, "split": {"train": ["V1_01_easy[0:0.5]"], "val": []}}},
                    epoch=0, step=0, best_metric=None)
    rc = ev_cli.main(["--config", str(EVAL_DEFAULT), "--methods", "raw", "--quiet", "--checkpoint", str(ck),
                  "--out", str(tmp_path / "out")])
    torch.set_num_threads(1)
    assert rc == 2
    line = _error_line_after_progress(capsys)
    assert "train split uses V1_01_easy" in line and str(ck) in line
    assert not (tmp_path / "out" / "report.md").exists()


def _error_line_after_progress(capsys):
    """The error line, after the command's own progress lines on stderr ("raw: fitting ...")."""
    err = capsys.readouterr().err.strip().splitlines()
    errors = [x for x in err if x.startswith("imu-learn evaluate: error:")]
    assert len(errors) == 1 and err[-1] == errors[0], err
    return errors[0]


def test_a_checkpoint_with_a_covariance_head_gets_the_calibration_table(tmp_path):
    """On the shipped V1_01 crop: rows for raw and refined IMU under the datasheet, the learned
    variances and their mean, per horizon, with NEES and χ² fractions, in result.json and report.md."""
    torch.manual_seed(0)
    model = ImuRefiner(ModelConfig(hidden=8, layers=1, fc=8, covariance=True))
    ck = tmp_path / "best.pt"
    save_checkpoint(ck, model, {"data": {"window": 50, "split": {"train": ["MH_01_easy"], "val": []}}},
                    epoch=0, step=0, best_metric=None)
    out = tmp_path / "out"
    rc = ev_cli.main(["--config", str(EVAL_DEFAULT), "--methods", "raw", "--quiet", "--checkpoint", str(ck),
                  "--out", str(out), "--eval.horizons", "[10, 200]", "--eval.stride", "50", "--eval.curve_count", "2"])
    torch.set_num_threads(1)
    assert rc == 0
    cal = json.loads((out / "result.json").read_text())["calibration"]
    kinds = {(r["input"], r["covariance"], r["n"]) for r in cal if r["sequence"] == "all test"}
    assert kinds == {(i, c, n) for i in ("raw", "refined") for c in ("datasheet", "learned", "learned mean")
                     for n in (10, 200)}
    for r in cal:
        s = r["summary"]["all"]
        assert s["dof"] == 9 and s["windows"] > 0 and s["mean_nees"] > 0
        assert s["expected_2sigma"] == pytest.approx(0.0886, abs=1e-3)
    # The untrained head's constant-ish variances (sigma ~1e-2 rad/s, 0.1 m/s^2) are far above the
    # datasheet's: the datasheet is the overconfident one on real data.
    by = {(r["input"], r["covariance"], r["n"]): r["summary"]["all"] for r in cal if r["sequence"] == "all test"}
    assert by[("raw", "datasheet", 200)]["mean_nees"] > by[("raw", "learned", 200)]["mean_nees"]
    assert "## Calibration of the increments' covariance" in (out / "report.md").read_text()


def test_a_missing_base_names_the_config_and_its_key(tmp_path, capsys):
    cfg = tmp_path / "eval_x.toml"
    cfg.write_text('base = "nofile.toml"\n')
    assert ev_cli.main(["--config", str(cfg), "--out", str(tmp_path / "out")]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and f"{cfg}: base = 'nofile.toml': no such run config" in err[0], err
