#!/usr/bin/env bash
# valgrind (Debian's), installed when missing: memcheck of the CVODE binding
# (tools/memcheck.sh), callgrind's instruction counts (tools/instructions.py and
# `realtime-check --instructions`, tested in tests/realtime_check.rs).
set -euo pipefail
command -v valgrind >/dev/null || {
    SUDO=$([ "$(id -u)" = 0 ] || echo sudo)
    $SUDO apt-get install -y -qq valgrind >/dev/null \
        || { $SUDO apt-get update -qq >/dev/null && $SUDO apt-get install -y -qq valgrind >/dev/null; }
}
