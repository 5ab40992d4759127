"""GyroDenoise baseline (Brossard et al. 2020), its own promises: chunk products, the multiscale
loss's zero, zero-init identity, pass-through accel, training. What every method must do (shapes,
save/load, determinism) is test_baselines_contract.py."""
import numpy as np
import pytest
import torch

from crops import cut
from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.gyro_denoise import GyroDenoise, _chunk_products, multiscale_rotation_loss
from imu_learn.nn.so3 import quat_mul, so3_exp

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def mh(crop_split):
    train, val = crop_split
    return train, cut(val, 0, 600)  # 15 s train, 3 s validation


def small() -> GyroDenoise:
    return GyroDenoise(channels=(8, 16), dilations=(1, 4), scales=(16, 32))


def test_chunk_products_order():
    torch.manual_seed(0)
    q = so3_exp(0.3 * torch.randn(2, 64, 3, dtype=torch.float64))
    p = _chunk_products(q, (4, 16))
    ref = q[:, 16]
    for i in range(17, 32):
        ref = quat_mul(ref, q[:, i])
    assert p[16].shape == (2, 4, 4) and p[4].shape == (2, 16, 4)
    assert torch.allclose(p[16][:, 1], ref, atol=1e-12)


def test_loss_zero_on_ground_truth(mh):
    """Gyro rates that reproduce the ground-truth increments give zero loss."""
    s = mh[0]
    q = torch.from_numpy(s.q_wxyz[:65])[None]
    dt = torch.from_numpy(np.diff(s.t_ns[:65]) * 1e-9)[None]
    from imu_learn.nn.so3 import quat_conj, so3_log
    rel = quat_mul(quat_conj(q[:, :-1]), q[:, 1:])
    gyro = so3_log(rel) / dt.unsqueeze(-1)
    assert float(multiscale_rotation_loss(gyro, dt, q, (16, 32, 64), 0.005)) < 1e-20
    assert float(multiscale_rotation_loss(gyro + 0.05, dt, q, (16, 32, 64), 0.005)) > 1e-6


def test_untrained_is_identity_and_shapes(mh):
    m = small()
    assert m.rotation_only and m.name == "gyro-denoise"
    g, a = m.refine(mh[1])
    assert g.shape == (len(mh[1]), 3) and g.dtype == np.float64
    np.testing.assert_allclose(g, mh[1].gyro, atol=1e-6)  # zero-initialised output layer, C = I
    assert a is mh[1].acc or np.array_equal(a, mh[1].acc)
    assert m.predict(mh[1], np.array([0, 10]), 100).p is None


def test_fit_improves_loss_and_passes_the_accelerometer_through(mh):
    m = small()
    st = FitSettings(window=64, batch_size=8, steps=150, lr=1e-2, seed=0, threads=1)
    log = m.fit([mh[0]], [mh[1]], st)
    tl = log["train_loss"]
    assert len(tl) == 150 and np.isfinite(tl).all()
    assert np.mean(tl[-10:]) < 0.5 * np.mean(tl[:10]), (np.mean(tl[:10]), np.mean(tl[-10:]))
    assert log["val_loss"][-1] < log["val_loss"][0]
    g, a = m.refine(mh[1])
    assert g.shape == (len(mh[1]), 3) and g.dtype == np.float64
    np.testing.assert_array_equal(a, mh[1].acc)
    assert np.abs(g - mh[1].gyro).max() > 1e-4  # it learned something


def test_training_shows_progress_only_when_asked_and_progress_is_not_part_of_the_fit(mh, capsys):
    """A learned baseline's training is a long job inside evaluate: a bar on stderr while it trains
    (evaluate passes its progress flag), none when quiet; the fit records' signature leaves it out so a
    saved fit is reused either way."""
    train, val = mh
    for progress in (True, False):
        st = FitSettings(window=64, batch_size=4, steps=3, lr=1e-3, seed=0, threads=1, progress=progress)
        small().fit([train], [val], st)
        err = capsys.readouterr().err
        assert ("gyro-denoise: fit" in err) == progress, err
    a, b = FitSettings(progress=True).record(), FitSettings(progress=False).record()
    assert a == b and "progress" not in a and a["steps"] == FitSettings().steps
