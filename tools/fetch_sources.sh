#!/usr/bin/env bash
# Fetch a pinned third-party source the tests build (tools/pins.sh) into a cache outside the
# clone, when the network allows: `fetch_sources.sh reference-fmus` or `fetch_sources.sh
# omsimulator`. Prints the folder (the Reference FMUs' sources; OMSimulator's source tree)
# and exits 0, or says on one line why it could not and exits 2.
#
# Both come from git at their pinned commits: git names content by its hash, so a fetched
# tree is the pinned one or the checkout fails (a release archive from a web page could
# change under the same name; OMSimulator's own archive is checked by its SHA-256 in
# tools/omsimulator.sh instead). Cache: ~/.cache/twinbench/sources
# ($TWINBENCH_SOURCES_CACHE); a fetch goes to a temporary folder renamed at the end, so an
# interrupted one leaves nothing that looks complete.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
. "$here/pins.sh"
cache=${TWINBENCH_SOURCES_CACHE:-$HOME/.cache/twinbench/sources}
what=${1:?usage: fetch_sources.sh reference-fmus|omsimulator}

# Clone $1 at commit $2 into $3 (shallow); submodules too with $4 = submodules. Each step
# checked by hand: `set -e` does not hold inside a function called before `||`.
checkout() {
    local repo=$1 commit=$2 dest=$3 tmp="$3.partial.$$"
    rm -rf "$tmp" && mkdir -p "$tmp" || return 1
    export GIT_TERMINAL_PROMPT=0
    git -C "$tmp" init -q && git -C "$tmp" remote add origin "$repo" || return 1
    # A full clone when the server refuses to serve a commit by its hash.
    if ! timeout 600 git -C "$tmp" fetch -q --depth 1 origin "$commit" 2>/dev/null; then
        timeout 1200 git -C "$tmp" fetch -q origin || { rm -rf "$tmp"; return 1; }
    fi
    git -C "$tmp" -c advice.detachedHead=false checkout -q "$commit" || { rm -rf "$tmp"; return 1; }
    if [ "${4:-}" = submodules ]; then
        timeout 1200 git -C "$tmp" submodule update -q --init --recursive || { rm -rf "$tmp"; return 1; }
    fi
    rm -rf "$dest" && mv "$tmp" "$dest"
}

command -v git >/dev/null || { echo "git is not installed (apt-get install git)" >&2; exit 2; }
mkdir -p "$cache"
case "$what" in
    reference-fmus)
        dest="$cache/reference-fmus-$REFERENCE_FMUS_COMMIT"
        if [ ! -f "$dest/src/fmi2Functions.c" ]; then
            echo "== fetching the Modelica Reference FMUs at $REFERENCE_FMUS_COMMIT into $dest" >&2
            checkout "$REFERENCE_FMUS_REPOSITORY" "$REFERENCE_FMUS_COMMIT" "$dest" \
                || { echo "cannot fetch $REFERENCE_FMUS_REPOSITORY (no network?)" >&2; exit 2; }
        fi
        ;;
    omsimulator)
        dest="$cache/omsimulator-$OMSIMULATOR_COMMIT"
        if [ ! -f "$dest/CMakeLists.txt" ]; then
            echo "== fetching OMSimulator at $OMSIMULATOR_COMMIT (with its 3rdParty submodule) into $dest" >&2
            checkout "$OMSIMULATOR_REPOSITORY" "$OMSIMULATOR_COMMIT" "$dest" submodules \
                || { echo "cannot fetch $OMSIMULATOR_REPOSITORY (no network?)" >&2; exit 2; }
            # The pinned third-party submodule, as the archive has it.
            got=$(git -C "$dest/3rdParty" rev-parse HEAD 2>/dev/null || echo none)
            case "$got" in
                "$OMSIMULATOR_3RDPARTY_COMMIT"*) ;;
                *) echo "OMSimulator's 3rdParty is at $got, not the pinned $OMSIMULATOR_3RDPARTY_COMMIT" >&2
                   rm -rf "$dest"; exit 2 ;;
            esac
        fi
        ;;
    *)
        echo "usage: fetch_sources.sh reference-fmus|omsimulator" >&2
        exit 2
        ;;
esac
echo "$dest"
