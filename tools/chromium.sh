#!/usr/bin/env bash
# Chromium, the headless browser tests/report_html.rs opens report.html in (offline, with a
# screenshot): Debian's package. Installed with apt-get when missing (CI's fresh machine);
# a no-op otherwise.
set -euo pipefail
browser=/usr/bin/chromium
[ -x "$browser" ] && exit 0
echo "== installing chromium (apt-get): the browser tests/report_html.rs renders report.html in" >&2
SUDO=$([ "$(id -u)" = 0 ] || echo sudo)
$SUDO apt-get install -y -qq chromium >/dev/null \
    || { $SUDO apt-get update -qq >/dev/null && $SUDO apt-get install -y -qq chromium >/dev/null; }
[ -x "$browser" ] || { echo "error: $browser still missing after installing chromium" >&2; exit 2; }
