#!/usr/bin/env bash
# The test command (README): prepares the Python tools' virtual environment (FMPy, numpy,
# scipy, pythonfmu, dask, maturin) under target/venv, then runs every test of the workspace,
# optimised, and the Python package's tests.
# The tests pack the FMUs themselves (cargo run --release -- pack does the same); the
# pythonfmu supplier EDU is built here.
set -euo pipefail
cd "$(dirname "$0")/.."
# What the suite builds from third-party sources (tools/pins.sh): found before anything
# else, or one line that says what is missing and where to get it.
. tools/pins.sh
export TWINBENCH_REFERENCE_FMUS="${TWINBENCH_REFERENCE_FMUS:-$(cd .. && pwd)/shared/reference-fmus}"
# Not beside the clone: fetched at their pinned commits into a cache when the network allows
# (tools/fetch_sources.sh), and only then missing.
if [ ! -f "$TWINBENCH_REFERENCE_FMUS/src/fmi2Functions.c" ]; then
    if fetched=$(tools/fetch_sources.sh reference-fmus); then
        export TWINBENCH_REFERENCE_FMUS="$fetched"
    fi
fi
tools/omsimulator.sh --check || tools/fetch_sources.sh omsimulator >/dev/null || true
missing=()
[ -f "$TWINBENCH_REFERENCE_FMUS/src/fmi2Functions.c" ] \
    || missing+=("the Modelica Reference FMUs' sources ($REFERENCE_FMUS_REPOSITORY at commit $REFERENCE_FMUS_COMMIT) at $TWINBENCH_REFERENCE_FMUS (or set TWINBENCH_REFERENCE_FMUS)")
tools/omsimulator.sh --check \
    || missing+=("OMSimulator's source archive $OMSIMULATOR_ARCHIVE (SHA-256 $OMSIMULATOR_SHA256; $OMSIMULATOR_REPOSITORY at $OMSIMULATOR_COMMIT) in ${TWINBENCH_OMSIMULATOR_SOURCES:-$(cd .. && pwd)/shared/omsimulator} (or set TWINBENCH_OMSIMULATOR_SOURCES)")
if [ ${#missing[@]} -gt 0 ]; then
    line="${missing[0]}"
    [ ${#missing[@]} -eq 1 ] || line="$line, and ${missing[1]}"
    echo "error: the tests need $line: see README, 'What the tests need'" >&2
    exit 2
fi
# The Model Exchange solver's library (Debian's libsundials-dev), before anything is built.
tools/sundials.sh
# The headless browser tests/report_html.rs opens report.html in (Debian's chromium).
tools/chromium.sh
if ! target/venv/bin/python -c "import fmpy, numpy, scipy, pythonfmu, libcosimpy, asammdf, distributed, pandas, pytest, maturin" 2>/dev/null; then
    echo "== creating target/venv (tools/requirements.txt)"
    python3 -m venv target/venv
    target/venv/bin/pip install --quiet --upgrade pip
    target/venv/bin/pip install --quiet -r tools/requirements.txt
fi
export TWINBENCH_PYTHON="$PWD/target/venv/bin/python"
# The pythonfmu supplier EDU (tests/supplier_edu.rs, systems/rls_v_supplier.toml) and the
# link to the libpython a native host must preload for it.
"$TWINBENCH_PYTHON" tools/supplier_edu/build.py
# valgrind: realtime-check's instruction count in the fast tier, memcheck after it.
tools/valgrind.sh
# OMSimulator for the host tests (built once per machine into ~/.cache/twinbench).
TWINBENCH_OMSIMULATOR="$(tools/omsimulator.sh)"
export TWINBENCH_OMSIMULATOR
# Everything the tests and the processes they start put in the temporary directory goes to
# a fresh folder, which must be empty at the end: the suite leaves nothing behind.
export TMPDIR="$PWD/target/test-tmp"
rm -rf "$TMPDIR"
mkdir -p "$TMPDIR"
# The store of unpacked FMUs the tests and their processes share: under target/, never in
# the home folder (docs/robustness.md, "The store of unpacked FMUs").
export TWINBENCH_CACHE="$PWD/target/unpack-cache"
# The fast tier: every crate's tests, the FMUs through their C symbols, the orchestrator.
cargo test --release --workspace "$@"
# The CVODE binding under valgrind's memcheck.
tools/memcheck.sh
# The slow tier: whole optimisations (Spielberg, and a lap the suite makes itself), the
# intervals' coverage on 20 synthetic laps and a study over several laps, the second-order
# chassis recovered on a lap of another circuit, FMPy's master over a lap, the SSP in FMPy,
# libcosim and OMSimulator.
cargo test --release -p twinbench --features slow-tests \
    --test optimize_spielberg --test optimize_study --test robustness_optimize \
    --test ssp_export --test cross_validation --test own_lap --test omsimulator \
    --test optimize_speedup --test interval_coverage --test multi_lap \
    --test chassis_recovery --test export_twin_tools "$@"
# The Python package: its wheel (abi3) built from the workspace into the venv, then its
# tests against the command line the slow tier built (studies on a Dask LocalCluster).
rm -rf target/wheels
(cd crates/python && ../../target/venv/bin/maturin build --release --quiet \
    --interpreter ../../target/venv/bin/python --out ../../target/wheels)
target/venv/bin/pip install --quiet --force-reinstall --no-deps target/wheels/twinbench-*.whl
TWINBENCH_EXE="$PWD/target/release/twinbench" target/venv/bin/python -m pytest -q \
    -p no:cacheprovider --basetemp="$PWD/target/pytest" crates/python/tests
if [ -n "$(ls -A "$TMPDIR")" ]; then
    echo "error: the tests left files in the temporary directory ($TMPDIR):" >&2
    ls -lA "$TMPDIR" >&2
    exit 1
fi
