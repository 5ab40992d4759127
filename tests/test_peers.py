"""The peers' open-loop protocols (imu_learn.score.peers): closed-form cases, an independent numpy /
scipy implementation on the shipped EuRoC crop, and the wiring into evaluate and its report."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_learn.baselines.base import Method, PosePrediction, Raw
from imu_learn.core.quat import xyzw_to_wxyz
from imu_learn.data.types import Segment
from imu_learn.eval import run as ev
from imu_learn.eval.report import _md_peers, peers_table, summary_text
from imu_learn.score import peers

G = 9.81


def _stamps(n, rate=200.0, jitter=0.0, seed=0):
    """Stamps [ns] at ``rate`` with up to ``jitter`` of a period of random jitter (strictly increasing)."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate * (1.0 + jitter * rng.uniform(-1, 1, n - 1))
    return np.concatenate([[0], np.cumsum(np.round(dt * 1e9))]).astype(np.int64) + 10**12


def _spinning(axis, rate_rad_s, bias_rad_s, n=1001, jitter=0.3, r0=None):
    """Constant rotation rate about ``axis`` from orientation ``r0``; gyro = rate + bias along the same axis."""
    t_ns = _stamps(n, jitter=jitter)
    t = (t_ns - t_ns[0]) * 1e-9
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    r0 = Rotation.identity() if r0 is None else r0
    rot = r0 * Rotation.from_rotvec(t[:, None] * rate_rad_s * axis)
    q = xyzw_to_wxyz(rot.as_quat())
    z = np.zeros((n, 3))
    gyro = np.tile((rate_rad_s + bias_rad_s) * axis, (n, 1))
    return Segment("spin", t_ns, gyro, z + [0, 0, G], z, z, q), t


@pytest.mark.parametrize("jitter", [0.0, 0.3])
def test_aoe_closed_form_tilted_axis(jitter):
    b = 0.08  # |bias| [rad/s]; 5 s -> 0.4 rad, far from the wrap at pi
    seq, t = _spinning([1.0, -2.0, 0.5], 0.7, b, jitter=jitter, r0=Rotation.from_rotvec([0.3, -0.2, 1.1]))
    e = peers.attitude_errors(seq)
    np.testing.assert_allclose(e["angle_rad"], b * t, atol=1e-12)
    acc = peers.PeerErrors()
    peers.add_segment(acc, peers.segment_errors(seq, seq.gyro, seq.acc, G))
    s = peers.summarise(acc)
    assert s["aoe_deg"] == pytest.approx(math.degrees(b * math.sqrt(np.mean(t**2))), rel=1e-10)
    assert s["aoe_mean_deg"] == pytest.approx(math.degrees(b * np.mean(t)), rel=1e-10)
    # the error is about a tilted axis: its yaw is smaller than the whole angle
    assert s["yaw_aoe_deg"] < 0.9 * s["aoe_deg"]
    # windows of 200 samples from the ground truth: each ends with an error of b * window duration
    w = peers.window_samples(seq)
    assert w == round(1e9 / np.median(np.diff(seq.t_ns)))
    k = peers.peer_window_starts(seq, w)
    if jitter == 0.0:
        assert w == 200
        np.testing.assert_array_equal(k, [0, 200, 400, 600, 800])  # non-overlapping, k + w <= N - 1
    np.testing.assert_array_equal(k, np.arange(0, len(seq) - w, w))
    win = peers.window_errors(seq, seq.gyro, seq.acc, w, G)
    np.testing.assert_allclose(win["rot_rad"], b * (t[k + w] - t[k]), atol=1e-12)


def test_pure_yaw_bias_gives_yaw_aoe_equal_to_aoe():
    b = -0.05
    seq, t = _spinning([0, 0, 1], 0.9, b, r0=Rotation.from_rotvec([0, 0, 2.0]))
    acc = peers.PeerErrors()
    peers.add_segment(acc, peers.segment_errors(seq, seq.gyro, seq.acc, G))
    s = peers.summarise(acc)
    assert s["aoe_deg"] == pytest.approx(math.degrees(abs(b) * math.sqrt(np.mean(t**2))), rel=1e-10)
    assert s["yaw_aoe_deg"] == pytest.approx(s["aoe_deg"], rel=1e-10)
    np.testing.assert_allclose(peers.attitude_errors(seq)["yaw_rad"], b * t, atol=1e-12)  # signed: R̂ Rᵀ = Rz(b t)


