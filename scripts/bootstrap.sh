#!/usr/bin/env bash
# Set up a development environment from scratch: a .venv with every Python dependency (build,
# test, lint, benchmark), and the Rust extension built into it. Safe to re-run.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v cargo >/dev/null 2>&1; then
  echo "error: cargo not found; install Rust with rustup (https://rustup.rs) and re-run" >&2
  exit 1
fi
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
# Build and test tools, then the package's own dependencies (pyproject.toml) and its test extras.
.venv/bin/python -m pip install --quiet "maturin>=1.5,<2" "rust-just>=1.30" "ruff>=0.4"
.venv/bin/python -m pip install --quiet numpy polars h5py scipy tqdm "rosbags>=0.11,<0.12" "pytest>=7" "gtsam>=4.3" "evo>=1.28"
# torch from PyPI (the CUDA build on Linux, ~3 GB once; pip's cache serves later runs).
.venv/bin/python -m pip install --quiet "torch>=2.1" onnx onnxruntime tensorboard matplotlib
# maturin develop wants an active virtualenv; VIRTUAL_ENV is all it reads.
VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" .venv/bin/maturin develop --release --quiet
echo "environment ready: .venv (activate with: . .venv/bin/activate)"
