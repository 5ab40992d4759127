"""imu_learn.fuse: aiding, the factor graph against closed-form and GTSAM cases, the experiment runner."""
import json

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from crops import CROP, REPO  # noqa: E402  (the `crop` fixture, conftest.py, is this recording)
from imu_learn.cli.fuse import main as fuse_main  # noqa: E402
from imu_learn.data.formats.asl import read_leica, read_sensor_yaml  # noqa: E402
from imu_learn.data.synthetic import spin_and_climb  # noqa: E402
from imu_learn.errors import ConfigError  # noqa: E402
from imu_learn.fuse import (  # noqa: E402
    ImuNoise,
    PositionFixes,
    apply_outages,
    fuse,
    leica_fixes,
    simulate_position,
    simulate_relative_pose,
)
from imu_learn.fuse.experiments.batch import run_experiment  # noqa: E402
from imu_learn.fuse.experiments.config import FuseConfig, RecordingSpec, ScenarioSpec, load, validate  # noqa: E402
from imu_learn.fuse.score import score  # noqa: E402


def start_of(seq):
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw
    return Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix(), seq.p[0], seq.v[0]


# --------------------------------------------------------------------------------------------
# noise and calibration files


def test_sensor_yaml_gives_the_euroc_densities_and_lever_arm(shipped):
    y = read_sensor_yaml(shipped / CROP / "mav0/imu0/sensor.yaml")
    assert y["gyroscope_noise_density"] == pytest.approx(1.6968e-4)
    assert y["T_BS"][0] == [1.0, 0.0, 0.0, 0.0]
    n = ImuNoise.from_sensor_yaml(shipped / CROP / "mav0/imu0/sensor.yaml")
    assert n.acc_random_walk == pytest.approx(3.0e-3)
    p = n.gtsam_params(9.81)
    assert np.allclose(p.getGyroscopeCovariance(), 1.6968e-4 ** 2 * np.eye(3))


def test_sensor_yaml_with_a_short_transform_is_a_parse_error(tmp_path):
    from imu_learn.errors import ParseError
    f = tmp_path / "sensor.yaml"
    f.write_text("T_BS:\n  cols: 4\n  rows: 4\n  data: [1.0, 0.0, 0.0]\nrate_hz: 200\n")
    with pytest.raises(ParseError, match="sensor.yaml:1: T_BS"):
        read_sensor_yaml(f)


def test_leica_reader_and_lever_arm(shared):
    t, p, lever = read_leica(shared / "euroc" / "MH_01_easy")
    assert len(t) > 3000 and p.shape == (len(t), 3) and np.all(np.diff(t) > 0)
    assert np.allclose(lever, [0.0749, -0.0185, -0.1202], atol=1e-4)


# --------------------------------------------------------------------------------------------
# aiding


def test_simulated_fixes_have_the_configured_rate_and_noise(crop):
    rng = np.random.default_rng(1)
    fixes = simulate_position(crop.t_ns, crop.p, 10.0, 0.1, rng)
    assert abs(len(fixes) - crop.duration_s * 10) <= 2
    err = fixes.p - crop.p[fixes.idx]
    assert 0.08 < err.std() < 0.12 and abs(err.mean()) < 0.03


def test_noise_free_relative_poses_are_the_ground_truth_motion(crop):
    rel = simulate_relative_pose(crop.t_ns, crop.p, crop.q_wxyz, 10.0, 0.0, 0.0, np.random.default_rng(0))
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw
    R = Rotation.from_quat(wxyz_to_xyzw(crop.q_wxyz))
    k = 5
    i, j = rel.i[k], rel.j[k]
    assert np.allclose(rel.R_ij[k], (R[i].inv() * R[j]).as_matrix(), atol=1e-12)
    assert np.allclose(R[i].apply(rel.t_ij[k]), crop.p[j] - crop.p[i], atol=1e-12)


def test_outages_drop_exactly_the_fixes_inside(crop):
    fixes = simulate_position(crop.t_ns, crop.p, 1.0, 0.1, np.random.default_rng(0))
    kept = apply_outages(fixes, crop.t_ns, [(10.0, 5.0)])
    rel_s = (crop.t_ns[fixes.idx] - crop.t_ns[0]) * 1e-9
    assert len(kept) == len(fixes) - int(np.sum((rel_s >= 10.0) & (rel_s < 15.0))) and len(kept) < len(fixes)
    assert not np.any(((crop.t_ns[kept.idx] - crop.t_ns[0]) * 1e-9 >= 10.0) &
                      ((crop.t_ns[kept.idx] - crop.t_ns[0]) * 1e-9 < 15.0))


