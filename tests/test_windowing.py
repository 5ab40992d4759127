"""imu_learn.infer.windowing: one rule applies a checkpoint everywhere.

The same checkpoint gives bit-identical refined samples through every path that applies one: fit's
helper (model selection and the final table), ``evaluate --checkpoint`` (CheckpointRefiner), the
``proposed`` baseline, ``refine_arrays``, the refine CLI's written file, model_check and fuse. The
checkpoints: small untrained refiners with a fixed seed and a non-zero head (bidirectional and
causal, saved with a training window of 150 so the rule has to come from the checkpoint), and the
shipped ``models/euroc_adis16448.pt``, all on the shipped MH_04_difficult crop.
"""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from crops import whole_pass
from imu_learn import _imu_core as core
from imu_learn.data.types import Segment
from imu_learn.infer import windowing
from imu_learn.infer.checkpoint import load_model, save_checkpoint
from imu_learn.infer.refiner import refine_arrays, refine_with_variance
from imu_learn.infer.windowing import Windowing, window_plan
from imu_learn.nn.model import ImuRefiner, ModelConfig
from imu_learn.train.config import RunConfig

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
CROP = REPO / "datasets" / "euroc" / "MH_04_difficult"
GT = CROP / "mav0" / "state_groundtruth_estimate0" / "data.csv"
IMU_REL = Path("mav0") / "imu0" / "data.csv"
SHIPPED = REPO / "models" / "euroc_adis16448.pt"
SHIPPED_COV = REPO / "models" / "euroc_adis16448_cov.pt"
W = 150  # the small checkpoints' training window (not the default 200)


@pytest.fixture(scope="module")
def imu():
    return core.read_asl_imu(str(CROP / IMU_REL))


def as_sequence(t, g, a) -> Segment:
    """The whole IMU file as a Segment (ground truth unused by refinement: placeholders)."""
    n = len(t)
    q = np.zeros((n, 4))
    q[:, 0] = 1.0
    return Segment("MH_04_difficult", t, g, a, np.zeros((n, 3)), np.zeros((n, 3)), q)


def small_model(causal: bool, g, a, seed: int = 0) -> ImuRefiner:
    torch.manual_seed(seed)
    raw = np.c_[g, a]
    m = ImuRefiner(ModelConfig(causal=causal), mean=torch.tensor(raw.mean(0)), std=torch.tensor(raw.std(0)))
    with torch.no_grad():
        torch.nn.init.normal_(m.head.weight, std=0.5)
        torch.nn.init.normal_(m.head.bias, std=0.1)
    return m.eval()


@pytest.fixture(scope="module", params=["bidirectional", "causal", "shipped"])
def checkpoint(request, imu, tmp_path_factory):
    if request.param == "shipped":
        return SHIPPED
    _t, g, a = imu
    path = tmp_path_factory.mktemp("ckpt") / f"{request.param}.pt"
    save_checkpoint(path, small_model(request.param == "causal", g, a), {"data": {"window": W}}, epoch=1, step=1,
                    best_metric=None)
    return path


def run_config_of(path: Path) -> RunConfig:
    """The run config fit would hold for this checkpoint (only data.window matters here)."""
    window = int(torch.load(path, map_location="cpu", weights_only=False)["config"]["data"]["window"])
    cfg = RunConfig()
    return replace(cfg, data=replace(cfg.data, window=window))


def through_every_path(path: Path, t, g, a, tmp_path: Path, monkeypatch) -> dict:
    """Refined (N, 6) float64 of the whole crop through each path that applies a checkpoint."""
    from imu_learn.baselines.proposed import Proposed
    from imu_learn.cli.refine import main as refine_cli
    from imu_learn.eval.run import CheckpointRefiner
    from imu_learn.fuse.inputs import imu_input
    from imu_learn.infer import model_check
    from imu_learn.train import trainer

    seq = as_sequence(t, g, a)
    out = {}
    s = trainer.refine_sequence(load_model(path), seq, run_config_of(path))
    out["fit"] = np.c_[s.gyro, s.acc]
    out["evaluate --checkpoint"] = np.c_[CheckpointRefiner(path, "cpu").refine(seq)]
    out["proposed"] = np.c_[Proposed.from_checkpoint(path).refine(seq)]
    out["refine_arrays"] = np.c_[refine_arrays(load_model(path), g, a)]
    assert refine_cli(["--checkpoint", str(path), "--input", str(CROP), "--out", str(tmp_path / "cli"),
                       "--device", "cpu", "--quiet"]) == 0
    t2, g2, a2 = core.read_asl_imu(str(tmp_path / "cli" / IMU_REL))
    assert np.array_equal(t2, t)
    out["refine CLI file"] = np.c_[g2, a2]
    seen = []

    def spy(*args, **kwargs):
        seen.append(np.c_[refine_arrays(*args, **kwargs)])
        return seen[-1][:, :3], seen[-1][:, 3:]

    monkeypatch.setattr(model_check, "refine_arrays", spy)
    res = model_check.compare_with_raw(path, CROP, "euroc", groundtruth=GT, horizons=(10,), max_gap_s=0.05)
    assert len(seen) == 1
    out["model_check"] = seen[0]
    rule = load_model(path).windowing
    assert (res["settings"]["window"], res["settings"]["overlap"]) == (rule.window, rule.overlap)
    out["fuse"] = np.c_[imu_input("proposed", seq, str(path), {})[:2]]
    return out


