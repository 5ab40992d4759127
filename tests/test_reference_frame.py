"""A reference in another frame, world, clock or scale is moved into the IMU's (calib.reference),
checked against the truth a synthetic trajectory was made from; what cannot be resolved is refused;
what a profile may be is bounded (calib.plausible)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_learn.calib.plausible import held_back_findings, parameter_findings
from imu_learn.calib.reference import Extrinsics, FrameOptions, level_rotation, resolve_frame, to_imu_frame
from imu_learn.core.quat import quat_conj, quat_from_matrix, quat_mul, quat_rotate
from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import ReferenceFrameError
from imu_learn.score.metrics import simulate_sequence


def rot(axis, deg) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = math.radians(deg)
    return np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * k @ k


def quat(r: np.ndarray) -> np.ndarray:
    return quat_from_matrix(r)


def flight(seconds=60.0, rate=200.0, seed=0, planar=False):
    """An exact IMU (gyro bias 0.01 rad/s on x) and its true trajectory: tilting and turning motion
    near hover."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    w = np.zeros((len(t), 3))
    for i in range(3):
        if planar and i < 2:
            continue
        for f in rng.uniform(0.1, 0.8, 3):
            w[:, i] += rng.uniform(0.2, 0.5) * np.sin(2 * math.pi * f * t + rng.uniform(0, 6))
    acc = np.tile([0.0, 0.0, 9.81], (len(t), 1)) + 0.5 * np.sin(2 * math.pi * 0.3 * t)[:, None] * [1, -1, 0.5]
    acc[:, 1] += 0.4 * np.sin(2 * math.pi * 0.7 * t + 1.0)  # a second direction (a robot's centripetal)
    t_ns = (1e9 + t * 1e9).astype(np.int64)
    seg = simulate_sequence(t_ns, w, acc)
    bias = np.array([0.01, 0.0, 0.0])
    return ImuData(t_ns=t_ns, gyro=w + bias, acc=acc), seg


def reference_of(seg, r_imu_ref=np.eye(3), world=np.eye(3), lever=np.zeros(3), lag_s=0.0, rate=30.0, scale=1.0):
    """The true IMU poses seen by a sensor whose frame is r_imu_ref^T of the IMU's, at ``lever`` (the
    IMU origin in the sensor frame), in a world rotated by ``world``, ``scale`` times the metres, its
    stamps ``lag_s`` late, sampled at ``rate``."""
    step = int(round(200 / rate))
    idx = np.arange(0, len(seg), step)
    q_wi = seg.q_wxyz[idx]
    q_ws = quat_mul(q_wi, quat(r_imu_ref)[None])  # R_WS = R_WI R_IS
    p_ws = seg.p[idx] - quat_rotate(q_ws, np.broadcast_to(lever, (len(idx), 3)))
    qw = quat(world)[None]
    return GroundTruth(t_ns=seg.t_ns[idx] + int(lag_s * 1e9), p=scale * (p_ws @ world.T),
                       q_wxyz=quat_mul(qw, q_ws))


def angle_deg(r: np.ndarray) -> float:
    return math.degrees(math.acos(np.clip((np.trace(r) - 1) / 2, -1, 1)))


def test_a_given_extrinsic_the_rates_contradict_is_refused_and_one_they_confirm_is_used():
    # a reference in a frame 0.6° off the file's (ORB-SLAM2's rectified left camera against EuRoC's cam0):
    # the floor's gyroscope matrix would take the 0.6° up and harm every other recording
    imu, seg = flight()
    r_true = rot([1, 2, 3], 90.0)
    ref = reference_of(seg, r_true)
    lever = np.zeros(3)
    fit = resolve_frame([(imu, ref)], extrinsics=Extrinsics(r_true, lever, "true.yaml"))
    assert angle_deg(fit.r_imu_ref @ r_true.T) < 1e-9 and fit.method == "true.yaml"
    near = rot([1, 0, 0], 0.2) @ r_true  # within the tolerance (a calibration's own error): used as given
    assert angle_deg(resolve_frame([(imu, ref)], extrinsics=Extrinsics(near, lever, "near.yaml")).r_imu_ref
                     @ near.T) < 1e-9
    off = rot([1, 0.5, -0.2], 0.6) @ r_true
    with pytest.raises(ReferenceFrameError, match=r"off\.yaml.*0\.6.° off the one the rotation rates give") as e:
        resolve_frame([(imu, ref)], extrinsics=Extrinsics(off, lever, "off.yaml"))
    assert "T_SB" not in str(e.value)
    # the file inverted (T_SB, the IMU in the camera's frame): named as such, not as a rectified camera's
    with pytest.raises(ReferenceFrameError, match=r"its inverse 0\.0.°: the file holds T_SB"):
        resolve_frame([(imu, ref)], extrinsics=Extrinsics(r_true.T, lever, "inverted.yaml"))
    # another recording's reference (here the motion's rates mirrored on one axis): the file, whatever the extrinsic
    mirrored = ImuData(imu.t_ns, imu.gyro * [1.0, 1.0, -1.0], imu.acc)
    with pytest.raises(ReferenceFrameError, match="do not match the IMU's in any frame"):
        resolve_frame([(mirrored, ref)], extrinsics=Extrinsics(r_true, lever, "true.yaml"))