def test_leica_fixes_snap_to_the_nearest_sample_and_thin_to_the_rate():
    imu_t = np.arange(0, 10_000_000_000, 5_000_000, dtype=np.int64)  # 10 s at 200 Hz
    leica_t = np.arange(1_000_000, 9_000_000_000, 50_000_000, dtype=np.int64)  # 20 Hz, 1 ms off the grid
    p = np.arange(len(leica_t) * 3, dtype=float).reshape(-1, 3)
    all_fixes = leica_fixes(leica_t, p, np.zeros(3), imu_t, None, 0.01)
    assert np.array_equal(imu_t[all_fixes.idx], leica_t - 1_000_000)
    one_hz = leica_fixes(leica_t, p, np.zeros(3), imu_t, 1.0, 0.01)
    assert len(one_hz) == 9 and np.all(np.diff(imu_t[one_hz.idx]) >= 1_000_000_000 - 50_000_000)


# --------------------------------------------------------------------------------------------
# the graph


def test_default_preintegration_is_close_to_the_exact_one_over_a_keyframe_interval(crop):
    """CombinedImuFactor integrates in GTSAM's tangent form; over 0.1 s (20 samples) its deltas
    stay within 1e-7 rad / 1e-7 m/s of the manifold integration on real EuRoC motion."""
    p = ImuNoise().gtsam_params(9.81)
    worst = [0.0, 0.0]
    for start in range(0, len(crop) - 21, 997):
        a = gtsam.PreintegratedCombinedMeasurements(p, gtsam.imuBias.ConstantBias())
        b = gtsam.PreintegratedCombinedMeasurementsManifold(p, gtsam.imuBias.ConstantBias())
        for s in range(start, start + 20):
            dt = (crop.t_ns[s + 1] - crop.t_ns[s]) * 1e-9
            a.integrateMeasurement(crop.acc[s], crop.gyro[s], dt)
            b.integrateMeasurement(crop.acc[s], crop.gyro[s], dt)
        worst[0] = max(worst[0], np.linalg.norm(gtsam.Rot3.Logmap(a.deltaRij().between(b.deltaRij()))))
        worst[1] = max(worst[1], np.linalg.norm(a.deltaVij() - b.deltaVij()))
    assert worst[0] < 1e-7 and worst[1] < 1e-7, worst


def test_a_stationary_chain_with_a_loose_bias_prior_solves():
    """The case GTSAM's default Cholesky iSAM2 reports as indeterminate: stiff bias random walk
    factors against a loose bias prior. Stationary, no aiding: it must stay put."""
    n = 400
    t = np.arange(n, dtype=np.int64) * 5_000_000
    res = fuse(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1)), (np.eye(3), np.zeros(3), np.zeros(3)))
    assert np.abs(res.causal_p).max() < 1e-6 and np.abs(res.smoothed_p).max() < 1e-6


