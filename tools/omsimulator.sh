#!/usr/bin/env bash
# Print the path of the OMSimulator command line, building it first when it is missing.
# OMSimulator 3.0 is built from the source snapshot in ../shared/omsimulator (its PyPI
# package downloads binaries from a host CI cannot reach) into a cache outside the clone,
# ~/.cache/twinbench/omsimulator (or $TWINBENCH_OMSIMULATOR_PREFIX): only the first run on a
# machine pays for the build (about 4 minutes on 2 cores). Needs cmake and g++ (installed
# with apt-get when missing).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
prefix=${TWINBENCH_OMSIMULATOR_PREFIX:-$HOME/.cache/twinbench/omsimulator}
exe="$prefix/bin/OMSimulator"
if [ ! -x "$exe" ]; then
    source_dir="$here/../../shared/omsimulator"
    if [ ! -f "$source_dir/build.sh" ]; then
        echo "error: OMSimulator's sources are not at $source_dir" >&2
        exit 1
    fi
    if ! command -v cmake >/dev/null || ! command -v g++ >/dev/null; then
        echo "== installing cmake and g++ (apt-get)" >&2
        SUDO=$([ "$(id -u)" = 0 ] || echo sudo)
        $SUDO apt-get install -y -qq cmake g++ >/dev/null \
            || { $SUDO apt-get update -qq >/dev/null && $SUDO apt-get install -y -qq cmake g++ >/dev/null; }
    fi
    echo "== building OMSimulator into $prefix (once per machine)" >&2
    # Built into a temporary prefix and renamed: an interrupted build leaves no half install.
    tmp="$prefix.partial.$$"
    rm -rf "$tmp"
    mkdir -p "$(dirname "$prefix")"
    bash "$source_dir/build.sh" "$tmp" >&2
    rm -rf "$prefix"
    mv "$tmp" "$prefix"
fi
echo "$exe"
