#!/usr/bin/env bash
# usage: device8.sh BUNDLE_TAR TAG
set -u
B=$1; TAG=$2
mkdir -p /tmp/d && tar xJf $B -C /tmp/d
cd /tmp/d/octocd-bundle || exit 9
[ -f datasets/cache/bunny.obj ] || { echo "no meshes in the bundle"; exit 9; }
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
R=/tmp/r-$TAG; mkdir -p $R
cp REVISION $R/ 2>/dev/null; nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1; shift; local t0=$SECONDS; timeout ${TMO:-150} "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
s test_cuda_world bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -8
s test_device_broadphase bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -3
export OMP_NUM_THREADS=16
s bench_stack50 bin/bench_step_paths datasets/scenes/bunny-stack-50.json --midphase 1,2 --small-wait poll,sync --one-block-pairs 0,512 --frames 2000 --repeat 5; tail -7 $R/bench_stack50.txt
OCTOCD_CUDA_SMALL_PROFILE=1 s profile_stack50 bin/bench_step_paths datasets/scenes/bunny-stack-50.json --midphase 1,2 --engines graph,small --small-wait poll,sync --frames 2000 --repeat 5; tail -6 $R/profile_stack50.txt
s grid_stack50 bin/bench_step_paths datasets/scenes/bunny-stack-50.json --midphase 1,2 --engines small --small-blocks 1,4,16,33,66,132 --frames 2000 --repeat 5; tail -7 $R/grid_stack50.txt
OCTOCD_CUDA_SMALL_PROFILE=1 s profile_bunny400 bin/bench_step_paths datasets/scenes/bunny-random-400.json --engines graph,small --one-block-pairs 0,512,4096 --frames 1000 --repeat 5; tail -8 $R/profile_bunny400.txt
TMO=240 s table5 bin/bench_step_paths datasets/scenes/bunny-random-400.json datasets/scenes/armadillo-random-250.json datasets/scenes/dragon-random-250.json datasets/scenes/asian-dragon-random-60.json --one-block-pairs 0,512,4096 --frames 1000 --repeat 5; grep "^|" $R/table5.txt | tail -20
TMO=120 s memcheck_small bash -c "OCTOCD_CUDA_SMALL=1 OCTOCD_CUDA_STAGE_TIMES=0 compute-sanitizer --tool memcheck bin/octocd run datasets/scenes/bunny-random-400.json --engine cuda --frames 200"; grep -h "SUMMARY" $R/memcheck_small.txt
TMO=200 s racecheck_small compute-sanitizer --tool racecheck bin/test_cuda_world --gtest_filter='CudaSmallStep.AnyGrid*'; grep -h "SUMMARY\|PASSED\|FAILED" $R/racecheck_small.txt
TMO=120 s synccheck_small compute-sanitizer --tool synccheck bin/test_cuda_world --gtest_filter='CudaSmallStep.AnyGrid*'; grep -h "SUMMARY\|PASSED\|FAILED" $R/synccheck_small.txt
tar cf $OUT/results.tar -C $R .
