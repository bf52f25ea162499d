#!/usr/bin/env bash
# The test command (README): prepares the Python tools' virtual environment (FMPy, numpy,
# scipy, pythonfmu) under target/venv, then runs every test of the workspace, optimised.
# The tests pack the FMUs themselves (cargo run --release -- pack does the same); the
# pythonfmu supplier EDU is built here.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! target/venv/bin/python -c "import fmpy, numpy, scipy, pythonfmu, libcosimpy" 2>/dev/null; then
    echo "== creating target/venv (tools/requirements.txt)"
    python3 -m venv target/venv
    target/venv/bin/pip install --quiet --upgrade pip
    target/venv/bin/pip install --quiet -r tools/requirements.txt
fi
export TWINBENCH_PYTHON="$PWD/target/venv/bin/python"
# The pythonfmu supplier EDU (tests/supplier_edu.rs, systems/rls_v_supplier.toml) and the
# link to the libpython a native host must preload for it.
"$TWINBENCH_PYTHON" tools/supplier_edu/build.py
cargo test --release --workspace "$@"
