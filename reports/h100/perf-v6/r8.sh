#!/usr/bin/env bash
# r8.sh R: compute-sanitizer memcheck of test_cuda_world at 20 frames per scene test (r7 ran
# the tests' own 200 and four of eight shards were cut at 420 s): san.sh with 8 shards at
# once, every test but CudaMemory.CliExits* (stalls under the sanitizer: its `octocd` child,
# even with --target-processes application-only) and CudaMidphase.EarlyExit* (fixed 850
# frames x 9 engines), which runs beside them as a ninth process.
set -u
R=${1:?}; mkdir -p $R
D=$(dirname $(readlink -f $0))
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
( timeout 500 $CS --tool memcheck --target-processes application-only bin/test_cuda_world --gtest_filter='CudaMidphase.EarlyExit*' > $R/memcheck-earlyexit.txt 2>&1; echo "earlyexit rc=$?" ) &
bash $D/san.sh $R memcheck 8 500 20 '-CudaMemory.CliExits*:CudaMidphase.EarlyExit*'
wait
grep -h "OK \]\|PASSED\|FAILED\|ERROR SUMMARY" $R/memcheck-earlyexit.txt | head -4
echo total $SECONDS s
