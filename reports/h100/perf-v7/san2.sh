#!/usr/bin/env bash
# san2.sh R TOOL LIST LIMIT [FRAMES]: compute-sanitizer TOOL over the test_cuda_world tests
# named in LIST (one gtest name a line), each its own process, all at once, each cut at
# LIMIT s; --target-processes application-only. FRAMES: OCTOCD_GPU_TEST_FRAMES (frames per
# scene test; default the tests' 200).
set -u
R=${1:?}; TOOL=${2:?}; LIST=${3:?}; LIMIT=${4:?}; FRAMES=${5:-200}
mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=2
export OCTOCD_GPU_TEST_FRAMES=$FRAMES
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
t0=$SECONDS
i=0
while read -r t; do
  [ -z "$t" ] && continue
  timeout $LIMIT $CS --tool $TOOL --target-processes application-only bin/test_cuda_world --gtest_filter="$t" > $R/$TOOL-$i.txt 2>&1 &
  i=$((i + 1))
done < $LIST
wait
echo "$TOOL: $i tests, one process each, $FRAMES frames per scene test, $((SECONDS - t0)) s"
for ((k = 0; k < i; k++)); do
  f=$R/$TOOL-$k.txt
  echo "$(grep '^\[ RUN' $f | head -1 | cut -c14-): ok $(grep -c '^\[       OK' $f), failed $(grep -c '^\[  FAILED  \] [A-Z]' $f); $(grep -h 'ERROR SUMMARY\|RACECHECK SUMMARY' $f | tr -s ' =' ' ')$(grep -q 'PASSED' $f || echo ' (cut or failed)')"
done
