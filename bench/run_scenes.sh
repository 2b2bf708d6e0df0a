#!/usr/bin/env bash
# Steps/s and per-stage time of every dataset scene with midphase B [1,2] and with
# aabb-only, side by side in one script, on this machine's CPU (issue 2 item 8).
# Usage: bench/run_scenes.sh [BUILD_DIR] [FRAMES] [OUT_DIR]
# Writes OUT_DIR/<scene>.<midphase>.json (octocd run --summary-json) and OUT_DIR/scenes.md.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-build}
FRAMES=${2:-3000}
OUT=${3:-reports/cpu}
mkdir -p "$OUT"
SCENES=(bunny-stack-50 bunny-random-400 armadillo-random-250 dragon-random-250 asian-dragon-random-60)
for scene in "${SCENES[@]}"; do
  for mp in 1,2 aabb-only; do
    tag=${mp/,/-}
    echo "bench: $scene midphase $mp ($FRAMES frames)" >&2
    "$BUILD/octocd" run "datasets/scenes/$scene.json" --midphase "$mp" --frames "$FRAMES" \
      --quiet --summary-json "$OUT/$scene.$tag.json"
  done
done
/usr/bin/python3 bench/scenes_table.py "$OUT" > "$OUT/scenes.md"
cat "$OUT/scenes.md"
