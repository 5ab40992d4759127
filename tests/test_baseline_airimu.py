"""The AirIMU-style baseline's own promises: zero-init identity, training through integration, the
unidirectional variant. What every method must do (shapes, save/load, determinism) is
test_baselines_contract.py."""
import numpy as np
import pytest
import torch

from imu_learn.baselines.airimu_style import AirImuConfig, AirImuNet, AirImuStyle
from imu_learn.baselines.base import FitSettings

torch.set_num_threads(1)

W = 50
SETTINGS = FitSettings(window=W, batch_size=16, steps=50, lr=3e-3, seed=0)
TINY = AirImuConfig(conv=8, hidden=16, evals=4)


@pytest.fixture(scope="module")
def fitted(crop_split):
    m = AirImuStyle(TINY)
    return m, m.fit([crop_split[0]], [crop_split[1]], SETTINGS)


def test_untrained_is_the_identity(crop_split):
    _, val = crop_split
    m = AirImuStyle(TINY)
    m.model = AirImuNet(TINY, mean=torch.ones(6), std=torch.full((6,), 2.0))  # zero heads whatever the stats
    g, a = m.refine(val)
    assert g.dtype == np.float64 and a.dtype == np.float64
    assert g.shape == val.gyro.shape and a.shape == val.acc.shape
    assert np.array_equal(g, val.gyro) and np.array_equal(a, val.acc)


def test_training_improves_its_own_loss(fitted):
    _m, log = fitted
    tl = log["train_loss"]
    assert len(tl) == SETTINGS.steps and np.isfinite(tl).all()
    assert np.mean(tl[-8:]) < 0.9 * np.mean(tl[:8])
    assert np.isfinite(log["val_loss"]).all() and len(log["val_loss"]) == 4


def test_trained_refine_changes_the_imu(fitted, crop_split):
    m, _ = fitted
    g, _a = m.refine(crop_split[1])
    assert not np.array_equal(g, crop_split[1].gyro)


def test_unidirectional_variant_trains(crop_split):
    train, _ = crop_split
    m = AirImuStyle(AirImuConfig(conv=4, hidden=8, bidirectional=False))
    log = m.fit([train], [], FitSettings(window=W, batch_size=8, steps=3, lr=1e-3))
    assert len(log["train_loss"]) == 3 and log["val_loss"] == []
    g, _a = m.refine(train)
    assert g.shape == train.gyro.shape
