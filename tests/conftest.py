"""Shared fixtures (the data folders, the shipped EuRoC crops that tests/crops.py loads) and the
``slow`` marker's list (SLOW below; ``just test-fast`` runs ``pytest -m "not slow"``)."""
from pathlib import Path

import pytest

from crops import REPO, SHIPPED, load_crop, load_easy, split

# Real datasets live beside the repository (../shared/data), never inside it.
SHARED = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared() -> Path:
    if not SHARED.exists():
        pytest.skip(f"{SHARED} not present (real datasets live beside the repository)")
    return SHARED


@pytest.fixture(scope="session")
def shipped() -> Path:
    return SHIPPED


# The crops are module-scoped: a test that writes into a crop's arrays spoils only its own module.
@pytest.fixture(scope="module")
def crop():
    """The shipped EuRoC MH_04_difficult crop (60 s at 200 Hz) as fusion loads it: one Segment."""
    return load_crop()


@pytest.fixture(scope="module")
def crop_easy():
    """The shipped EuRoC MH_01_easy crop (60 s at 200 Hz) with the loader's defaults: one Segment."""
    return load_easy()


@pytest.fixture(scope="module")
def crop_split(crop_easy):
    """(train, val) of ``crop_easy``: samples [0, 3000) (15 s) and [3000, 4000) (5 s)."""
    return split(crop_easy)


# The slow tests, by module and function name (every parametrisation of it): trainings, whole CLI
# runs and fusion experiments, chosen from `just test`'s --durations (about 1.5 s or more each, or a
# module fixture of that cost that only they use). Listed here so that the files being edited need no
# decorator; a file may also mark its own with @pytest.mark.slow (test_packaging.py does). A name
# here that its module no longer defines is an error, so the list cannot rot silently.
SLOW = {
    "test_cli.py": {"test_an_unknown_exception_prints_the_traceback_through_python_dash_m"},
    "test_evaluate.py": {
        "test_end_to_end_writes_the_report",  # these two share the module's evaluate run (e2e, ~17 s)
        "test_end_to_end_reuse",
        "test_a_checkpoint_with_a_covariance_head_gets_the_calibration_table",
    },
    "test_fit.py": {
        "test_resume_in_new_process_matches_uninterrupted",
        "test_sigint_to_a_real_process",
        "test_corrupt_checkpoint_is_one_line_exit_2_and_nothing_changes",
    },
    "test_fuse.py": {
        "test_experiment_on_the_shipped_crop_writes_results_and_resumes",
        "test_a_changed_scenario_reruns_only_its_own_runs",
        "test_a_graph_gtsam_cannot_solve_is_recorded_as_failed_and_the_rest_runs",
        "test_startup_bias_prior_and_traditional_input",
        "test_trajectories_read_by_evo_give_the_reported_rmse",
        "test_simulated_aiding_runs_once_per_noise_seed_and_the_table_gives_mean_and_std",
        "test_any_evaluate_method_that_outputs_imu_is_an_input_and_end_to_end_is_not",
    },
    "test_fuse_aiding.py": {"test_the_first_fix_after_a_long_gap_settles_the_causal_estimate"},
    "test_fuse_displacement.py": {"test_tlio_style_is_a_fusion_input_that_adds_factors"},
    "test_outputs_under_failure.py": {
        "test_two_labels_runs_on_one_cache_take_turns",
        "test_fit_signal_midway_through_a_checkpoint_then_resume",
        "test_refine_ctrl_c_midway_through_its_imu_writes_both_files_then_stops",
        "test_refine_killed_midway_keeps_the_previous_output_then_reruns",
        "test_evaluate_sigint_midway_then_rerun",
        "test_evaluate_rerun_interrupted_while_writing_its_report_leaves_the_previous_report_whole",
        "test_labels_sigterm_midway_then_resume",
        "test_fuse_sigterm_midway_then_rerun",
    },
    "test_refine.py": {"test_cli_refines_an_asl_folder"},
    "test_rosbag_fuse.py": {"test_fuse_a_bag_with_its_position_topic_writes_odometry_in_its_kind"},
}


@pytest.hookimpl(tryfirst=True)  # before -m deselects: `-m "not slow"` must see the marks
def pytest_collection_modifyitems(config, items):
    for item in items:
        names = SLOW.get(item.path.name, ())
        missing = [n for n in names if not hasattr(getattr(item, "module", None), n)]
        if missing:
            raise pytest.UsageError(f"tests/conftest.py SLOW names {item.path.name}::{missing[0]}, "
                                    "which that module does not define (renamed or removed?)")
        if getattr(item, "originalname", item.name) in names:
            item.add_marker(pytest.mark.slow)
