#!/usr/bin/env bash
# compute-sanitizer TOOL (memcheck, racecheck, synccheck) over the test_cuda_world tests
# named in LIST (one gtest name a line), each in its own process, P at a time, each cut at
# LIMIT s; --target-processes application-only; FRAMES: OCTOCD_GPU_TEST_FRAMES (default 200).
# Run from an extracted GPU bundle (scripts/gpu-bundle.sh) on the GPU machine:
#   bash scripts/gpu-sanitize-tests.sh R TOOL LIST LIMIT P [FRAMES]
# Writes R/TOOL-N.txt per test and prints one line per test (ok, failed, the sanitizer's
# summary). `bin/test_cuda_world --gtest_list_tests` lists the names for LIST.
set -u
R=${1:?}; TOOL=${2:?}; LIST=${3:?}; LIMIT=${4:?}; P=${5:?}; FRAMES=${6:-200}
mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=4
export OCTOCD_GPU_TEST_FRAMES=$FRAMES
export CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer) TOOL LIMIT R
t0=$SECONDS
grep -v '^$' $LIST | nl -nln -w1 -s' ' | xargs -P $P -L 1 bash -c 'timeout $LIMIT $CS --tool $TOOL --target-processes application-only bin/test_cuda_world --gtest_filter="$1" > $R/$TOOL-$0.txt 2>&1'
echo "$TOOL: $(grep -vc '^$' $LIST) tests, $P at a time, $FRAMES frames per scene test, $((SECONDS - t0)) s"
for f in $R/$TOOL-*.txt; do
  echo "$(grep '^\[ RUN' $f | head -1 | cut -c14-): ok $(grep -c '^\[       OK' $f), failed $(grep -c '^\[  FAILED  \] [A-Z]' $f); $(grep -h 'ERROR SUMMARY\|RACECHECK SUMMARY' $f | tr -s ' =' ' ')$(grep -q 'PASSED' $f || echo ' (cut or failed)')"
done
