"""Augmented batches: deterministic per seed whatever the thread count, labels as documented."""
import os
import subprocess
import sys

import numpy as np
import pytest

import imu_learn as il

AUG = il.AugmentConfig(gyro_noise_density=1.7e-4, acc_noise_density=2e-3, gyro_bias_max=0.02, acc_bias_max=0.1)


@pytest.fixture(scope="module")
def seqs(shipped):
    return [s for name in ("MH_01_easy", "V1_01_easy") for s in il.load_sequence(shipped / "euroc" / name)]


def test_shapes_and_dtypes(seqs):
    b = il.BatchSampler(seqs, il.BatchConfig(window=200, batch_size=8, augment=AUG)).sample(0)
    assert b.imu.shape == (8, 200, 6) and b.dt.shape == (8, 200) and b.bias.shape == (8, 200, 6)
    assert b.dq_wxyz.shape == (8, 5, 4) and b.dv.shape == (8, 5, 3) and b.label_dt.shape == (8, 5)
    assert list(b.horizons) == [40, 80, 120, 160, 200]


def test_without_augmentation_windows_are_the_recorded_samples_and_labels(seqs):
    b = il.BatchSampler(seqs, il.BatchConfig(window=100, batch_size=16)).sample(3)
    lab_cache = {}
    for i in range(16):
        s = seqs[int(b.seq_index[i])]
        k = int(b.start[i])
        np.testing.assert_array_equal(b.imu[i, :, :3], s.gyro[k:k + 100])
        np.testing.assert_array_equal(b.imu[i, :, 3:], s.acc[k:k + 100])
        np.testing.assert_allclose(b.dt[i], np.diff(s.t_ns[k:k + 101]) * 1e-9, atol=1e-15)
        key = int(b.seq_index[i])
        if key not in lab_cache:
            lab_cache[key] = il.window_labels(s, window=100, stride=1)
        lab = lab_cache[key]
        np.testing.assert_allclose(b.dv[i], lab.dv[k], atol=1e-12)
        np.testing.assert_allclose(b.dp[i], lab.dp[k], atol=1e-12)
    assert np.all(b.bias == 0)


def test_bias_is_what_was_added_and_within_bounds(seqs):
    aug = il.AugmentConfig(gyro_bias_max=0.05, acc_bias_max=0.2)
    b = il.BatchSampler(seqs, il.BatchConfig(window=50, batch_size=32, augment=aug)).sample(11)
    for i in range(32):
        s = seqs[int(b.seq_index[i])]
        k = int(b.start[i])
        raw = np.concatenate([s.gyro[k:k + 50], s.acc[k:k + 50]], axis=1)
        np.testing.assert_allclose(b.imu[i] - raw, b.bias[i], atol=1e-12)
    assert np.all(np.abs(b.bias[..., :3]) <= 0.05) and np.all(np.abs(b.bias[..., 3:]) <= 0.2)
    np.testing.assert_array_equal(b.bias[:, :1], np.broadcast_to(b.bias[:, :1], b.bias[:, :1].shape))
    assert np.all(b.bias == b.bias[:, :1])  # constant over each window without a walk


def test_seeds_differ(seqs):
    s = il.BatchSampler(seqs, il.BatchConfig(window=100, batch_size=8, augment=AUG))
    a, b = s.sample(1), s.sample(2)
    assert not np.array_equal(a.imu, b.imu)
    np.testing.assert_array_equal(a.imu, s.sample(1).imu)


SCRIPT = """
import hashlib, sys, numpy as np, imu_learn as il
seqs = [s for n in ("MH_01_easy", "V1_01_easy") for s in il.load_sequence(sys.argv[1] + "/euroc/" + n)]
aug = il.AugmentConfig(gyro_noise_density=1.7e-4, acc_noise_density=2e-3, gyro_bias_max=0.02, acc_bias_max=0.1, gyro_bias_walk=1e-4)
b = il.BatchSampler(seqs, il.BatchConfig(window=200, batch_size=64, augment=aug)).sample(42)
h = hashlib.sha256()
for k in ("imu", "dt", "dq_wxyz", "dv", "dp", "bias", "seq_index", "start"):
    h.update(np.ascontiguousarray(getattr(b, k)).tobytes())
print(h.hexdigest())
"""


def test_same_seed_same_batch_whatever_the_thread_count(shipped):
    digests = set()
    for threads in ("1", "2", "3"):
        env = dict(os.environ, RAYON_NUM_THREADS=threads)
        out = subprocess.run([sys.executable, "-c", SCRIPT, str(shipped)], env=env, capture_output=True, text=True, check=True)
        digests.add(out.stdout.strip())
    assert len(digests) == 1


def test_eval_windows_cover_every_stride(seqs):
    s = il.BatchSampler(seqs[:1], il.BatchConfig(window=200, batch_size=1))
    b = s.eval_windows(stride=100)
    n = len(seqs[0])
    assert list(b.start) == list(range(0, n - 200, 100))


FIELDS = ("imu", "dt", "dq_wxyz", "dv", "dp", "label_dt", "bias", "seq_index", "start")


@pytest.mark.parametrize("aug", [AUG, il.AugmentConfig()], ids=["augmented", "plain"])
def test_reused_batch_storage_holds_nothing_of_the_previous_batch(seqs, aug):
    """Batches are carved from storage the sampler reuses once Python drops them: a batch built in
    reused storage must equal the same seed's batch from a fresh sampler, element for element."""
    cfg = il.BatchConfig(window=100, batch_size=16, augment=aug)
    want = il.BatchSampler(seqs, cfg).sample(7)
    sampler = il.BatchSampler(seqs, cfg)
    first = sampler.sample(1)
    first.imu[...] = np.nan  # poison the storage, then give it back
    first.bias[...] = np.nan
    del first
    got = sampler.sample(7)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(got, f), getattr(want, f), err_msg=f)
    if aug == il.AugmentConfig():
        assert not got.bias.any()


def test_batches_held_by_the_caller_are_never_overwritten(seqs):
    sampler = il.BatchSampler(seqs, il.BatchConfig(window=100, batch_size=8, augment=AUG))
    kept = [sampler.sample(s) for s in range(4)]
    copies = [{f: getattr(b, f).copy() for f in FIELDS} for b in kept]
    for s in range(4, 12):  # more batches, with and without dropping them
        sampler.sample(s)
    for b, c in zip(kept, copies):
        for f in FIELDS:
            np.testing.assert_array_equal(getattr(b, f), c[f], err_msg=f)
