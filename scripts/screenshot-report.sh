#!/usr/bin/env bash
# Screenshot of a report page (octocd report's index.html) in headless Chromium, to look at
# the page as a browser shows it (Debian package `chromium`; not needed to build or test).
# Usage: scripts/screenshot-report.sh INDEX.html OUT.png [WIDTH] [HEIGHT]
set -euo pipefail
page=$(readlink -f "$1"); out=$(readlink -f "$(dirname "$2")")/$(basename "$2")
width=${3:-1280}; height=${4:-6000}
browser=$(command -v chromium || command -v chromium-browser || command -v google-chrome || true)
if [ -z "$browser" ]; then echo "screenshot-report: chromium not installed (apt-get install chromium)" >&2; exit 77; fi
profile=$(mktemp -d)
trap 'rm -rf "$profile"' EXIT
# --no-sandbox: needed when running as root (containers, CI); the page is a local file.
"$browser" --headless --disable-gpu --no-sandbox --hide-scrollbars --user-data-dir="$profile" \
  --window-size="$width,$height" --screenshot="$out" "file://$page" >/dev/null 2>&1
test -s "$out"
echo "screenshot-report: $out"
