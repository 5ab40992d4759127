# imu-learn tasks. `just --list` shows them; recipes use .venv (made by scripts/bootstrap.sh).

set shell := ["bash", "-euo", "pipefail", "-c"]
set export

py := justfile_directory() + "/.venv/bin/python"
VIRTUAL_ENV := justfile_directory() + "/.venv"
PATH := justfile_directory() + "/.venv/bin:" + env_var('PATH')
# Two cores here: rayon and the test runner share them deliberately.
RAYON_NUM_THREADS := env_var_or_default('RAYON_NUM_THREADS', '2')

# List the recipes
default:
    @just --list

# Create .venv, install every dependency, build the Rust extension (release)
setup:
    bash scripts/bootstrap.sh

# Rebuild the Rust extension into .venv after a change to crates/ (release build)
dev:
    maturin develop --release --quiet

# Run the whole test suite: Rust (no Python needed) then Python, slow tests included; lists the 20 slowest
test:
    cargo test --quiet
    {{py}} -m pytest -q --durations=20

# The Python tests without the slow ones (trainings, whole CLI runs, fusion experiments), for quick checks
test-fast *args="":
    {{py}} -m pytest -q -m "not slow" {{args}}

# Property tests of every imu_core reader with many cases (release); prints the cases each property ran
fuzz cases="50000":
    PROPTEST_CASES={{cases}} cargo test --release -p imu_core --test prop_readers --test io_columns -- --nocapture

# Lint: rustfmt, clippy (no warnings), ruff
lint:
    cargo fmt --all --check
    cargo clippy --all-targets --features python -- -D warnings
    {{py}} -m ruff check python tests bench

# Train the paper's model (no args: the shipped crops, < 10 min on 2 CPU cores); e.g. just fit --config configs/euroc.toml --data-root DIR
fit *args="":
    {{py}} -m imu_learn.cli fit {{args}}

# Fit every method on the train split and evaluate on the test split; e.g. just evaluate --config configs/eval_euroc.toml --data-root DIR
evaluate *args="":
    {{py}} -m imu_learn.cli evaluate {{args}}

# The fusion experiments of a config (IMU with aiding in a GTSAM factor graph); e.g. just fuse --config configs/fuse_euroc.toml --data-root DIR
fuse *args="":
    {{py}} -m imu_learn.cli fuse {{args}}

# Navigate a recording with its aiding file, no ground truth; e.g. just navigate --input REC --aiding FILE --aiding-kind relative-pose
navigate *args="":
    {{py}} -m imu_learn.cli navigate {{args}}

# Write refined IMU in the input's own format: just refine CKPT IN OUT
refine checkpoint input output *args="":
    {{py}} -m imu_learn.cli refine --checkpoint {{checkpoint}} --input {{input}} --out {{output}} {{args}}

# Build the label cache of a dataset (euroc, tum-vi, ...) from <data root>/<name> (--data-root DIR, $IMU_LEARN_DATA, else datasets/) or --dataset-dir DIR
labels dataset *args="":
    {{py}} -m imu_learn.cli labels {{dataset}} {{args}}

# Print measured throughput: imu_core vs numpy/GTSAM/polars, training/refine/causal latency, online fusion latency, cost against recording length (BENCH_SCALE_ARGS='--hours 1,10'), then the Allan deviation of 10 h at 200 Hz against allantools
bench *args="":
    {{py}} bench/bench_core.py {{args}}
    {{py}} bench/bench_learn.py
    {{py}} bench/bench_fit_startup.py {{ if args =~ '--quick' { '--repeat 1' } else { '' } }}
    {{py}} bench/bench_fuse_online.py
    {{py}} bench/bench_rosbag.py {{ if args =~ '--quick' { '--quick' } else { '' } }}
    {{py}} bench/bench_scale.py {{ if args =~ '--quick' { '--quick' } else { '' } }} ${BENCH_SCALE_ARGS:-}
    {{py}} bench/bench_allan.py {{ if args =~ '--quick' { '--hours 1 --repeats 1' } else { '' } }}
    {{py}} bench/bench_calibrate.py {{ if args =~ '--quick' { '--quick' } else { '' } }}
