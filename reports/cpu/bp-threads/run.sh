#!/bin/bash
# octree vs bullet-dbvt in one process, 1 and 2 OpenMP threads, 10 repetitions.
# Usage (repo root, built build/bench_broadphase): bash reports/cpu/bp-threads/run.sh [OUT_DIR]
#   OUT_DIR   where the .txt/.json/meta.txt go (default reports/cpu/bp-threads)
#   env FRAMES=10 (recorded consecutive frames replayed per iteration), REPS=10,
#       THREADS="1 2", BIN=./build/bench_broadphase (e.g. a build of another revision),
#       SCENES="boxes-random-10000 boxes-uniform-50000"
# Then: python3 reports/cpu/bp-threads/table.py OUT_DIR
set -u
out=${1:-reports/cpu/bp-threads}
frames=${FRAMES:-10}
reps=${REPS:-10}
bin=${BIN:-./build/bench_broadphase}
mkdir -p "$out"
for scene in ${SCENES:-boxes-random-10000 boxes-uniform-50000}; do
  for t in ${THREADS:-1 2}; do
    { echo "scene=$scene threads=$t frames=$frames reps=$reps bin=$bin rev=$(git rev-parse --short HEAD) nproc=$(nproc) start=$(date -u +%FT%TZ) loadavg_before=$(cat /proc/loadavg)"; } >> "$out/meta.txt"
    OMP_WAIT_POLICY=passive OMP_NUM_THREADS=$t "$bin" datasets/scenes/$scene.json \
      --frames "$frames" --warmup 100 --only octree,bullet-dbvt --benchmark_repetitions="$reps" \
      --benchmark_report_aggregates_only=true \
      --benchmark_out="$out/$scene-t$t.json" --benchmark_out_format=json > "$out/$scene-t$t.txt" 2>&1
    echo "  end=$(date -u +%FT%TZ) loadavg_after=$(cat /proc/loadavg)" >> "$out/meta.txt"
  done
done
