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
# Build tools, then every dependency pyproject.toml declares (core + the extras train, fuse, eval,
# export, bags, test, dev: ".[all]"; declared there once, not here). The extras refer to each other
# (all = imu-learn[train,...]), which pip resolves for a published wheel but `maturin develop --extras`
# would look up on PyPI, so the requirements of ".[all]" are read from pyproject.toml here.
# torch comes from PyPI (the CUDA build on Linux, ~3 GB once; pip's cache serves later runs).
# EXTRAS=train,test (comma-separated) installs fewer extras than the default "all".
.venv/bin/python -m pip install --quiet "maturin>=1.5,<2" "tomli>=1.1; python_version < '3.11'"
.venv/bin/python - "${EXTRAS:-all}" > .venv/requirements-extras.txt <<'PY'
import re
import sys

try:
    import tomllib
except ImportError:  # Python < 3.11
    import tomli as tomllib

project = tomllib.load(open("pyproject.toml", "rb"))["project"]
norm = lambda s: re.sub(r"[-_.]+", "-", s).lower()
name, extras = norm(project["name"]), project.get("optional-dependencies", {})
reqs, seen, todo = list(project.get("dependencies", [])), set(), sys.argv[1].split(",")
while todo:
    extra = todo.pop()
    if extra in seen:
        continue
    seen.add(extra)
    for req in extras[extra]:
        m = re.match(r"\s*([A-Za-z0-9_.-]+)\s*\[([^\]]*)\]\s*$", req)
        if m and norm(m[1]) == name:  # imu-learn[train,...]: the package's own extras
            todo += [e.strip() for e in m[2].split(",")]
        elif req not in reqs:
            reqs.append(req)
print("\n".join(reqs))
PY
.venv/bin/python -m pip install --quiet -r .venv/requirements-extras.txt
# The package itself, editable, with the Rust extension built in release. maturin develop wants an
# active virtualenv; VIRTUAL_ENV is all it reads.
VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" .venv/bin/maturin develop --release --quiet
echo "environment ready: .venv (activate with: . .venv/bin/activate)"
