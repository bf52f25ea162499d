#!/usr/bin/env bash
# SUNDIALS CVODE, the solver twinbench integrates Model Exchange FMUs with: Debian's
# libsundials-dev (6.4.1), linked statically by crates/fmi/build.rs. Installed with apt-get
# when its static library is missing (CI's fresh machine); a no-op otherwise.
set -euo pipefail
lib="${TWINBENCH_SUNDIALS_LIB:-/usr/lib/x86_64-linux-gnu}/libsundials_cvode.a"
[ -f "$lib" ] && exit 0
echo "== installing libsundials-dev (apt-get): the Model Exchange solver" >&2
SUDO=$([ "$(id -u)" = 0 ] || echo sudo)
$SUDO apt-get install -y -qq libsundials-dev >/dev/null \
    || { $SUDO apt-get update -qq >/dev/null && $SUDO apt-get install -y -qq libsundials-dev >/dev/null; }
[ -f "$lib" ] || { echo "error: $lib still missing after installing libsundials-dev" >&2; exit 2; }
