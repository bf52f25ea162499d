#!/usr/bin/env bash
# Print the path of the OMSimulator command line, building it first when it is missing.
# OMSimulator 3.0 is built from its source archive (tools/pins.sh: name and SHA-256), found
# in $TWINBENCH_OMSIMULATOR_SOURCES or ../shared/omsimulator beside the clone, into a cache
# outside the clone, ~/.cache/twinbench/omsimulator (or $TWINBENCH_OMSIMULATOR_PREFIX):
# only the first run on a machine pays for the build (about 4 minutes on 2 cores). Needs
# cmake and g++ (installed with apt-get when missing).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
. "$here/pins.sh"
prefix=${TWINBENCH_OMSIMULATOR_PREFIX:-$HOME/.cache/twinbench/omsimulator}
exe="$prefix/bin/OMSimulator"
# A source tree tools/fetch_sources.sh fetched at the pinned commits (when the archive is
# not at hand).
tree="${TWINBENCH_SOURCES_CACHE:-$HOME/.cache/twinbench/sources}/omsimulator-$OMSIMULATOR_COMMIT"
if [ "${1:-}" = "--check" ]; then
    # Can the tests have OMSimulator? (built already, its archive is there, or a fetched tree)
    [ -x "$exe" ] && exit 0
    archive="${TWINBENCH_OMSIMULATOR_SOURCES:-$here/../../shared/omsimulator}/$OMSIMULATOR_ARCHIVE"
    [ -f "$archive" ] || [ -f "$tree/CMakeLists.txt" ]
    exit $?
fi
if [ ! -x "$exe" ]; then
    sources=${TWINBENCH_OMSIMULATOR_SOURCES:-$here/../../shared/omsimulator}
    archive="$sources/$OMSIMULATOR_ARCHIVE"
    if [ ! -f "$archive" ] && [ ! -f "$tree/CMakeLists.txt" ]; then
        echo "error: OMSimulator's source archive $OMSIMULATOR_ARCHIVE is not in $sources (set TWINBENCH_OMSIMULATOR_SOURCES, or let tools/fetch_sources.sh omsimulator fetch it; README, 'What the tests need')" >&2
        exit 2
    fi
    if [ -f "$archive" ] && ! echo "$OMSIMULATOR_SHA256  $archive" | sha256sum --check --status; then
        echo "error: $archive is not the pinned OMSimulator archive (SHA-256 $(sha256sum "$archive" | cut -d' ' -f1), expected $OMSIMULATOR_SHA256)" >&2
        exit 2
    fi
    if ! command -v cmake >/dev/null || ! command -v g++ >/dev/null; then
        echo "== installing cmake and g++ (apt-get)" >&2
        SUDO=$([ "$(id -u)" = 0 ] || echo sudo)
        $SUDO apt-get install -y -qq cmake g++ >/dev/null \
            || { $SUDO apt-get update -qq >/dev/null && $SUDO apt-get install -y -qq cmake g++ >/dev/null; }
    fi
    echo "== building OMSimulator into $prefix (once per machine, about 4 minutes)" >&2
    # Built into a temporary prefix and renamed: an interrupted build leaves no half install.
    tmp="$prefix.partial.$$"
    work=$(mktemp -d)
    trap 'rm -rf "$work" "$tmp"' EXIT
    mkdir -p "$(dirname "$prefix")"
    if [ -f "$archive" ]; then
        tar -xzf "$archive" -C "$work"
        src=$(find "$work" -mindepth 1 -maxdepth 1 -type d | head -n 1)
    else
        src="$work/oms-src"
        cp -a "$tree" "$src"
    fi
    cmake -S "$src" -B "$src/build" -DCMAKE_INSTALL_PREFIX="$tmp" -DCMAKE_BUILD_TYPE=Release \
        >"$work/cmake.log" 2>&1 || { tail -20 "$work/cmake.log" >&2; exit 1; }
    # Its progress, a line per tenth of the build (the whole log is kept for a failure).
    set +o pipefail
    cmake --build "$src/build" --target install -j"$(nproc)" 2>&1 | tee "$work/build.log" \
        | awk 'match($0, /^\[ *[0-9]+%\]/) { p = substr($0, 2, RLENGTH - 3) + 0;
               if (p >= last + 10) { last = p - p % 10; printf "== OMSimulator build: %d %%\n", last > "/dev/stderr"; fflush("/dev/stderr") } }'
    status=${PIPESTATUS[0]}
    set -o pipefail
    [ "$status" = 0 ] || { tail -30 "$work/build.log" >&2; exit 1; }
    rm -rf "$prefix"
    mv "$tmp" "$prefix"
fi
echo "$exe"
