"""imu_learn.util.threads: one number sizes torch's and OpenBLAS's pools within a block (restored
after), clamped to the cores the process may use; the environment for a process about to start;
the traditional floor fits with the threads it says (one by default) and leaves the caller's as
they were."""
from __future__ import annotations

import os

import numpy as np
import pytest
import torch

from imu_learn.util import threads as th


@pytest.fixture(autouse=True)
def torch_threads_as_they_were():
    """Each test leaves torch's pool as it found it (later tests compare float32 results that depend on it)."""
    before = torch.get_num_threads()
    yield
    torch.set_num_threads(before)


def blas_threads():
    return [get() for _, get in th._openblas_setters() if get is not None]


def test_thread_limits_sets_and_restores_torch_and_openblas():
    np.ones((4, 3)) @ np.eye(3)  # numpy's OpenBLAS is loaded
    before_torch, before_blas = torch.get_num_threads(), blas_threads()
    with th.thread_limits(1) as n:
        assert n == 1 and torch.get_num_threads() == 1
        assert all(b == 1 for b in blas_threads())
    assert torch.get_num_threads() == before_torch and blas_threads() == before_blas


def test_clamped_to_the_cores():
    cores = th.cores()
    assert cores >= 1
    assert th.clamp(10 * cores + 5) == cores and th.clamp(0) == 1 and th.clamp(None) == cores
    with th.thread_limits(10 * cores + 5) as n:
        assert n == cores and torch.get_num_threads() == cores


def test_thread_env_for_a_child_keeps_the_users_choice():
    env = th.thread_env(1, {"RAYON_NUM_THREADS": "3", "PATH": os.environ.get("PATH", "")})
    assert env["RAYON_NUM_THREADS"] == "3"  # set by the user: kept
    assert env["OMP_NUM_THREADS"] == env["OPENBLAS_NUM_THREADS"] == env["MKL_NUM_THREADS"] == "1"
    assert env["OMP_WAIT_POLICY"] == "PASSIVE"


def test_the_floor_fits_single_threaded_and_restores_the_callers_threads(crop_split, monkeypatch):
    from imu_learn.baselines.base import FitSettings
    from imu_learn.baselines.traditional import Traditional

    seen = []
    real = th.thread_limits

    def spy(n, *a, **k):
        seen.append(n)
        return real(n, *a, **k)

    monkeypatch.setattr("imu_learn.baselines.traditional.thread_limits", spy)
    torch.set_num_threads(min(2, th.cores()))
    before = torch.get_num_threads()
    Traditional(cutoffs_hz=(None,), max_windows=50).fit([crop_split[0]], [crop_split[1]], FitSettings(window=100, threads=2))
    assert seen == [1] and torch.get_num_threads() == before
