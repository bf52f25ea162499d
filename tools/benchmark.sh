#!/usr/bin/env bash
# The side-by-side benchmark (docs/benchmark.md): builds twinbench, packs the FMUs, then
# times one lap of the RLS/v bench in twinbench (FMUs, native models), FMPy (its Python
# master and simulate_ssp) and libcosim. Needs target/venv (tools/test.sh creates it).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
target/release/twinbench pack -o target/fmu >/dev/null
exec target/venv/bin/python tools/benchmark.py "$@"