def test_exact_imu_on_constant_acceleration_gives_zero_rte():
    n = 1201
    t_ns = _stamps(n, jitter=0.2, seed=3)
    t = (t_ns - t_ns[0]) * 1e-9
    a = np.array([0.4, -0.3, 0.2])
    v0, p0 = np.array([1.0, 0.5, -0.2]), np.array([3.0, -1.0, 2.0])
    p = p0 + v0 * t[:, None] + 0.5 * a * t[:, None] ** 2
    v = v0 + a * t[:, None]
    r0 = Rotation.from_rotvec([0.4, -0.7, 0.9])
    q = np.tile(xyzw_to_wxyz(r0.as_quat()), (n, 1))
    acc = np.tile(r0.inv().apply(a - np.array([0, 0, -G])), (n, 1))
    seq = Segment("line", t_ns, np.zeros((n, 3)), acc, p, v, q)
    acc_e = peers.PeerErrors()
    peers.add_segment(acc_e, peers.segment_errors(seq, seq.gyro, seq.acc, G))
    s = peers.summarise(acc_e)
    assert s["windows"] == 6 and s["samples"] == n  # starts 0, 200, ..., 1000 (k + 200 <= 1200)
    assert s["rte_m"] < 1e-9 and s["rp_rmse_m"] < 1e-9
    assert s["aoe_deg"] < 1e-9 and s["ro_rmse_deg"] < 1e-9
    # a biased accelerometer is seen: RTE = ½ |b| T² for each 1 s window (no rotation)
    ba = np.array([0.02, 0.0, -0.01])
    win = peers.window_errors(seq, seq.gyro, seq.acc + ba, 200, G)
    k = win["starts"]
    np.testing.assert_allclose(win["trans_m"], 0.5 * np.linalg.norm(ba) * (t[k + 200] - t[k]) ** 2, rtol=1e-9)


# ---------------------------------------------------------------------------------------------
# an independent implementation: loops, scipy rotations, the same zero-order hold as the core
# (GTSAM's scheme: position and velocity use the rotation from before the sample, then R <- R Exp(w dt))


def _rot(q_wxyz):
    return Rotation.from_quat(np.concatenate([q_wxyz[..., 1:], q_wxyz[..., :1]], axis=-1))


def _independent(seq, w, gravity=G):
    n = len(seq)
    dt = np.diff(seq.t_ns).astype(np.float64) * 1e-9
    r_gt = _rot(seq.q_wxyz)
    r = r_gt[0]
    angles, yaws = [0.0], [0.0]
    for i in range(n - 1):
        r = r * Rotation.from_rotvec(seq.gyro[i] * dt[i])
        angles.append((r_gt[i + 1].inv() * r).magnitude())
        yaws.append((r * r_gt[i + 1].inv()).as_euler("ZYX")[0])
    g = np.array([0.0, 0.0, -gravity])
    rot_err, pos_err = [], []
    for k in range(0, n - w, w):
        r, v, p = r_gt[k], seq.v[k].copy(), seq.p[k].copy()
        for i in range(k, k + w):
            a = r.apply(seq.acc[i]) + g
            p = p + v * dt[i] + 0.5 * a * dt[i] ** 2
            v = v + a * dt[i]
            r = r * Rotation.from_rotvec(seq.gyro[i] * dt[i])
        rot_err.append((r_gt[k + w].inv() * r).magnitude())
        pos_err.append(np.linalg.norm(p - seq.p[k + w]))
    return np.array(angles), np.array(yaws), np.array(rot_err), np.array(pos_err)


def test_agrees_with_an_independent_implementation_on_the_euroc_crop(crop):
    seq = Segment(crop.name, crop.t_ns[:6001], crop.gyro[:6001], crop.acc[:6001], crop.p[:6001], crop.v[:6001],
                   crop.q_wxyz[:6001])  # 30 s: the raw gyro drifts by several degrees, far from any wrap
    w = peers.window_samples(seq)
    assert w == 200
    angles, yaws, rot_err, pos_err = _independent(seq, w)
    att = peers.attitude_errors(seq)
    assert angles.max() > math.radians(1.0)  # the test sees a real drift
    np.testing.assert_allclose(att["angle_rad"], angles, atol=1e-9)
    np.testing.assert_allclose(att["yaw_rad"], yaws, atol=1e-9)
    win = peers.window_errors(seq, seq.gyro, seq.acc, w, G)
    assert win["rot_rad"].size == rot_err.size == 30
    np.testing.assert_allclose(win["rot_rad"], rot_err, atol=1e-9)
    np.testing.assert_allclose(win["trans_m"], pos_err, atol=1e-9)
    acc = peers.PeerErrors()
    peers.add_segment(acc, peers.segment_errors(seq, seq.gyro, seq.acc, G))
    s = peers.summarise(acc)
    d = math.degrees
    assert s["aoe_deg"] == pytest.approx(d(np.sqrt(np.mean(angles**2))), abs=1e-7)
    assert s["yaw_aoe_deg"] == pytest.approx(d(np.sqrt(np.mean(yaws**2))), abs=1e-7)
    assert s["roe_deg"] == pytest.approx(d(rot_err.mean()), abs=1e-7)
    assert s["ro_rmse_deg"] == pytest.approx(d(np.sqrt(np.mean(rot_err**2))), abs=1e-7)
    assert s["rte_m"] == pytest.approx(pos_err.mean(), abs=1e-9)
    assert s["rp_rmse_m"] == pytest.approx(np.sqrt(np.mean(pos_err**2)), abs=1e-9)


