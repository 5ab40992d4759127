"""The proposed refiner as a Method, its own promises: training (normalisation from the train split,
selection), refine through imu_learn.infer.refiner's windows, checkpoints (ours and imu_learn.train.trainer's).
What every method must do (shapes, save/load, determinism) is test_baselines_contract.py."""
import numpy as np
import pytest
import torch

from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.proposed import Proposed, ProposedConfig
from imu_learn.infer.checkpoint import load_model, save_checkpoint
from imu_learn.infer.refiner import refine_arrays
from imu_learn.nn.model import ImuRefiner, ModelConfig

torch.set_num_threads(1)

W = 50
SETTINGS = FitSettings(window=W, batch_size=16, steps=60, lr=3e-3, seed=0)
TINY = ProposedConfig(model=ModelConfig(hidden=16, layers=1, fc=16), evals=4)


@pytest.fixture(scope="module")
def fitted(crop_split):
    m = Proposed(TINY)
    return m, m.fit([crop_split[0]], [crop_split[1]], SETTINGS)


def test_training_improves_its_own_loss(fitted):
    m, log = fitted
    tl = log["train_loss"]
    assert len(tl) == SETTINGS.steps and np.isfinite(tl).all()
    assert np.mean(tl[-8:]) < 0.9 * np.mean(tl[:8])
    assert len(log["val_loss"]) == 4 and log["best_step"][0] in log["val_step"]
    assert m.window == W
    assert torch.all(m.model.std > 0) and not torch.all(m.model.mean == 0)  # normalisation from the train split


def test_refine_is_refine_arrays_with_half_window_overlap(fitted, crop_split):
    m, _ = fitted
    _, val = crop_split
    g, a = m.refine(val)
    assert not np.array_equal(g, val.gyro)
    g2, a2 = refine_arrays(m.model, val.gyro, val.acc, window=W, overlap=W // 2)
    assert np.array_equal(g, g2) and np.array_equal(a, a2)


def test_untrained_is_the_identity(crop_split):
    _, val = crop_split
    g, a = Proposed(TINY).refine(val)
    assert np.array_equal(g, val.gyro) and np.array_equal(a, val.acc)


def test_save_is_an_imu_learn_checkpoint(fitted, crop_split, tmp_path):
    m, _ = fitted
    _, val = crop_split
    f = tmp_path / "proposed.pt"
    m.save(f)
    assert isinstance(load_model(f), ImuRefiner)  # readable by imu_learn.infer.refiner's loader
    for m2 in (Proposed().load(f), Proposed.from_checkpoint(f)):
        assert m2.window == W and m2.model.cfg.hidden == 16
        g1, a1 = m.refine(val)
        g2, a2 = m2.refine(val)
        assert np.array_equal(g1, g2) and np.array_equal(a1, a2)


def test_from_a_fit_style_checkpoint(crop_split, tmp_path):
    """A checkpoint as imu_learn.train.trainer writes it: the window comes from config.data.window."""
    _, val = crop_split
    torch.manual_seed(1)
    model = ImuRefiner(ModelConfig(hidden=8, layers=1, fc=8))
    with torch.no_grad():
        torch.nn.init.normal_(model.head.weight, std=0.01)
    f = tmp_path / "best.pt"
    save_checkpoint(f, model, {"data": {"window": 80, "split": {"train": ["x"]}}}, epoch=3, step=30, best_metric=0.1)
    m = Proposed.from_checkpoint(f)
    assert m.window == 80 and m.run_config["data"]["split"]["train"] == ["x"]
    g, a = m.refine(val)
    g2, a2 = refine_arrays(model.eval(), val.gyro, val.acc, window=80, overlap=40)
    assert np.array_equal(g, g2) and np.array_equal(a, a2)
