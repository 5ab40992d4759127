"""calibrate's summary says what the profile holds: the level ``offset`` is the time offset alone (no
term at all where that offset is held at its prior), a held-back raise is not blamed on a sensor whose
terms are all at their prior, and a sensor put at its prior is said so in the terms line."""
from __future__ import annotations

import logging
import math

import numpy as np

from imu_learn.baselines.affine import FLOOR_METHOD, Floor, TraditionalParams
from imu_learn.calib import run as calib_run
from imu_learn.calib.profile import Affine, Profile
from imu_learn.cli.calibrate import _terms_line

SELECTION = {"gyro": "offset", "acc": "bias", "held_out": "leave one recording out"}


def test_the_offset_level_is_named_for_what_it_holds():
    assert "gyroscope offset (the time offset alone), accelerometer bias" in _terms_line(SELECTION, "poses", True)
    line = _terms_line(SELECTION, "poses", False)
    assert "gyroscope none (the time offset held at its prior), accelerometer bias" in line


def profile(b_g: np.ndarray) -> Profile:
    p = TraditionalParams.identity()
    floor = Floor(TraditionalParams(M_g=p.M_g, b_g=b_g, G=p.G, M_a=p.M_a, b_a=np.array([0.1, 0.0, 0.0]),
                                    cutoff_gyro=None, cutoff_acc=None, time_offset=0.5), FLOOR_METHOD, 2)
    prof = Profile(device="d", sample_rate_hz=200.0, time_offset_s=0.0025, time_offset_s_std=math.nan,
                   gyro=Affine(np.eye(3), np.zeros(3), "rad/s"), acc=Affine(np.eye(3), np.zeros(3), "m/s^2"),
                   g_sensitivity=np.zeros((3, 3)), gravity_mps2=9.81, gravity_mps2_std=math.nan, floor={})
    prof.floor = floor  # the blocks derived from it
    prof.selection = dict(SELECTION)
    return prof


RAISE = {"raw_rot_deg": 0.10, "profile_rot_deg": 0.101, "raw_trans_m": 0.01, "profile_trans_m": 0.01,
         "window_samples": 200, "z_rot": 0.5}


def test_a_raise_is_not_blamed_on_a_gyroscope_with_no_term(monkeypatch, caplog):
    """The gyroscope at level offset (no term): the held-back rotation raise within the block's noise
    is the time offset's or the noise's; nothing is 'kept at its prior'."""
    prof = profile(np.zeros(3))
    monkeypatch.setattr(calib_run, "_held_back", lambda p, inp: dict(RAISE))
    with caplog.at_level(logging.WARNING):
        errs, kept = calib_run.keep_unsupported_at_prior(prof, None, dict(RAISE))
    assert kept == [] and "kept at their prior" not in caplog.text
    assert prof.selection["gyro"] == "offset"


def test_a_gyroscope_put_at_its_prior_is_said_so_in_the_terms_line(monkeypatch, caplog):
    prof = profile(np.array([0.01, 0.0, 0.0]))
    calls = []

    def held_back(p, inp):
        calls.append(1)
        return dict(RAISE, profile_rot_deg=0.099)  # at the prior the raise is gone

    monkeypatch.setattr(calib_run, "_held_back", held_back)
    with caplog.at_level(logging.WARNING):
        errs, kept = calib_run.keep_unsupported_at_prior(prof, None, dict(RAISE))
    assert [k["sensor"] for k in kept] == ["gyroscope"] and calls == [1]
    assert np.array_equal(prof.floor.params.b_g, np.zeros(3))
    assert prof.selection["gyro"] == "offset, then kept at its prior (the held-back block)"
    assert "gyroscope: the fitted terms kept at their prior" in caplog.text


def test_a_raise_within_the_noise_for_a_sensor_with_no_term_is_written(monkeypatch):
    """calibrate's plausibility: the gyroscope at level offset (no term) and a held-back rotation raise within
    the block's noise: written, the raise said under within_noise_at_prior (BROAD's trial 21 alone was refused,
    0.215° against raw 0.215°, 0.1 standard errors); the same raise beyond the noise is refused."""
    import pytest

    from imu_learn.errors import ImplausibleProfileError

    class Inp:
        class source:
            kind = "poses"

    prof = profile(np.zeros(3))
    monkeypatch.setattr(calib_run, "_held_back", lambda p, inp: dict(RAISE))
    checks = calib_run.plausibility(prof, Inp(), calib_run.CalibOptions(plot=False), lambda s: None)
    assert checks["failed"] == [] and len(checks["within_noise_at_prior"]) == 1, checks
    monkeypatch.setattr(calib_run, "_held_back", lambda p, inp: dict(RAISE, z_rot=5.0))
    with pytest.raises(ImplausibleProfileError, match="held_back.rotation"):
        calib_run.plausibility(profile(np.zeros(3)), Inp(), calib_run.CalibOptions(plot=False), lambda s: None)