def test_segments_are_pooled_each_from_its_own_start(crop):
    a = Segment("r#0", *(x[:2001] for x in (crop.t_ns, crop.gyro, crop.acc, crop.p, crop.v, crop.q_wxyz)))
    b = Segment("r#1", *(x[3000:5001] for x in (crop.t_ns, crop.gyro, crop.acc, crop.p, crop.v, crop.q_wxyz)))
    pooled = peers.PeerErrors()
    for s in (a, b):
        peers.add_segment(pooled, peers.segment_errors(s, s.gyro, s.acc, G))
    got = peers.summarise(pooled)
    ea, eb = (peers.attitude_errors(s)["angle_rad"] for s in (a, b))
    assert ea[0] < 1e-12 and eb[0] < 1e-12  # each segment starts from its own ground truth
    assert got["aoe_deg"] == pytest.approx(math.degrees(np.sqrt(np.mean(np.concatenate([ea, eb]) ** 2))), rel=1e-12)
    assert got["segments"] == 2 and got["samples"] == 4002 and got["windows"] == 20


# ---------------------------------------------------------------------------------------------
# wiring: evaluate_sequence, the result rows, the report


class _Regressor(Method):
    """Overrides predict: the ground-truth end orientation, no position."""

    def predict(self, seq, starts, n, gravity=9.81):
        return PosePrediction(seq.q_wxyz[np.asarray(starts, dtype=np.int64) + n], None, None)


class _RotationOnly(Raw):
    rotation_only = True


def test_evaluate_sequence_fills_the_peer_errors(crop):
    seq = Segment(crop.name, *(x[:2401] for x in (crop.t_ns, crop.gyro, crop.acc, crop.p, crop.v, crop.q_wxyz)))
    d = {}
    ev.evaluate_sequence(Raw(), seq, [10], 10, 2.0, G, peers=d)
    ref = peers.segment_errors(seq, seq.gyro, seq.acc, G)
    np.testing.assert_array_equal(d["angle_rad"], ref["angle_rad"])
    np.testing.assert_array_equal(d["trans_m"], ref["trans_m"])
    d = {}
    ev.evaluate_sequence(_RotationOnly(), seq, [10], 10, 2.0, G, peers=d)
    assert d["trans_m"] is None and d["rot_rad"].size == 12
    d = {}
    ev.evaluate_sequence(_Regressor(), seq, [10], 10, 2.0, G, peers=d)
    assert d["angle_rad"] is None and d["trans_m"] is None
    np.testing.assert_allclose(d["rot_rad"], 0.0, atol=1e-7)
    acc = peers.PeerErrors()
    peers.add_segment(acc, d)
    s = peers.summarise(acc)
    assert math.isnan(s["aoe_deg"]) and math.isnan(s["rte_m"]) and s["ro_rmse_deg"] < 1e-5

    result = {"methods": ["raw", "reg"], "test_sequences": ["A", "B"], "config_name": "x", "stride": 10,
              "startup_bias_s": 2.0, "eval": {"horizons": [10]}, "rows": [], "skipped": [],
              "peers": [{"method": "raw", "sequence": q, **peers.summarise(p)} for q, p in
                        (("A", _pool(seq)), ("B", _pool(seq)))]
              + [{"method": "reg", "sequence": "A", **s}]}
    table = peers_table(result)
    assert [(x["method"], x["sequence"]) for x in table] == [("raw", "A"), ("raw", "B"), ("raw", "average"), ("reg", "A")]
    md = "\n".join(_md_peers(result, table))
    assert "| reg | A | - | - | - |" in md and "AOE [deg]" in md
    text = summary_text({**result, "eval": {"horizons": [10], "airimu_s": [1.0]}, "horizons_by_s": {}})
    assert "AOE [deg] / RO_RMSE 1 s [deg]" in text


def _pool(seq):
    acc = peers.PeerErrors()
    peers.add_segment(acc, peers.segment_errors(seq, seq.gyro, seq.acc, G))
    return acc


def test_masked_aoe_bridges_gaps_and_counts_only_measured_samples():
    """The gyro runs through a ground-truth gap; the error grows there (b t) but is counted only where
    ground truth was measured: closed form over the kept samples; covered() against a hand-made case."""
    b = 0.03
    seq, t = _spinning([0.2, 1.0, -0.4], 0.5, b, n=2001, jitter=0.0)
    gt_t = np.r_[seq.t_ns[:600], seq.t_ns[1100:]]  # 2.5 s without ground truth
    m = peers.covered(seq.t_ns, gt_t, max_gap_s=0.05)
    assert m[:600].all() and not m[600:1100].any() and m[1100:].all()
    r = peers.masked_aoe(seq, seq.gyro, m)
    kept = t[m]
    assert r["aoe_deg"] == pytest.approx(math.degrees(b * math.sqrt(np.mean(kept**2))), rel=1e-10)
    assert r["samples"] == 1501 and r["bridged"] == 500
    # a stamp between two ground-truth stamps 0.04 s apart is measured, one halfway across 0.06 s is not
    g = np.array([0, 40_000_000, 100_000_000], dtype=np.int64)
    np.testing.assert_array_equal(peers.covered(np.array([0, 20_000_000, 70_000_000, 100_000_000]), g, 0.05),
                                  [True, True, False, True])
    with pytest.raises(ValueError, match="first sample"):
        peers.masked_aoe(seq, seq.gyro, ~m)
