#!/usr/bin/env bash
# san.sh R TOOL SHARDS LIMIT [FRAMES [FILTER]]: compute-sanitizer TOOL (memcheck, racecheck)
# over the whole test_cuda_world (or the gtest FILTER), split into SHARDS gtest shards run at once (GTEST_TOTAL_SHARDS /
# GTEST_SHARD_INDEX), each cut at LIMIT s; --target-processes application-only, so the
# CLI tests' `octocd` children run unchecked (memcheck followed them and stalled last
# session). FRAMES: OCTOCD_GPU_TEST_FRAMES (frames per scene test; default the tests' 200).
set -u
R=${1:?}; TOOL=${2:?}; N=${3:?}; LIMIT=${4:?}; FRAMES=${5:-200}; FILTER=${6:-*}
mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
export OCTOCD_GPU_TEST_FRAMES=$FRAMES GTEST_TOTAL_SHARDS=$N
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
t0=$SECONDS
for ((i = 0; i < N; i++)); do
  GTEST_SHARD_INDEX=$i timeout $LIMIT $CS --tool $TOOL --target-processes application-only bin/test_cuda_world \
    --gtest_filter="$FILTER" > $R/$TOOL-shard$i.txt 2>&1 &
done
wait
echo "$TOOL: $N shards, $FRAMES frames per scene test, filter '$FILTER', $((SECONDS - t0)) s"
for ((i = 0; i < N; i++)); do
  f=$R/$TOOL-shard$i.txt
  echo "shard $i: run $(grep -c '^\[ RUN' $f), ok $(grep -c '^\[       OK' $f), failed $(grep '^\[  FAILED  \] [A-Z]' $f | awk '{print $4}' | sort -u | wc -l), skipped $(grep -c '^\[  SKIPPED \] [A-Z]' $f); $(grep -h 'ERROR SUMMARY\|RACECHECK SUMMARY' $f | tr -s ' =' ' ')$(grep -q 'PASSED' $f || echo ' (no PASSED line: cut or failed; last test:' $(grep '^\[ RUN' $f | tail -1 | cut -c14-)')')"
done
