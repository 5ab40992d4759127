"""The IMU noise fitted from the aiding's innovations (imu_learn.fuse.noise_fit): a synthetic IMU
with known white noise, position and pose aiding; the class default 10x too quiet or too noisy."""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_learn.fuse.noise import ImuNoise
from imu_learn.fuse.noise_fit import FACTOR_BOUNDS, fit_noise, fitted_noise

G = 9.81
RATE = 200.0
TRUE_GYRO, TRUE_ACC = 2e-3, 2e-2  # the IMU's white noise [rad/s/sqrt(Hz)], [m/s^2/sqrt(Hz)]
AID_SIGMA_M = 0.002
BIAS = np.array([0.05, -0.03, 0.08])


def recording(seconds: float = 240.0, aid_hz: float = 10.0, seed: int = 0):
    """(t_ns, noisy gyro, noisy acc, aiding stamps, noisy positions, rotations): the IMU's exact
    samples integrated under a zero-order hold give the true trajectory."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE) + 1
    dt = 1.0 / RATE
    t = np.arange(n) * dt
    w = np.c_[0.3 * np.sin(0.5 * t), 0.2 * np.cos(0.9 * t), 0.4 + 0.2 * np.sin(0.3 * t)]
    a_w = np.c_[np.sin(0.4 * t), 0.8 * np.cos(0.7 * t), 0.3 * np.sin(1.3 * t)]
    steps = Rotation.from_rotvec(w[:-1] * dt).as_matrix()
    R = np.empty((n, 3, 3))
    R[0] = np.eye(3)
    for k in range(n - 1):
        R[k + 1] = R[k] @ steps[k]
    f = np.einsum("nji,nj->ni", R, a_w - np.array([0.0, 0.0, -G]))
    v = np.r_[np.zeros((1, 3)), np.cumsum(a_w[:-1] * dt, axis=0)]
    p = np.r_[np.zeros((1, 3)), np.cumsum(v[:-1] * dt + 0.5 * a_w[:-1] * dt ** 2, axis=0)]
    t_ns = 10 ** 18 + np.arange(n, dtype=np.int64) * 5_000_000
    gyro = w + rng.normal(0, TRUE_GYRO / np.sqrt(dt), w.shape)
    acc = f + rng.normal(0, TRUE_ACC / np.sqrt(dt), f.shape) + BIAS  # with a bias
    idx = np.arange(0, n, int(RATE / aid_hz))
    return t_ns, gyro, acc, t_ns[idx], p[idx] + rng.normal(0, AID_SIGMA_M, (len(idx), 3)), R[idx]


def scaled_default(k: float) -> ImuNoise:
    return ImuNoise(k * TRUE_GYRO, k * TRUE_ACC, 1e-5, 1e-3, source="test class")


@pytest.mark.parametrize("wrong", [0.1, 10.0])
@pytest.mark.parametrize("kind", ["position", "pose"])
def test_the_fitted_densities_are_within_two_of_the_truth(wrong, kind):
    t_ns, gyro, acc, aid_t, p, R = recording()
    default = scaled_default(wrong)
    fit = fit_noise(t_ns, gyro, acc, aid_t, p, R if kind == "pose" else None, G, default=default)
    assert fit.used, fit.reason
    noise = fitted_noise(fit, default)
    assert 0.5 < noise.acc_noise_density / TRUE_ACC < 2.0, fit
    assert 0.5 < noise.gyro_noise_density / TRUE_GYRO < 2.0, fit
    assert 0.5 < fit.aiding_sigma_m / AID_SIGMA_M < 2.0, fit
    assert 0.7 < fit.chi2_ratio < 1.4, fit
    assert noise.source.startswith("fitted from the aiding's innovations: x")


def test_a_factor_outside_the_bounds_falls_back_to_the_class_default_and_says_so():
    t_ns, gyro, acc, aid_t, p, _ = recording(seconds=120.0)
    default = scaled_default(1e-3)  # the truth is 1000x the "class default"
    fit = fit_noise(t_ns, gyro, acc, aid_t, p, None, G, default=default)
    assert not fit.used and fit.factor > FACTOR_BOUNDS[1]
    noise = fitted_noise(fit, default)
    assert noise.acc_noise_density == default.acc_noise_density
    assert "outside [0.05, 100]" in noise.source


def test_too_few_aiding_rows_give_no_fit():
    t_ns, gyro, acc, aid_t, p, _ = recording(seconds=1.5)
    fit = fit_noise(t_ns, gyro, acc, aid_t, p, None, G)
    assert not fit.used and fit.factor is None and "2 needed" in fit.reason


def write_asl(root, t_ns, gyro, acc, aid_t, p):
    """An ASL IMU folder without sensor.yaml and the aiding's positions (TUM, 4 columns)."""
    imu = root / "rec" / "mav0" / "imu0"
    imu.mkdir(parents=True)
    rows = [f"{k},{w[0]:.9f},{w[1]:.9f},{w[2]:.9f},{a[0]:.9f},{a[1]:.9f},{a[2]:.9f}" for k, w, a in zip(t_ns, gyro, acc)]
    (imu / "data.csv").write_text("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                                  "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n" + "\n".join(rows) + "\n")
    fixes = "\n".join(f"{k // 10 ** 9}.{k % 10 ** 9:09d} {q[0]:.5f} {q[1]:.5f} {q[2]:.5f}" for k, q in zip(aid_t, p))
    (root / "fixes.tum").write_text(fixes + "\n")
    return root / "rec", root / "fixes.tum"


def test_navigate_without_a_noise_source_fits_it_and_says_so(tmp_path, capsys):
    from imu_learn.cli import main

    rec, fixes = write_asl(tmp_path, *recording(seconds=60.0)[:5])
    out = tmp_path / "out"
    rc = main(["navigate", "--input", str(rec), "--aiding", str(fixes), "--aiding-kind", "position", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["noise"].startswith("fitted from the aiding's innovations: x") and s["noise"] == s["imu_noise"]["source"]
    assert 0.5 < s["imu_noise"]["accelerometer_noise_density"] / TRUE_ACC < 2.0
    assert sum("fitted from the aiding's innovations" in line for line in err.splitlines()) == 1


def test_a_profiles_white_noise_is_raised_to_the_moving_imus_with_pose_aiding():
    """navigate's :func:`in_motion`: a profile measures the white noise at rest; the pose aiding's
    innovations see the moving IMU's. A profile 10x too quiet gets the fitted densities (within 2x of
    the truth), its random walks kept; a sensor noisier than the fit keeps its own; no fit leaves the
    profile's as they are, and each source says which."""
    from imu_learn.fuse.navigate import in_motion
    from imu_learn.fuse.noise_fit import CLASS_WHITE

    t_ns, gyro, acc, aid_t, p, R = recording()
    fit = fit_noise(t_ns, gyro, acc, aid_t, p, R, G)
    assert fit.used, fit.reason
    quiet = ImuNoise(TRUE_GYRO / 10, TRUE_ACC / 10, 2e-5, 4e-3, source="profile P")
    raised = in_motion(quiet, fit)
    assert 0.5 < raised.acc_noise_density / TRUE_ACC < 2.0 and 0.5 < raised.gyro_noise_density / TRUE_GYRO < 2.0
    assert raised.acc_noise_density == pytest.approx(fit.factor * CLASS_WHITE[1])
    assert (raised.gyro_random_walk, raised.acc_random_walk) == (2e-5, 4e-3)
    assert raised.source.startswith("profile P; white noise") and "raised" in raised.source
    noisy_gyro = in_motion(ImuNoise(TRUE_GYRO * 5, TRUE_ACC / 10, 2e-5, 4e-3, source="profile P"), fit)
    assert noisy_gyro.gyro_noise_density == TRUE_GYRO * 5 and noisy_gyro.acc_noise_density == raised.acc_noise_density
    kept = in_motion(ImuNoise(TRUE_GYRO * 5, TRUE_ACC * 5, 2e-5, 4e-3, source="profile P"), fit)
    assert (kept.gyro_noise_density, kept.acc_noise_density) == (TRUE_GYRO * 5, TRUE_ACC * 5)
    assert "not above it: kept" in kept.source
    short = fit_noise(t_ns[:300], gyro[:300], acc[:300], aid_t[:1], p[:1], R[:1], G)
    assert not short.used
    same = in_motion(quiet, short)
    assert same.acc_noise_density == quiet.acc_noise_density and "no in-motion fit" in same.source


SENSOR_YAML = """sensor_type: imu
rate_hz: 200
gyroscope_noise_density: {g:.6e}
gyroscope_random_walk: 2.0e-05
accelerometer_noise_density: {a:.6e}
accelerometer_random_walk: 4.0e-03
"""


def test_a_sensor_yamls_noise_is_kept_as_given_with_pose_aiding(tmp_path, capsys):
    """A recording's own sensor.yaml is used as it is with pose aiding, even 10x quieter than the moving IMU:
    raised to the innovations' fit as a profile's is, the raw IMU followed the camera closer at its stamps
    but coasted through camera gaps 1.2-3x further (docs/experiments/navigate-vo.md, "A recording's
    sensor.yaml raised in motion"): not kept, and this holds the choice."""
    from imu_learn.cli import main
    from imu_learn.fuse.output import write_trajectory

    t_ns, gyro, acc, aid_t, p, R = recording(seconds=40.0)
    rec, _ = write_asl(tmp_path, t_ns, gyro, acc, aid_t, p)
    yaml = rec / "mav0" / "imu0" / "sensor.yaml"
    yaml.write_text(SENSOR_YAML.format(g=TRUE_GYRO / 10, a=TRUE_ACC / 10))
    poses = tmp_path / "poses.tum"
    write_trajectory(poses, aid_t, p, R)  # the package's TUM writer
    out = tmp_path / "out"
    rc = main(["navigate", "--quiet", "--input", str(rec), "--aiding", str(poses), "--aiding-kind", "pose",
               "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    s = json.loads((out / "summary.json").read_text())["imu_noise"]
    assert s["source"] == str(yaml)
    assert s["gyroscope_noise_density"] == pytest.approx(TRUE_GYRO / 10)
    assert s["accelerometer_noise_density"] == pytest.approx(TRUE_ACC / 10)


def test_a_profile_that_measured_no_noise_writes_the_class_default_and_navigate_fits_its_own(tmp_path, capsys):
    """calibrate --imu-only on a recording that never rests measures no noise: refused in one line (exit 2,
    nothing written) naming the rest it needs and --force; with --force imu.yaml holds the device-class
    default with a line saying so (not .nan), and navigate --profile with it fits the noise from the
    aiding's innovations as without a profile (not the built-in ADIS16448's)."""
    import yaml

    from imu_learn.calib.profile import CLASS_DEFAULT_SOURCE, CLASS_DEFAULTS
    from imu_learn.cli import main

    rec, fixes = write_asl(tmp_path, *recording(seconds=60.0)[:5])
    cal = tmp_path / "cal"
    rc = main(["calibrate", "--imu-only", "--input", str(rec), "--out", str(cal), "--no-plot", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "NothingObservedError" in err and "--force" in err, err
    assert "0.0 s at rest" in err and not cal.exists()
    rc = main(["calibrate", "--imu-only", "--input", str(rec), "--out", str(cal), "--no-plot", "--quiet", "--force"])
    err = capsys.readouterr().err
    assert rc == 0 and "written with --force" in err, err
    text = (cal / "imu.yaml").read_text()
    assert yaml.safe_load(text) | CLASS_DEFAULTS == yaml.safe_load(text)  # every figure the class default
    assert ".nan" not in text and text.count(f"not measured (no reference, no still stretch): the {CLASS_DEFAULT_SOURCE}") == 4
    capsys.readouterr()
    out = tmp_path / "out"
    rc = main(["navigate", "--input", str(rec), "--aiding", str(fixes), "--aiding-kind", "position",
               "--profile", str(cal / "profile.json"), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["noise"].startswith("fitted from the aiding's innovations: x"), s["noise"]
    assert 0.5 < s["imu_noise"]["accelerometer_noise_density"] / TRUE_ACC < 2.0
    assert sum("measured no noise" in line for line in err.splitlines()) == 1


def test_the_white_noise_at_rest_is_raised_axis_by_axis():
    """A car parked with its engine running shakes one gyro axis most (the drive: 1.1e-3, 4.0e-3, 1.6e-4
    rad/s/sqrt(Hz) at rest): each axis is raised to its own spread where above the innovations' fit, the
    graph's covariance is that diagonal (GTSAM's own matrix read back), the summary's density their RMS;
    a rest quieter than the fit on every axis leaves the noise as it was."""
    from imu_learn.fuse.navigate import at_rest_floor

    rng = np.random.default_rng(3)
    rate, n = 100.0, 3000
    t_ns = 10 ** 18 + np.arange(n, dtype=np.int64) * 10_000_000
    axes = np.array([1.1e-3, 4.0e-3, 1.6e-4])
    gyro = rng.normal(0.0, 1.0, (n, 3)) * axes * np.sqrt(rate)
    acc = rng.normal(0.0, 2e-3 * np.sqrt(rate), (n, 3)) + [0.0, 0.0, G]
    fit = ImuNoise(1.2e-3, 1.4e-2, 2e-5, 3e-3, source="fit")
    raised = at_rest_floor(fit, (t_ns, gyro, acc), (0, n, "a rest"), G)
    assert raised.gyro_axes[0] == raised.gyro_axes[2] == 1.2e-3  # below the fit: the fit's
    assert raised.gyro_axes[1] == pytest.approx(4.0e-3, rel=0.05)
    assert raised.acc_axes == (1.4e-2,) * 3
    assert raised.gyro_noise_density == pytest.approx(np.sqrt(np.mean(axes ** 2)), rel=0.05)
    assert raised.acc_noise_density == 1.4e-2 and "axis by axis" in raised.source
    cov = raised.gtsam_params(G).getGyroscopeCovariance()
    assert np.allclose(cov, np.diag(np.square(raised.gyro_axes)), rtol=1e-12, atol=0)
    assert np.allclose(ImuNoise(2e-3, 1e-2).gtsam_params(G).getGyroscopeCovariance(), 4e-6 * np.eye(3))
    d = raised.to_dict()
    assert d["gyroscope_noise_density_axes"] == list(raised.gyro_axes) and "accelerometer_noise_density_axes" in d
    quiet = at_rest_floor(ImuNoise(5e-3, 1.4e-2, source="fit"), (t_ns, gyro, acc), (0, n, "a rest"), G)
    assert quiet.gyro_axes is None and quiet.source == "fit"
    with pytest.raises(Exception, match="three positive numbers"):
        ImuNoise(gyro_axes=(1e-3, 0.0, 1e-3))


def test_a_profiles_noise_with_gnss_is_raised_to_the_rest_axis_by_axis(tmp_path):
    """navigate --profile with GNSS fixes: the profile's white noise raised to the innovations' fit and then,
    axis by axis, to what this recording's rest shows (a car's idling engine), as without a profile (before:
    the rest's floor only without a profile; the walk's profile on the car drive lost it, outages 2-11 up to
    3 m further)."""
    from imu_learn.data import formats
    from imu_learn.fuse import navigate as nav
    from imu_learn.fuse.aiding import rtklib
    from test_navigate_gnss import synthetic_car

    class Quiet:  # a profile whose noise is the class default: what a positions reference writes
        def kalibr(self):
            return {"gyroscope_noise_density": 1.7e-4, "accelerometer_noise_density": 2e-3,
                    "gyroscope_random_walk": 2e-5, "accelerometer_random_walk": 3e-3}

        def unobserved_noise(self, key):
            return True

    imu, pos, _ = synthetic_car(tmp_path)
    src = formats.read_imu_source(imu, "gnss-imu")
    t_ns, gyro, acc = np.asarray(src.t_ns), np.array(src.gyro, dtype=np.float64), np.array(src.acc, dtype=np.float64)
    still = (t_ns - t_ns[0]) * 1e-9 < 3.5  # the car's 4 s at rest: its engine shakes the gyro's y axis
    gyro[still, 1] += np.random.default_rng(0).normal(0.0, 5e-3 * np.sqrt(100.0), int(still.sum()))
    sol = rtklib.read_pos(pos)
    opts = nav.NavigateOptions(aiding_kind=None, aiding_format="auto")
    noise = nav.imu_noise(nav.Sources(imu, pos, profile=tmp_path / "p.json"), opts, None, Quiet(), (t_ns, gyro, acc), sol)
    assert noise.source.startswith("profile ") and "axis by axis" in noise.source, noise.source
    assert noise.gyro_axes[1] == pytest.approx(5e-3, rel=0.2) and noise.gyro_axes[1] > 2 * noise.gyro_axes[0]


def test_aiding_a_little_faster_than_the_imu_is_one_run():
    """Rows of a capture slightly faster than the IMU (Fetch's ~100 Hz motion capture on its 100 Hz IMU),
    each on its nearest sample (as navigate keeps them, one per sample): one run, so the scale check has its
    triples (before, the first sample at or after each row put pairs on one sample: 398 runs of 3339 rows,
    "0 reference triples")."""
    from imu_learn.fuse.aiding.sampling import snap_to_samples
    from imu_learn.fuse.noise_fit import prepare

    t_imu = 10 ** 18 + np.arange(4000, dtype=np.int64) * 10_000_000
    t_aid = 10 ** 18 + 3_000_000 + np.round(np.arange(3900) * 9.9e6).astype(np.int64)
    nearest = snap_to_samples(t_imu, t_aid)[0]
    _, first = np.unique(nearest, return_index=True)  # navigate's rows: one per IMU sample
    rows = t_aid[np.sort(first)]
    zeros = np.zeros((len(t_imu), 3))
    prep = prepare(t_imu, zeros, zeros + [0.0, 0.0, G], rows)
    assert len(np.unique(prep.run)) == 1 and np.all(np.diff(prep.sample) > 0)