def test_a_reference_in_the_imu_frame_is_left_untouched():
    imu, seg = flight()
    ref = reference_of(seg, rate=200.0)
    fit = resolve_frame([(imu, ref)])
    assert fit.in_imu_frame, fit.applied
    assert to_imu_frame(ref, fit, 0) is ref
    assert np.allclose(fit.gyro_bias, [0.01, 0, 0], atol=2e-3)


@pytest.mark.parametrize("deg", [90.0, 119.0, 180.0])
def test_a_rotated_tilted_late_reference_is_resolved(deg):
    imu, seg = flight()
    r_true = rot([1, 2, 3], deg)
    world = rot([1, 0, 0], 100.0)  # a camera's first frame: z forward
    lever = np.array([0.10, -0.05, 0.02])
    ref = reference_of(seg, r_true, world, lever, lag_s=0.1)
    fit = resolve_frame([(imu, ref)])
    assert angle_deg(fit.r_imu_ref @ r_true.T) < 0.3
    assert fit.lag_s == pytest.approx(0.1, abs=0.006)
    assert fit.applied["level"] and fit.applied["lag"] and fit.applied["rotation"]
    assert fit.tilt_deg == pytest.approx(100.0, abs=1.0)
    assert fit.scale == pytest.approx(1.0, abs=0.02) and not fit.applied["scale"]
    moved = to_imu_frame(ref, fit, 0)
    # the moved reference is the IMU's pose up to a yaw of the world: compare relative rotations and
    # the vertical, which no yaw changes
    k = np.searchsorted(seg.t_ns, moved.t_ns[10:-10])
    q_true = seg.q_wxyz[k]
    rel_true = quat_mul(quat_conj(q_true[:-30]), q_true[30:])
    rel_mov = quat_mul(quat_conj(moved.q_wxyz[10:-10][:-30]), moved.q_wxyz[10:-10][30:])
    err = quat_mul(quat_conj(rel_true), rel_mov)
    assert np.degrees(2 * np.arcsin(np.clip(np.linalg.norm(err[:, 1:], axis=1), 0, 1))).max() < 1.0
    up_true = quat_rotate(quat_conj(q_true), np.broadcast_to([0, 0, 1.0], (len(k), 3)))
    up_mov = quat_rotate(quat_conj(moved.q_wxyz[10:-10]), np.broadcast_to([0, 0, 1.0], (len(k), 3)))
    assert np.degrees(np.arccos(np.clip(np.sum(up_true * up_mov, 1), -1, 1))).max() < 1.0


