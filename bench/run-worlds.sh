#!/usr/bin/env bash
# The batched-worlds benchmark of issue 70 (docs/gpu.md, "Batched worlds") for a GPU
# host: `octocd bench worlds` (bunny-stack-50 x 1, 1,024, 8,192, 65,536 copies on cuda; the
# cpu engine on all the host's threads at 1 and 1,024 copies; 5 repetitions each), then the
# hand-built scene of 8,192 copies (bench/hand_built_worlds.py: one scene file, each copy in
# its own open box of static boxes) on cuda with the same frames and repetitions, then the
# table of both (bench/worlds_table.py) with the ratio --worlds 8192 / hand-built.
#
# Usage: bench/run-worlds.sh [OCTOCD] [OUT_DIR]   (defaults: build/octocd, reports/h100/worlds)
# Meshes: the dataset cache of the source tree (datasets/fetch.sh) or $OCTOCD_DATA_DIR.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
octocd=${1:-build/octocd}
out=${2:-reports/h100/worlds}
copies=8192
mkdir -p "$out"
"$octocd" bench worlds -o "$out/worlds.json"
python3 "$here/hand_built_worlds.py" --copies "$copies" -o "$out/bunny-stack-50-hand-built-x$copies.json"
cat > "$out/hand-built.sweep.json" <<JSON
{
  "name": "worlds-hand-built",
  "kind": "steps",
  "description": "The hand-built baseline of bench/sweeps/worlds.json: $copies copies of bunny-stack-50 in one scene file (bench/hand_built_worlds.py), on cuda, the same frames and repetitions.",
  "scenes": ["bunny-stack-50-hand-built-x$copies.json"],
  "engines": ["cuda"],
  "warmup": 30,
  "frames": 1000,
  "repeat": 5
}
JSON
"$octocd" bench "$out/hand-built.sweep.json" -o "$out/hand-built.json"
python3 "$here/worlds_table.py" "$out/worlds.json" "$out/hand-built.json" | tee "$out/worlds.md"
