"""The IMU's time offset against GNSS fixes (fuse/start/delay.py): recovered on a synthetic car track
whose IMU stamps run a known delay off, with vibration on the accelerometer and an unknown mounting;
refused at the grid's edge and without enough moving epochs; the exact double integral."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_learn.errors import InvalidInputError
from imu_learn.fuse.aiding import rtklib
from imu_learn.fuse.start.delay import double_integral, imu_delay
from test_navigate_gnss import LEVER, RPY, synthetic_car

G = 9.7968
T0 = 1_752_003_258_499_000_000


def track(t: np.ndarray):
    """Position [m], velocity [m/s] and acceleration [m/s^2] of a car weaving over a bumpy road (the
    vertical bumps are what moves the specific force's norm most, as on the real drive)."""
    w1, w2, w3, w4 = 0.35, 0.22, 0.9, 2 * np.pi * 0.7
    z = 0.3 * np.sin(w3 * t) + 0.04 * np.sin(w4 * t + 0.01 * t * t)
    vz = 0.3 * w3 * np.cos(w3 * t) + 0.04 * (w4 + 0.02 * t) * np.cos(w4 * t + 0.01 * t * t)
    az = (-0.3 * w3 ** 2 * np.sin(w3 * t) - 0.04 * (w4 + 0.02 * t) ** 2 * np.sin(w4 * t + 0.01 * t * t)
          + 0.04 * 0.02 * np.cos(w4 * t + 0.01 * t * t))
    p = np.stack([6.0 * t + 9.0 * np.sin(w1 * t), 12.0 * np.cos(w2 * t), z], 1)
    v = np.stack([6.0 + 9.0 * w1 * np.cos(w1 * t), -12.0 * w2 * np.sin(w2 * t), vz], 1)
    a = np.stack([-9.0 * w1 ** 2 * np.sin(w1 * t), -12.0 * w2 ** 2 * np.cos(w2 * t), az], 1)
    return p, v, a


def drive(delay_s: float, seconds: float = 200.0, vib: float = 0.3, seed: int = 0):
    """IMU stamps as a logger writes them (true time - delay_s, so the delay to add is delay_s), the
    specific force in a tilted body frame with white vibration, and a 4 Hz RTKLIB-like solution."""
    rng = np.random.default_rng(seed)
    t_true = np.arange(0.0, seconds, 0.01)
    _, _, a = track(t_true)
    f_world = a + np.array([0.0, 0.0, G])
    R = Rotation.from_euler("xyz", [3.0, -5.0, 40.0], degrees=True).as_matrix()  # any mounting: the norm needs none
    acc = f_world @ R + rng.normal(0.0, vib, f_world.shape)
    imu_t = T0 + np.round((t_true - delay_s) * 1e9).astype(np.int64)
    tg = np.arange(0.5, seconds - 0.5, 0.25)
    p, v, _ = track(tg)
    m = len(tg)
    sol = rtklib.RtkSolution("synthetic.pos", T0 + np.round(tg * 1e9).astype(np.int64),
                             p + rng.normal(0.0, 0.005, p.shape), np.full((m, 3), 0.01), v,
                             np.ones(m, dtype=np.int8), np.arange(m) + 2, (40.0, -105.0, 1600.0), "llh")
    return imu_t, acc, sol


@pytest.mark.parametrize("delay", [-0.2, -0.05, 0.0, 0.13])
def test_imu_delay_recovers_a_known_offset(delay):
    imu_t, acc, sol = drive(delay)
    est = imu_delay(imu_t, acc, sol, G)
    assert est.delay_s == pytest.approx(delay, abs=0.01)
    assert est.epochs > 500
    if abs(delay) >= 0.05:
        assert est.rms_mps2 < est.rms_at_zero_mps2


def test_imu_delay_uses_only_the_epochs_given():
    imu_t, acc, sol = drive(-0.1, seconds=200.0)
    use = np.zeros(len(sol.t_ns), bool)
    use[:200] = True
    est = imu_delay(imu_t, acc, sol, G, use=use)
    assert est.epochs <= 198 and est.delay_s == pytest.approx(-0.1, abs=0.02)
    use[:] = False
    use[:30] = True
    with pytest.raises(InvalidInputError, match="too few"):
        imu_delay(imu_t, acc, sol, G, use=use)


def test_imu_delay_refuses_a_best_match_at_the_grid_edge():
    imu_t, acc, sol = drive(-0.3)
    with pytest.raises(InvalidInputError, match="edge"):
        imu_delay(imu_t, acc, sol, G, grid_s=(-0.2, 0.2, 0.01))


def testdouble_integral_is_exact_for_piecewise_linear():
    t = np.sort(np.random.default_rng(2).uniform(0.0, 3.0, 40))
    t = np.r_[0.0, t]
    y = 2.0 + 3.0 * t  # linear: F = t^2 + t^3 / 2
    assert np.allclose(double_integral(t, y), t ** 2 + t ** 3 / 2, rtol=1e-12, atol=1e-12)


def test_navigate_reads_the_fixes_once_for_the_delay_the_noise_fit_and_the_rows(tmp_path, monkeypatch):
    """``--imu-delay-s auto`` with no noise given (the noise fitted from the fixes too): navigate reads
    the .pos once, and the delay it adds is :func:`imu_delay`'s on the same file read apart."""
    from pathlib import Path

    from imu_learn.data import formats
    from imu_learn.fuse import navigate as nav

    imu, pos, _ = synthetic_car(tmp_path)
    reads = []
    real = nav.read_pos
    monkeypatch.setattr(nav, "read_pos", lambda path: reads.append(Path(path)) or real(path))
    opts = nav.NavigateOptions(aiding_kind=None, aiding_format="auto", imu_rotation_rpy_deg=RPY, lever_arm=tuple(LEVER),
                               imu_delay_from="fixes")
    inp = nav.read_inputs(nav.Sources(imu, pos), opts)
    assert reads == [pos]
    assert "the aiding's innovations" in inp.imu.noise.source  # the noise fit ran, on the same solution
    src = formats.read_imu_source(imu, "gnss-imu")
    sol = rtklib.read_pos(pos)
    want = imu_delay(np.asarray(src.t_ns), np.asarray(src.acc), sol, rtklib.normal_gravity(*sol.origin_llh[::2]))
    assert inp.imu.delay["from"] == "fixes" and inp.imu.delay["delay_s"] == round(want.delay_s, 4)
    assert inp.imu.delay["epochs"] == want.epochs
    assert inp.imu.t_ns[0] - int(src.t_ns[0]) == int(round(inp.imu.delay["delay_s"] * 1e9))


def test_a_profiles_delay_is_checked_against_the_fixes(caplog):
    """navigate --profile with calibrate's reference.navigator delay (its own recording's): where this log's
    fixes fit it clearly worse than the delay they show, it is left out with one warning naming
    --imu-delay-s to keep it, and the delay is decided as with none given (the walk's profile on the car
    drive, before: 0 s applied without a word); a profile's delay the fixes fit about as well is kept."""
    import logging
    from pathlib import Path

    from imu_learn.fuse import navigate as nav

    imu_t, acc, sol = drive(-0.2)
    est = imu_delay(imu_t, acc, sol, G)
    assert est.rms_at(0.0) == pytest.approx(est.rms_at_zero_mps2) and est.rms_at(-0.2) < 0.9 * est.rms_at(0.0)
    prof = Path("profile.json")
    for given, want in ((0.0, -0.2), (0.2, -0.2)):
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            got = nav.profile_delay(sol, nav.NavigateOptions(imu_delay_s=given, imu_delay_from="profile"), imu_t, acc, prof)
        assert got["delay_s"] == pytest.approx(want, abs=0.01) and got["profile_s"] == given, got
        assert f"--imu-delay-s {given:g} keeps the profile's" in caplog.text
    on_time, acc0, sol0 = drive(0.0)  # fixes that show none: the profile's 0.2 s left out, none applied
    got = nav.profile_delay(sol0, nav.NavigateOptions(imu_delay_s=0.2, imu_delay_from="profile"), on_time, acc0, prof)
    assert got["delay_s"] == 0.0 and got["from"].startswith("none"), got
    for near in (-0.2, -0.19):
        kept = nav.profile_delay(sol, nav.NavigateOptions(imu_delay_s=near, imu_delay_from="profile"), imu_t, acc, prof)
        assert kept["delay_s"] == near and kept["from"] == "the profile's reference.navigator", kept
    far = nav.profile_delay(sol, nav.NavigateOptions(imu_delay_s=0.8, imu_delay_from="profile"), imu_t, acc, prof)
    assert far["delay_s"] == 0.8 and far["checked"].startswith("not checked"), far  # beyond the search: kept
    few = nav.profile_delay(sol, nav.NavigateOptions(imu_delay_s=0.0, imu_delay_from="profile"), imu_t[:300], acc[:300],
                            prof)
    assert few["delay_s"] == 0.0 and "not measured" in few["checked"], few


# --- the real drive (skipped without the data root) ------------------------------------------------

def _data_root():
    import os
    from pathlib import Path

    env = os.environ.get("IMU_LEARN_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"


DRIVE = _data_root() / "gnss-imu" / "drive_0708"


@pytest.mark.skipif(not (DRIVE / "imu_1934.csv").is_file(), reason="the gnss-imu drive is not on this machine "
                    "(set IMU_LEARN_DATA to the data root)")
def test_real_drive_timing():
    """The drive's IMU runs ~0.20 s behind its fixes (not the peer's -0.125 s), and its velocities lag
    the positions by half the 0.25 s epoch interval (docs/experiments/fusion_gnss.md)."""
    from imu_learn.data.formats import gnss_imu
    from imu_learn.fuse.factors.velocity import velocity_lag

    log = gnss_imu.read_imu_log(DRIVE / "imu_1934.csv", mounting=np.eye(3), delay_s=0.0)
    sol = rtklib.read_pos(DRIVE / "gnss_1934_sf.pos")
    est = imu_delay(log.imu.t_ns, log.imu.acc, sol, rtklib.normal_gravity(sol.origin_llh[0], sol.origin_llh[2]))
    assert -0.23 < est.delay_s < -0.17 and est.rms_mps2 < 0.8 * est.rms_at_zero_mps2
    lag = velocity_lag(sol)
    assert 0.10 < lag.lag_s < 0.15 and lag.rms_after_mps < 0.5 * lag.rms_before_mps
