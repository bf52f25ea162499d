#!/usr/bin/env bash
# The distributed benchmark (docs/distributed.md): builds twinbench and the Python package
# into target/venv (tools/test.sh creates the venv), packs the FMUs, builds the supplier EDU,
# then measures laps per second on rayon threads and on a Dask LocalCluster.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
target/release/twinbench pack -o target/fmu >/dev/null
target/venv/bin/python tools/supplier_edu/build.py >/dev/null
rm -rf target/wheels
(cd crates/python && ../../target/venv/bin/maturin build --release --quiet \
    --interpreter ../../target/venv/bin/python --out ../../target/wheels)
target/venv/bin/pip install --quiet --force-reinstall --no-deps target/wheels/twinbench-*.whl
exec target/venv/bin/python tools/benchmark_distributed.py "$@"