def test_noise_free_fixes_pin_a_bias_that_dead_reckoning_cannot(crop):
    """A constant gyro and accelerometer bias added to the real crop: without aiding the position
    runs away; with exact 1 Hz fixes the smoothed estimate recovers the bias and the trajectory."""
    bg, ba = np.array([0.01, -0.02, 0.015]), np.array([0.1, -0.05, 0.08])
    gyro, acc = crop.gyro + bg, crop.acc + ba
    fixes = simulate_position(crop.t_ns, crop.p, 1.0, 0.0, np.random.default_rng(0))
    fixes = PositionFixes(fixes.idx, fixes.p, 0.01, fixes.lever, fixes.label)
    start = start_of(crop)
    free = score(fuse(crop.t_ns, gyro, acc, start, []), crop.t_ns, crop.p, crop.q_wxyz)
    aided_res = fuse(crop.t_ns, gyro, acc, start, [fixes])
    aided = score(aided_res, crop.t_ns, crop.p, crop.q_wxyz)
    assert free["smoothed"]["pos_rmse_m"] > 10 * aided["smoothed"]["pos_rmse_m"]
    assert aided["smoothed"]["pos_rmse_m"] < 0.05
    # the crop's own bias (EuRoC state file) plus the added one is what the graph should find
    est = aided_res.smoothed_bias[len(aided_res.smoothed_bias) // 2]
    assert np.abs(est[:3] - (bg + np.array([-0.0022, 0.0208, 0.0757]))).max() < 5e-3


def test_exact_imu_and_perfect_fixes_recover_the_closed_form_trajectory():
    t, gyro, acc, p, R = spin_and_climb()
    fixes = PositionFixes(np.arange(0, len(t), 200), p[::200], 1e-4, np.zeros(3), "exact")
    res = fuse(t, gyro, acc, (R[0], p[0], np.zeros(3)), [fixes])
    for est_p, est_R in ((res.causal_p, res.causal_R), (res.smoothed_p, res.smoothed_R)):
        assert np.abs(est_p - p[res.kf_idx]).max() < 1e-6
        assert np.abs(est_R - R[res.kf_idx]).max() < 1e-7
    assert np.abs(res.smoothed_bias).max() < 1e-6


def test_with_noise_fusion_beats_dead_reckoning_and_drifts_inside_an_outage():
    rng = np.random.default_rng(3)
    t, gyro, acc, p, R = spin_and_climb()
    gyro = gyro + 0.005 + rng.normal(0, 0.002, gyro.shape)  # a bias and white noise
    acc = acc + 0.05 + rng.normal(0, 0.02, acc.shape)
    fixes = apply_outages(PositionFixes(np.arange(0, len(t), 200), p[::200] + rng.normal(0, 0.02, (10, 3)), 0.02,
                                        np.zeros(3), "noisy"), t, [(4.0, 4.0)])
    start = (R[0], p[0], np.zeros(3))
    q_wxyz = np.array([[np.cos(0.5 * 0.5 * s), 0, 0, np.sin(0.5 * 0.5 * s)] for s in t * 1e-9])
    outage = [(4.0, 4.0)]
    free = score(fuse(t, gyro, acc, start, []), t, p, q_wxyz, outage)
    aided = score(fuse(t, gyro, acc, start, [fixes]), t, p, q_wxyz, outage)
    assert aided["causal"]["pos_rmse_m"] < free["causal"]["pos_rmse_m"]
    assert aided["smoothed"]["pos_rmse_m"] < 0.5 * free["smoothed"]["pos_rmse_m"]
    # inside the outage the causal error grows well past its level while aided
    assert aided["causal"]["outages"][0]["max_m"] > 2 * aided["causal"]["pos_rmse_aided_m"]


# --------------------------------------------------------------------------------------------
# config, experiment runner and CLI


def test_config_rejects_unknown_keys_inputs_and_kinds(tmp_path):
    f = tmp_path / "f.toml"
    f.write_text('inputs = ["raw"]\nbogus = 1\n')
    with pytest.raises(ConfigError, match="bogus: unknown key"):
        load(f)
    with pytest.raises(ConfigError, match="inputs"):
        validate(FuseConfig(inputs=["magic"], recordings=[RecordingSpec("x")], scenarios=[ScenarioSpec("a")]))
    with pytest.raises(ConfigError, match="kind"):
        validate(FuseConfig(recordings=[RecordingSpec("x")], scenarios=[ScenarioSpec("a", kind="radar")]))


@pytest.mark.parametrize("path", sorted((REPO / "configs").glob("fuse_*.toml")), ids=lambda p: p.name)
def test_every_shipped_fusion_config_loads(path):
    """The configs whose commands docs/ quotes must parse: unknown keys, inputs or kinds are errors."""
    from imu_learn.cli.fuse import config_kind
    from imu_learn.fuse.experiments import gnss as gnss_run

    if config_kind(path) is None:
        cfg = load(path)
        assert cfg.recordings and cfg.scenarios and cfg.inputs
        if "learned" in cfg.inputs:
            assert cfg.covariance_checkpoint and cfg.methods_dir, "learned needs a covariance head and tlio-style"
    else:
        gnss_run.check(gnss_run.load_config(path), path)


def test_cli_reports_a_missing_recording_in_one_line(tmp_path, capsys):
    f = tmp_path / "f.toml"
    f.write_text('inputs = ["raw"]\n[[recordings]]\npath = "nowhere"\n[[scenarios]]\nname = "g"\n')
    assert fuse_main(["--config", str(f), "--data-root", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nowhere" in err[0]


def test_experiment_on_the_shipped_crop_writes_results_and_resumes(shipped, tmp_path):
    cfg = validate(FuseConfig(init="groundtruth",
        name="t", data_root=str(shipped), inputs=["raw", "proposed"], checkpoint="models/euroc_adis16448.pt",
        recordings=[RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv")],
        scenarios=[ScenarioSpec("gnss", "position", 1.0, 0.1, outages=[[20.0, 10.0]])]))
    logs = []
    res = run_experiment(cfg, tmp_path, logs.append)
    assert set(res) == {"MH_04_difficult|gnss|raw|s0", "MH_04_difficult|gnss|proposed|s0"}
    for r in res.values():
        assert r["smoothed"]["pos_rmse_m"] < 0.3 and len(r["causal"]["outages"]) == 1
    assert (tmp_path / "table.md").read_text().count("MH_04_difficult") >= 1
    assert len(list((tmp_path / "trajectories").glob("*.tum"))) == 4
    assert (tmp_path / "plots" / "MH_04_difficult_gnss.png").stat().st_size > 10_000
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["runs"] == json.loads(json.dumps(res))
    logs.clear()
    run_experiment(cfg, tmp_path, logs.append)
    assert any("2 of 2 runs already" in m for m in logs) and not any("position RMSE" in m for m in logs)


def test_a_changed_scenario_reruns_only_its_own_runs(shipped, tmp_path, monkeypatch):
    import imu_learn.fuse.experiments.batch as run_mod

    rec = RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv")
    a, b = ScenarioSpec("a", "position", 1.0, 0.1), ScenarioSpec("b", "position", 0.5, 0.1)
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw"], recordings=[rec], scenarios=[a, b]))
    calls = []
    real = run_mod.fuse
    monkeypatch.setattr(run_mod, "fuse", lambda *x, **k: calls.append(1) or real(*x, **k))
    run_experiment(cfg, tmp_path, lambda m: None)
    assert len(calls) == 2
    b.sigma_m = 0.2  # only b changes: a is kept
    calls.clear()
    res = run_experiment(cfg, tmp_path, lambda m: None)
    assert len(calls) == 1 and set(res) == {"MH_04_difficult|a|raw|s0", "MH_04_difficult|b|raw|s0"}


def test_a_graph_gtsam_cannot_solve_is_recorded_as_failed_and_the_rest_runs(shipped, tmp_path, monkeypatch):
    import imu_learn.fuse.experiments.batch as run_mod

    real = run_mod.fuse

    def flaky(*x, **k):
        if len(x[4][0]) < 45:  # the 0.5 Hz scenario: 30 fixes in the 60 s crop, against 60 at 1 Hz
            raise RuntimeError("Indeterminate linear system detected while working near variable x3")
        return real(*x, **k)

    monkeypatch.setattr(run_mod, "fuse", flaky)
    rec = RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv")
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw"], recordings=[rec],
                              scenarios=[ScenarioSpec("slow", "position", 0.5, 0.1), ScenarioSpec("fast", "position", 1.0, 0.1)]))
    res = run_experiment(cfg, tmp_path, lambda m: None)
    assert "Indeterminate" in res["MH_04_difficult|slow|raw|s0"]["failed"]
    assert res["MH_04_difficult|fast|raw|s0"]["smoothed"]["pos_rmse_m"] < 0.3
    assert "| failed | failed |" in (tmp_path / "table.md").read_text()


def test_startup_bias_prior_and_traditional_input(shipped, tmp_path):
    from imu_learn.baselines.traditional import Traditional, TraditionalParams

    # A calibration that removes a known gyro offset: the start-up fit on its output must see ~0.
    trad = Traditional()
    trad.params = TraditionalParams(np.eye(3), np.array([0.0, 0.0, 0.01]), np.zeros((3, 3)), np.eye(3), np.zeros(3),
                                    None, None)
    trad.save(tmp_path / "trad.json")
    rec = RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv")
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw", "traditional"],
                              traditional=str(tmp_path / "trad.json"), recordings=[rec],
                              scenarios=[ScenarioSpec("g", "position", 1.0, 0.1, bias_prior="startup")]))
    res = run_experiment(cfg, tmp_path / "o", lambda m: None)
    raw, tr = res["MH_04_difficult|g|raw|s0"]["bias_prior"], res["MH_04_difficult|g|traditional|s0"]["bias_prior"]
    assert abs(raw[2] - tr[2] - 0.01) < 1e-4  # the calibration's offset, seen by the start-up fit
    assert np.linalg.norm(raw[:3]) > 0.05  # EuRoC's ADIS16448 starts with ~0.08 rad/s of gyro bias
    assert res["MH_04_difficult|g|traditional|s0"]["smoothed"]["pos_rmse_m"] < 0.3
    with pytest.raises(ConfigError, match="bias_prior"):
        validate(FuseConfig(recordings=[rec], scenarios=[ScenarioSpec("a", bias_prior="oracle")]))


