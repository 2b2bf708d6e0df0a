#!/usr/bin/env bash
set -u
B=$1; TAG=$2
mkdir -p /tmp/d && tar xJf $B -C /tmp/d
cd /tmp/d/octocd-bundle || exit 9
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
R=/tmp/r-$TAG; mkdir -p $R
s() { local name=$1; shift; local t0=$SECONDS; timeout ${TMO:-150} "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
TMO=270 s racecheck_run_small bash -c "OCTOCD_CUDA_SMALL=1 OCTOCD_CUDA_STAGE_TIMES=0 compute-sanitizer --tool racecheck bin/octocd run datasets/scenes/bunny-random-400.json --engine cuda --frames 200 --quiet"; grep -h "SUMMARY" $R/racecheck_run_small.txt
TMO=270 s memcheck_test_cuda_world_small compute-sanitizer --tool memcheck bin/test_cuda_world --gtest_filter='*_small*:CudaSmallStep.*'; grep -h "SUMMARY\|PASSED\|FAILED" $R/memcheck_test_cuda_world_small.txt
tar cf $OUT/results.tar -C $R .
