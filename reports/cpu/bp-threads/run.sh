#!/bin/bash
# octree vs bullet-dbvt in one process, 1 and 2 OpenMP threads, 10 repetitions.
# Usage (repo root, built build/bench_broadphase): bash reports/cpu/bp-threads/run.sh
set -u
out=reports/cpu/bp-threads
for scene in boxes-random-10000 boxes-uniform-50000; do
  for t in 1 2; do
    { echo "scene=$scene threads=$t rev=$(git rev-parse --short HEAD) nproc=$(nproc) start=$(date -u +%FT%TZ) loadavg_before=$(cat /proc/loadavg)"; } >> $out/meta.txt
    OMP_WAIT_POLICY=passive OMP_NUM_THREADS=$t ./build/bench_broadphase datasets/scenes/$scene.json \
      --frames 10 --warmup 100 --only octree,bullet-dbvt --benchmark_repetitions=10 \
      --benchmark_report_aggregates_only=true \
      --benchmark_out=$out/$scene-t$t.json --benchmark_out_format=json > $out/$scene-t$t.txt 2>&1
    echo "  end=$(date -u +%FT%TZ) loadavg_after=$(cat /proc/loadavg)" >> $out/meta.txt
  done
done