def test_trajectories_read_by_evo_give_the_reported_rmse(shipped, crop, tmp_path):
    """The TUM files are what evo_ape reads; its unaligned APE on them is our position RMSE."""
    evo_file = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics, sync

    from imu_learn import _imu_core as core
    rec = RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv")
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw"], recordings=[rec],
                              scenarios=[ScenarioSpec("g", "position", 1.0, 0.1)]))
    res = run_experiment(cfg, tmp_path, lambda m: None)["MH_04_difficult|g|raw|s0"]
    gt = tmp_path / "gt.tum"
    core.write_tum(str(gt), np.ascontiguousarray(crop.t_ns), np.ascontiguousarray(crop.p),
                   np.ascontiguousarray(crop.q_wxyz))
    ref = evo_file.read_tum_trajectory_file(str(gt))
    for which in ("causal", "smoothed"):
        est = evo_file.read_tum_trajectory_file(str(tmp_path / "trajectories" / f"MH_04_difficult_g_raw_s0_{which}.tum"))
        assert est.num_poses > 500  # 10 Hz keyframes over the 60 s crop
        r, e = sync.associate_trajectories(ref, est, max_diff=1e-6)
        assert r.num_poses == e.num_poses == est.num_poses
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((r, e))
        assert ape.get_statistic(metrics.StatisticsType.rmse) == pytest.approx(res[which]["pos_rmse_m"], rel=1e-6)


