"""Relative-pose aiding with breaks in one map (fuse/aiding/maps.py): on the synthetic flight of
test_aiding_world.py, a 3 s break in the same world passes the check against the IMU's dead reckoning
and a map restarted after it (its first pose the identity at the origin, as a visual odometry that
reinitialises writes) fails it; one map ties every run to the world in both passes, so the causal
and the smoothed tracks after the break lie closer to the truth than the chained ones, and the rows just
after the break put the causal track back on the map at once."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("gtsam")

from imu_learn.fuse.aiding import kinds as kinds_module  # noqa: E402
from imu_learn.fuse.aiding.kinds import KINDS  # noqa: E402
from imu_learn.fuse.aiding.maps import one_map  # noqa: E402
from imu_learn.fuse.aiding.spans import REJOIN_INFLATE, world_inflation  # noqa: E402
from imu_learn.fuse.graph import IncrementalFusion, feed, samples_of  # noqa: E402
from imu_learn.fuse.navigate import NavigateOptions  # noqa: E402
from imu_learn.fuse.settings import FusionSettings  # noqa: E402
from test_aiding_world import rows_of, vo_flight  # noqa: E402


@pytest.fixture(scope="module")
def broken():
    t_ns, gyro, acc, R, p, v0, (sample, R_A, p_A, _) = vo_flight()
    t = (t_ns[sample] - t_ns[0]) * 1e-9
    gap = (t >= 10.0) & (t < 13.0)
    return t_ns, gyro, acc, R, p, v0, sample, R_A, p_A, gap


def check(t_ns, gyro, acc, rows):
    return one_map(t_ns, gyro, acc, rows.sample, rows.t_ns, rows.p, rows.R, 0.5)


def test_a_break_in_one_map_passes_and_a_restarted_map_fails(broken):
    t_ns, gyro, acc, R, p, v0, sample, R_A, p_A, gap = broken
    rows = rows_of(t_ns, gyro, acc, sample, R_A, p_A, gap)
    same = check(t_ns, gyro, acc, rows)
    assert same is not None and same.verdict and len(same.breaks) == 1, same
    b = same.breaks[0]
    assert b["rotation_deg"] < 0.3 * b["rotation_bound_deg"] and b["translation_miss_m"] < 0.5 * b["translation_bound_m"], b
    # after the break, a new map: the first pose after it is the identity at the origin
    first = int(np.argmax(gap)) + int(gap.sum())
    R_new, p_new = R_A.copy(), p_A.copy()
    R_new[first:] = np.einsum("ji,njk->nik", R_A[first], R_A[first:])
    p_new[first:] = (p_A[first:] - p_A[first]) @ R_A[first]
    new = check(t_ns, gyro, acc, rows_of(t_ns, gyro, acc, sample, R_new, p_new, gap))
    assert new is not None and not new.verdict and "new map" in new.why, new
    assert check(t_ns, gyro, acc, rows_of(t_ns, gyro, acc, sample, R_A, p_A)) is None  # no break


def test_a_raw_gyros_bias_is_taken_off_before_a_long_break_is_judged(broken):
    """A raw MEMS gyro (EuRoC's ADIS16448 reads 80 mrad/s off on z): over a 10 s break its chain is 46°
    off, above the rotation bound (about 6-9°) though the map is one; the bias measured against the
    aiding's increments on either side is taken off first. The restarted map still fails."""
    t_ns, gyro, acc, R, p, v0, sample, R_A, p_A, _ = broken
    t = (t_ns[sample] - t_ns[0]) * 1e-9
    gap = (t >= 12.0) & (t < 22.0)
    bias = np.array([0.01, -0.02, 0.08])
    raw = gyro + bias
    same = check(t_ns, raw, acc, rows_of(t_ns, raw, acc, sample, R_A, p_A, gap))
    assert same is not None and same.verdict, same
    b = same.breaks[0]
    assert b["duration_s"] > 9.9 and b["rotation_deg"] < 2.0, b
    # the bias found is the one added (the flight's own 2 mrad/s on top)
    assert np.allclose(b["gyro_bias_rad_s"], bias + 0.002, atol=2e-3), b
    first = int(np.argmax(gap)) + int(gap.sum())
    R_new, p_new = R_A.copy(), p_A.copy()
    R_new[first:] = np.einsum("ji,njk->nik", R_A[first], R_A[first:])
    p_new[first:] = (p_A[first:] - p_A[first]) @ R_A[first]
    new = check(t_ns, raw, acc, rows_of(t_ns, raw, acc, sample, R_new, p_new, gap))
    assert new is not None and not new.verdict, new


def test_one_map_ties_its_world_in_both_passes(broken, monkeypatch):
    t_ns, gyro, acc, R, p, v0, sample, R_A, p_A, gap = broken
    kind, opts = KINDS["relative-pose"], NavigateOptions()

    def fused(maps: bool):
        rows = rows_of(t_ns, gyro, acc, sample, R_A, p_A, gap)
        rows.maps = check(t_ns, gyro, acc, rows) if maps else None
        a, counts = kind.build(rows, 0, np.eye(3), np.zeros(3), opts, "vo", "")
        inc = IncrementalFusion(t_ns, (R[0], p[0], v0), [a], FusionSettings(lag_s=3.0), predict_between=False)
        feed(inc, samples_of(gyro, acc))
        return inc.smooth(), counts, a

    chained, _, a0 = fused(False)
    tied, counts, a1 = fused(True)
    assert a0.world is None and a1.world is not None
    ratio = a1.world.causal_sigmas / a1.world.sigmas  # x100 at 20 Hz; the rejoining rows' translation x10
    rejoin = ratio[:, 3] != ratio[:, 0]
    np.testing.assert_allclose(ratio[~rejoin], world_inflation(t_ns[sample][~gap]))
    assert counts["world_poses"] == tied.counts["world_pose_factors"] == int((~gap).sum())
    at = np.isin(tied.kf_idx, sample)
    after = at & (tied.kf_idx > sample[np.argmax(gap)])

    def rmse(x, where=at):
        return float(np.sqrt(np.mean(np.sum((x[where] - p[tied.kf_idx[where]]) ** 2, axis=1))))

    # one world across the break (the chained tracks are tied across it by the IMU alone); the causal
    # track as the solver held it, mapped by the final world (FusionResult's causal frame)
    assert rmse(tied.smoothed_p) < 0.8 * rmse(chained.smoothed_p), (rmse(tied.smoothed_p), rmse(chained.smoothed_p))
    assert rmse(tied.causal_p, after) < 0.8 * rmse(chained.causal_p, after), (rmse(tied.causal_p, after),
                                                                             rmse(chained.causal_p, after))
    # the rows of the first half second after the break rejoin the map at 10x their translation noise (not
    # 100x): the causal track is back on it within the first second, where the inflated world takes longer
    np.testing.assert_allclose(ratio[rejoin], np.r_[np.full(3, world_inflation(t_ns[sample][~gap])),
                                                    np.full(3, REJOIN_INFLATE)][None, :].repeat(rejoin.sum(), 0))
    assert rejoin.sum() == 10 and a1.world.idx[rejoin][0] == sample[np.argmax(gap) + gap.sum()]
    monkeypatch.setattr(kinds_module, "rejoining", lambda t_ns, max_gap_s: np.zeros(len(t_ns), bool))
    slow, _, _ = fused(True)
    t_kf = (t_ns[tied.kf_idx] - t_ns[sample[np.argmax(gap) + gap.sum()]]) * 1e-9
    first = at & (t_kf >= 0) & (t_kf < 1.0)  # measured 0.013 m against 0.050
    assert rmse(tied.causal_p, first) < 0.5 * rmse(slow.causal_p, first), (rmse(tied.causal_p, first),
                                                                           rmse(slow.causal_p, first))
