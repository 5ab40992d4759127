"""The AirIMU-style baseline: zero-init identity, training through integration, refine, save/load."""
from pathlib import Path

import numpy as np
import pytest
import torch

import imu_learn as il
from imu_learn.baselines.airimu_style import AirImuConfig, AirImuNet, AirImuStyle
from imu_learn.baselines.base import FitSettings, poses_from_imu

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
W = 50
SETTINGS = FitSettings(window=W, batch_size=16, steps=50, lr=3e-3, seed=0)
TINY = AirImuConfig(conv=8, hidden=16, evals=4)


def crop(s, a, b):
    return il.Sequence(s.name, s.t_ns[a:b], s.gyro[a:b], s.acc[a:b], s.p[a:b], s.v[a:b], s.q_wxyz[a:b])


@pytest.fixture(scope="module")
def data():
    s = il.load_sequence(REPO / "datasets" / "euroc" / "MH_01_easy")[0]
    return crop(s, 0, 3000), crop(s, 3000, 4000)


@pytest.fixture(scope="module")
def fitted(data):
    train, val = data
    m = AirImuStyle(TINY)
    log = m.fit([train], [val], SETTINGS)
    return m, log


def test_untrained_is_the_identity(data):
    _, val = data
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


def test_refine_changes_the_imu_and_predict_integrates_it(fitted, data):
    m, _ = fitted
    _, val = data
    g, a = m.refine(val)
    assert g.shape == (len(val), 3) and a.shape == (len(val), 3) and g.dtype == np.float64
    assert np.isfinite(g).all() and np.isfinite(a).all()
    assert not np.array_equal(g, val.gyro)
    starts = np.arange(0, 800, 40, dtype=np.uint64)
    p = m.predict(val, starts, 100)
    assert p.q_wxyz.shape == (len(starts), 4) and p.p.shape == (len(starts), 3) and p.v.shape == (len(starts), 3)
    ref = poses_from_imu(val, g, a, starts, 100)
    assert np.array_equal(p.q_wxyz, ref.q_wxyz) and np.array_equal(p.p, ref.p)


def test_refine_of_a_sequence_shorter_than_the_window(fitted, data):
    m, _ = fitted
    _, val = data
    short = crop(val, 0, W - 7)
    g, a = m.refine(short)
    assert g.shape == (W - 7, 3) and a.shape == (W - 7, 3)


def test_save_load_round_trip(fitted, data, tmp_path):
    m, _ = fitted
    _, val = data
    f = tmp_path / "air.pt"
    m.save(f)
    m2 = AirImuStyle().load(f)
    assert m2.window == W and m2.config.hidden == 16 and m2.config.conv == 8
    g1, a1 = m.refine(val)
    g2, a2 = m2.refine(val)
    assert np.array_equal(g1, g2) and np.array_equal(a1, a2)


def test_unidirectional_variant_trains(data):
    train, _ = data
    m = AirImuStyle(AirImuConfig(conv=4, hidden=8, bidirectional=False))
    log = m.fit([train], [], FitSettings(window=W, batch_size=8, steps=3, lr=1e-3))
    assert len(log["train_loss"]) == 3 and log["val_loss"] == []
    g, _a = m.refine(train)
    assert g.shape == train.gyro.shape