def test_a_recording_can_name_its_own_model_and_a_missing_one_fails_before_any_run(shipped, tmp_path):
    from imu_learn.fuse.experiments.batch import artefact_of, run_hash

    own = RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv", checkpoint=str(tmp_path / "nope.pt"))
    other = RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv")
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw", "proposed"], recordings=[other, own],
                              scenarios=[ScenarioSpec("g", "position", 1.0, 0.1)]))
    assert artefact_of(cfg, own, "proposed") == str(tmp_path / "nope.pt")
    assert artefact_of(cfg, other, "proposed") == cfg.checkpoint
    assert run_hash(cfg, own, cfg.scenarios[0], "raw", 0) == run_hash(cfg, other, cfg.scenarios[0], "raw", 0)
    assert run_hash(cfg, own, cfg.scenarios[0], "raw", 0) != run_hash(cfg, own, cfg.scenarios[0], "raw", 1)
    with pytest.raises(FileNotFoundError, match="nope.pt"):
        run_experiment(cfg, tmp_path / "o", lambda m: None)
    assert not (tmp_path / "o" / "results.json").exists()


def test_simulated_aiding_runs_once_per_noise_seed_and_the_table_gives_mean_and_std(shipped, tmp_path):
    from imu_learn.fuse.experiments.batch import seeds_of

    rec = RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv")
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw"], recordings=[rec], seeds=[3, 7],
                              scenarios=[ScenarioSpec("g", "position", 1.0, 0.1)]))
    res = run_experiment(cfg, tmp_path, lambda m: None)
    a, b = res["MH_04_difficult|g|raw|s3"], res["MH_04_difficult|g|raw|s7"]
    assert set(res) == {"MH_04_difficult|g|raw|s3", "MH_04_difficult|g|raw|s7"} and (a["seed"], b["seed"]) == (3, 7)
    ra, rb = a["smoothed"]["pos_rmse_m"], b["smoothed"]["pos_rmse_m"]
    assert ra != rb  # different fixes
    mean, std = (ra + rb) / 2, abs(ra - rb) / np.sqrt(2)
    assert f"{mean:.3f} ± {std:.3f}" in (tmp_path / "table.md").read_text()
    assert seeds_of(cfg, ScenarioSpec("l", "leica", 0.0, 0.005)) == [None]  # real aiding: one run
    with pytest.raises(ConfigError, match="seeds"):
        validate(FuseConfig(recordings=[rec], scenarios=cfg.scenarios, seeds=[1, 1]))