def test_a_vos_glitches_do_not_tilt_the_frame():
    """A 20 Hz reference 90° off the IMU whose orientation jumps now and then (a VO's relocalisations: every
    40th pose turned 3° about one axis for one frame) ; the plain Kabsch fit of the rate windows is pulled
    off by more than 0.15° (about the size that moved a multirotor's accelerometer bias across its thrust
    axis on EuRoC, docs/experiments/references.md), the frame calibrate resolves (its fit trimmed of the
    windows beyond 3 robust sigmas, calib.frames.trimmed_kabsch) stays within 0.05° of the truth."""
    from imu_learn.calib.frames import fit_offset, segments

    imu, seg = flight(seconds=120.0)
    r_true = rot([1, 2, 3], 90.0)
    ref = reference_of(seg, r_true, rate=20.0)
    q = ref.q_wxyz.copy()
    q[::30] = quat_mul(q[::30], quat(rot([0, 1, 0.3], 5.0))[None])
    glitched = GroundTruth(t_ns=ref.t_ns, p=ref.p, q_wxyz=q)
    segs = segments(imu, glitched, 0.2)
    plain = fit_offset(segs, m=20, max_shift=4)
    assert angle_deg(plain.r_off @ r_true.T) > 0.15
    assert angle_deg(fit_offset(segs, m=20, max_shift=4, trim=True).r_off @ r_true.T) < 0.05
    assert angle_deg(resolve_frame([(imu, glitched)]).r_imu_ref @ r_true.T) < 0.05


def test_a_monocular_scale_is_estimated_and_applied():
    imu, seg = flight()
    ref = reference_of(seg, rot([0, 1, 1], 45), scale=0.5)
    fit = resolve_frame([(imu, ref)])
    assert fit.scale == pytest.approx(2.0, rel=0.03) and fit.applied["scale"]  # metres per reference unit
    moved = to_imu_frame(ref, fit, 0)
    k = np.searchsorted(seg.t_ns, moved.t_ns)
    assert np.ptp(moved.p[:, 2]) == pytest.approx(np.ptp(seg.p[k, 2]), rel=0.03)


@pytest.mark.parametrize("scale", [0.93, 1.08])
def test_a_scale_a_few_percent_off_is_applied(scale):
    """A reference 7-8 % off metric (a monocular VO's scale, a stereo rig's baseline): the rule of
    calib.metric_scale (5 % and 4 standard errors) applies it; the rule before (25 %) took it for metric,
    and the accelerometer's floor absorbed it (on EuRoC's ORB-SLAM2 poses x0.93: acc bias 0.81 m/s^2)."""
    imu, seg = flight()
    ref = reference_of(seg, rot([0, 1, 1], 45), rot([1, 0, 0], 100.0), scale=scale)
    fit = resolve_frame([(imu, ref)])
    assert fit.applied["scale"] and fit.scale == pytest.approx(1 / scale, rel=0.01), (fit.scale, fit.scale_std)


def test_planar_motion_takes_the_rotation_from_specific_force():
    imu, seg = flight(planar=True)
    r_true = rot([1, 2, 3], 119)
    fit = resolve_frame([(imu, reference_of(seg, r_true))])
    assert "specific force" in fit.method
    assert angle_deg(fit.r_imu_ref @ r_true.T) < 1.0


def test_planar_motion_without_horizontal_acceleration_is_refused():
    imu, seg = flight(planar=True)
    still = ImuData(imu.t_ns, imu.gyro, np.tile([0.0, 0.0, 9.81], (len(imu.t_ns), 1)))
    seg = simulate_sequence(imu.t_ns, imu.gyro - [0.01, 0, 0], still.acc)
    with pytest.raises(ReferenceFrameError, match="one axis only.*--extrinsics"):
        resolve_frame([(still, reference_of(seg, rot([1, 2, 3], 119)))])


def test_positions_only_is_refused():
    imu, seg = flight()
    ref = reference_of(seg)
    ref = GroundTruth(ref.t_ns, ref.p, np.tile([1.0, 0, 0, 0], (len(ref.t_ns), 1)))
    with pytest.raises(ReferenceFrameError, match="positions only"):
        resolve_frame([(imu, ref)])


def test_planar_odometry_is_the_odometry_source_s_not_the_6dof_path():
    from imu_learn.calib.odometry import is_planar_odometry

    imu, seg = flight(planar=True)
    ref = reference_of(seg, rot([0, 0, 1], 119), lag_s=0.091)
    ref = GroundTruth(ref.t_ns, ref.p * [1, 1, 0], ref.q_wxyz)  # yaw-only quaternions (planar motion), z = 0
    assert is_planar_odometry(ref)  # calibrate's source selection reads it as odometry (calib.odometry)
    with pytest.raises(ReferenceFrameError, match="planar.*wheel odometry.*reads it as odometry"):
        resolve_frame([(imu, ref)])