def test_every_path_gives_bit_identical_samples(checkpoint, imu, tmp_path, monkeypatch):
    t, g, a = imu
    got = through_every_path(checkpoint, t, g, a, tmp_path, monkeypatch)
    ref = got["refine_arrays"]
    assert np.abs(ref - np.c_[g, a]).max() > 1e-4  # the model does change the data
    differ = {k: float(np.abs(v - ref).max()) for k, v in got.items() if not np.array_equal(v, ref)}
    assert not differ, f"paths that differ from refine_arrays (max abs difference): {differ}"


def test_the_rule_comes_from_the_checkpoint(checkpoint):
    model = load_model(checkpoint)
    window = run_config_of(checkpoint).data.window
    assert model.windowing == Windowing(window, window // 2, windowing.DEFAULT_BATCH)
    assert windowing.windowing_of(ImuRefiner(ModelConfig())) == Windowing(200, 100)  # a model built in memory




def test_causal_chunks_with_carried_state_equal_one_whole_sequence_pass(imu):
    """Measured exact on an idle CPU for chunk lengths that do and do not divide N (9, 37: remainders of 3
    samples, which as chunks of their own differed by ~1e-8; the rule joins them to the last chunk).
    Bit equality is not guaranteed (torch may block its reductions differently with the threads it
    gets: see the windowing module's docstring), so the check is to 1e-10, far below the 1e-8 that a
    chunk boundary handled wrongly gives."""
    assert windowing.causal_chunks(301, 150) == [(0, 150), (150, 301)]
    assert windowing.causal_chunks(300, 150) == [(0, 150), (150, 300)]
    assert windowing.causal_chunks(100, 150) == [(0, 100)] and windowing.causal_chunks(0, 150) == []
    _t, g, a = imu
    model = small_model(True, g, a)
    ref = whole_pass(model, g, a)
    for w in (W, 9, 37, 333, len(g), len(g) + 5):
        got = np.c_[refine_arrays(model, g, a, window=w)]
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10, err_msg=f"chunks of {w}")


@pytest.mark.parametrize("causal", [False, True], ids=["bidirectional", "causal"])
@pytest.mark.parametrize("n", [W - 37, W, W + 1, 2 * W + 1], ids=["shorter", "one window", "window+1", "2 windows+1"])
def test_edge_lengths(imu, causal, n):
    from imu_learn.train import trainer

    t, g, a = (x[:n] for x in imu)
    model = windowing.attach(small_model(causal, g, a), Windowing.for_training_window(W))
    cfg = replace(RunConfig(), data=replace(RunConfig().data, window=W))
    got = np.c_[refine_arrays(model, g, a)]
    s = trainer.refine_sequence(model, as_sequence(t, g, a), cfg)
    assert np.array_equal(np.c_[s.gyro, s.acc], got)
    plan = window_plan(n, W, W // 2)
    assert plan[0][2] == 0 and plan[-1][3] == n and all(p[3] == q[2] for p, q in zip(plan, plan[1:]))
    if causal or n <= W:  # one window, or the causal forward: the whole-sequence pass exactly
        np.testing.assert_array_equal(got, whole_pass(model, g, a))
    if n == W + 1:  # two windows, [0, W) and [1, W + 1), split at the middle of their overlap
        assert plan == [(0, W, 0, (W + 1) // 2), (1, W + 1, (W + 1) // 2, W + 1)]


def test_empty_sequence_and_bad_rules(imu):
    _t, g, a = imu
    model = small_model(False, g, a)
    rg, ra = refine_arrays(model, g[:0], a[:0])
    assert rg.shape == (0, 3) and ra.shape == (0, 3)
    for bad in ((0, 0), (10, 10), (10, -1)):
        with pytest.raises(ValueError):
            Windowing(*bad)
    assert Windowing(200, 100).replace(window=64) == Windowing(64, 32)
    assert Windowing(200, 100).replace(overlap=10) == Windowing(200, 10)


def test_variances_are_stitched_by_the_same_rule(imu):
    """refine_with_variance and fuse's learned-covariance input: identical samples and variances."""
    from imu_learn.fuse.inputs import imu_input

    t, g, a = imu
    seq = as_sequence(t, g, a)
    rg, ra, var = refine_with_variance(load_model(SHIPPED_COV), g, a)
    fg, fa, fvar = imu_input("proposed+learned-cov", seq, str(SHIPPED_COV), {})
    assert np.array_equal(rg, fg) and np.array_equal(ra, fa) and np.array_equal(var, fvar)
    assert np.array_equal(np.c_[rg, ra], np.c_[refine_arrays(load_model(SHIPPED_COV), g, a)])
    assert var.shape == (len(g), 6) and (var > 0).all()


def test_model_selection_scores_the_rule_it_will_be_applied_with(imu):
    """fit's val_pose score equals the metric computed on refine_arrays' output."""
    from imu_learn import AlignOptions, load_recording
    from imu_learn.score.metrics import with_imu
    from imu_learn.train import trainer

    rec = load_recording(CROP, "euroc", groundtruth=GT, options=AlignOptions(max_gap_s=0.05))
    seq = max(rec.segments, key=len)
    model = small_model(False, seq.gyro, seq.acc)
    base = RunConfig()
    cfg = replace(base, data=replace(base.data, window=W), optim=replace(base.optim, select="val_pose"))
    got = trainer.ValidationPose([seq], cfg)(model, torch.device("cpu"))
    refined = with_imu(seq, *refine_arrays(model, seq.gyro, seq.acc, window=W, overlap=W // 2))
    want = trainer.bias_removed_pose([refined], W, cfg)
    assert got[f"pose_rot_deg_n{W}"] == want["rot_deg"] and got[f"pose_trans_m_n{W}"] == want["trans_m"]