def test_any_evaluate_method_that_outputs_imu_is_an_input_and_end_to_end_is_not(shipped, tmp_path, monkeypatch):
    from imu_learn.baselines.base import Method
    from imu_learn.eval import run as evaluate

    class Offset(Method):
        """A fitted method stand-in: adds 0.01 rad/s to the gyro z axis."""

        name = "offset"

        def refine(self, seq):
            return seq.gyro + np.array([0.0, 0.0, 0.01]), seq.acc

    monkeypatch.setitem(evaluate.REGISTRY, "offset", Offset)
    (tmp_path / "methods").mkdir()
    (tmp_path / "methods" / "offset.pt").write_bytes(b"")  # what evaluate would have saved
    rec = RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv")
    scn = ScenarioSpec("g", "position", 1.0, 0.1, bias_prior="startup")
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw", "offset"], recordings=[rec],
                              methods_dir=str(tmp_path / "methods"), scenarios=[scn]))
    res = run_experiment(cfg, tmp_path / "o", lambda m: None)
    raw, off = res["MH_04_difficult|g|raw|s0"]["bias_prior"], res["MH_04_difficult|g|offset|s0"]["bias_prior"]
    assert off[2] - raw[2] == pytest.approx(0.01, abs=1e-4)  # the method's output is what was fused
    with pytest.raises(ConfigError, match="end-to-end"):
        validate(FuseConfig(recordings=[rec], scenarios=[scn], inputs=["raw", "end-to-end"]))
    with pytest.raises(FileNotFoundError, match="gyro-denoise"):
        run_experiment(validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["gyro-denoise"], recordings=[rec],
                                           methods_dir=str(tmp_path / "none"), scenarios=[scn])), tmp_path / "p",
                       lambda m: None)


@pytest.mark.slow
def test_nhc_scenario_adds_the_constraint_and_leaves_other_runs_hashes_alone(shipped, tmp_path, monkeypatch):
    """scenarios.nhc_sigma_mps > 0 adds the non-holonomic constraint at the keyframes (an extra_factors
    hook reaches fuse); 0 (the default) leaves the run's hash as it was before the option existed."""
    import imu_learn.fuse.experiments.batch as run_mod

    rec = RecordingSpec(CROP, "euroc", CROP + "/mav0/state_groundtruth_estimate0/data.csv")
    plain, nhc = ScenarioSpec("p", "position", 1.0, 0.1), ScenarioSpec("n", "position", 1.0, 0.1, nhc_sigma_mps=0.05)
    assert "nhc_sigma_mps" not in run_mod.scenario_of(plain) and run_mod.scenario_of(nhc)["nhc_sigma_mps"] == 0.05
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw"], recordings=[rec], scenarios=[plain, nhc]))
    hooks = {}
    real = run_mod.fuse

    def spy(*x, **k):
        hooks[len(hooks)] = k.get("extra_factors")
        return real(*x, **k)

    monkeypatch.setattr(run_mod, "fuse", spy)
    res = run_experiment(cfg, tmp_path, lambda m: None)
    assert hooks[0] is None and callable(hooks[1])
    a, b = res["MH_04_difficult|p|raw|s0"], res["MH_04_difficult|n|raw|s0"]
    assert a["smoothed"]["pos_rmse_m"] != b["smoothed"]["pos_rmse_m"]  # the constraint acts (a drone is not a car)
    with pytest.raises(ConfigError, match="nhc_sigma_mps"):
        validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw"], recordings=[rec],
                            scenarios=[ScenarioSpec("x", "position", 1.0, 0.1, nhc_sigma_mps=-1.0)]))