def test_another_recordings_reference_is_refused():
    imu, seg = flight(seed=0)
    _, other = flight(seed=5)
    with pytest.raises(ReferenceFrameError, match="does not follow the IMU"):
        resolve_frame([(imu, reference_of(other))])


def test_a_pair_that_does_not_overlap_is_named():
    """Two recordings, the second's reference on another clock (no overlap): the one line names that pair
    (it said "the reference overlaps the IMU for 0.0 s" with no name)."""
    imu, seg = flight(seed=0)
    imu2, seg2 = flight(seed=1)
    late = reference_of(seg2)
    late = GroundTruth(late.t_ns + int(1e12), late.p, late.q_wxyz)
    with pytest.raises(ReferenceFrameError, match=r"^room3: the reference overlaps the IMU for 0\.0 s"):
        resolve_frame([(imu, reference_of(seg)), (imu2, late)], names=["room1", "room3"])


def test_a_lag_beyond_the_search_is_refused():
    imu, seg = flight(seconds=80)
    ref = reference_of(seg, lag_s=3.0)
    with pytest.raises(ReferenceFrameError):
        resolve_frame([(imu, ref)], FrameOptions(max_lag_s=1.0))


def test_level_rotation_takes_the_vector_up():
    for v in ([0.3, -4, 2], [0, 0, -1], [0, 0, 1]):
        r = level_rotation(np.asarray(v, float))
        assert np.allclose(r @ (np.asarray(v) / np.linalg.norm(v)), [0, 0, 1], atol=1e-12)
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-12)


def floor(**kw):
    d = {"M_g": np.eye(3), "b_g": np.zeros(3), "M_a": np.eye(3), "b_a": np.zeros(3)}
    d.update(kw)
    return d


def test_plausibility_names_the_parameter():
    assert parameter_findings(floor(), 9.81) == []
    f = parameter_findings(floor(M_a=np.eye(3) * 9.81), 9.81)
    assert {x.field for x in f} == {"accelerometer.matrix[0][0]", "accelerometer.matrix[1][1]", "accelerometer.matrix[2][2]"}
    assert "g read as m/s^2" in f[0].message
    mis = np.eye(3)
    mis[2, 1] = 0.16  # 9.1°
    assert [x.field for x in parameter_findings(floor(M_a=mis), 9.81)] == ["accelerometer.matrix[2][1]"]
    assert [x.field for x in parameter_findings(floor(b_g=np.array([0, -2.1, 0])), 9.81)] == ["gyroscope.bias"]
    assert [x.field for x in parameter_findings(floor(b_a=np.array([95.9, 0, 0])), 9.81)] == ["accelerometer.bias"]
    zero_row = np.eye(3)
    zero_row[0] = 0
    assert [x.field for x in parameter_findings(floor(M_g=zero_row), 9.81)] == ["gyroscope.matrix[0]"]
    assert [x.field for x in parameter_findings(floor(), 6.89)] == ["gravity_mps2"]


def test_the_held_back_block_must_not_get_worse():
    base = {"window_samples": 200, "raw_rot_deg": 1.0, "raw_trans_m": 0.1}
    assert held_back_findings({**base, "profile_rot_deg": 0.5, "profile_trans_m": 0.101}) == []
    assert [f.field for f in held_back_findings({**base, "profile_rot_deg": 1.5, "profile_trans_m": 0.05})] == [
        "held_back.rotation"]
    assert [f.field for f in held_back_findings({**base, "profile_rot_deg": 0.5, "profile_trans_m": 0.2})] == [
        "held_back.translation"]


def test_a_sparse_reference_does_not_resolve_the_accelerometer():
    from imu_learn.calib.reference import resolves_acceleration

    assert resolves_acceleration(200.0, 1.0) and resolves_acceleration(120.0, 1.0)  # EuRoC, TUM-VI motion capture
    assert resolves_acceleration(90.0, 2.0)  # Fetch: 90 Hz motion capture, a 100 Hz IMU's 200-sample window
    assert not resolves_acceleration(20.0, 1.0) and not resolves_acceleration(30.0, 1.0)  # VO / SLAM
    imu, seg = flight()
    assert not resolve_frame([(imu, reference_of(seg, rate=20.0))]).resolves_acceleration
    assert resolve_frame([(imu, reference_of(seg, rate=200.0))]).resolves_acceleration
