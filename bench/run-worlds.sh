#!/usr/bin/env bash
# The batched-worlds benchmark of issue 70 (docs/gpu.md, "Batched worlds") for a GPU
# host: `octocd bench worlds` (bunny-stack-50 x 1, 1,024, 8,192, 65,536 copies on cuda; the
# cpu engine on all the host's threads at 1 and 1,024 copies; 5 repetitions each), then the
# hand-built scene of 8,192 copies (bench/hand_built_worlds.py: one scene file, each copy in
# its own open box of static boxes) on cuda with the same frames and repetitions, then the
# table of both (bench/worlds_table.py) with the ratio --worlds 8192 / hand-built.
#
# Usage: bench/run-worlds.sh [OCTOCD] [OUT_DIR] [BENCH_OPTION...]   (defaults: build/octocd,
# reports/h100/worlds; in the GPU bundle of scripts/gpu-bundle.sh: ./bench/run-worlds.sh
# bin/octocd OUT). BENCH_OPTIONs go to both `octocd bench` calls (a smoke run: --frames 3
# --warmup 1 --repeat 1).
# Meshes: $OCTOCD_DATA_DIR, else the datasets/cache beside bench/ (datasets/fetch.sh).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
octocd=${1:-build/octocd}
out=${2:-reports/h100/worlds}
shift $(( $# < 2 ? $# : 2 ))
copies=8192
# The hand-built scene is written to OUT_DIR: its mesh names resolve through the data dir.
if [ -z "${OCTOCD_DATA_DIR:-}" ] && [ -d "$here/../datasets/cache" ]; then
  export OCTOCD_DATA_DIR="$here/../datasets/cache"
fi
mkdir -p "$out"
"$octocd" bench worlds -o "$out/worlds.json" "$@"
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
"$octocd" bench "$out/hand-built.sweep.json" -o "$out/hand-built.json" "$@"
python3 "$here/worlds_table.py" "$out/worlds.json" "$out/hand-built.json" | tee "$out/worlds.md"
