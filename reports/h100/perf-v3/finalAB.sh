#!/usr/bin/env bash
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
BUDGET=560
s() { local name=$1 t=$2; shift 2; local left=$((BUDGET-SECONDS)); ((t>left)) && t=$left; ((t<10)) && { echo "$name skipped"; return; }; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
s test_cuda_world 150 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -12
s memcheck_run_resident 100 env OCTOCD_CUDA_STAGE_TIMES=0 compute-sanitizer --tool memcheck bin/octocd run $S/bunny-random-400.json --engine cuda --frames 200; grep -h "SUMMARY\|steps/s\|small" $R/memcheck_run_resident.txt | head -4
s stack50 120 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines cpu,graph,small,persistent --front-bodies 0,256 --frames 2000 --repeat 5; grep "^|" $R/stack50.txt | tail -7
s table5 150 bin/bench_step_paths $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --midphase 1,2 --engines graph,small,persistent --frames 1000 --repeat 5; grep "^|" $R/table5.txt | tail -12
s memcheck_persistent_tests 100 compute-sanitizer --tool memcheck bin/test_cuda_world --gtest_filter='CudaPersistent.*'; grep -h "SUMMARY\|PASSED\|FAILED" $R/memcheck_persistent_tests.txt
s racecheck_run_resident 150 env OCTOCD_CUDA_STAGE_TIMES=0 compute-sanitizer --tool racecheck bin/octocd run $S/bunny-random-400.json --engine cuda --frames 200 --quiet; grep -h "SUMMARY" $R/racecheck_run_resident.txt
s memcheck_loose 60 compute-sanitizer --tool memcheck bin/test_device_broadphase --gtest_filter='*/loose_auto:*/loose_thread_auto:*WithScratch*'; grep -h "ERROR SUMMARY\|PASSED\|FAILED" $R/memcheck_loose.txt
s racecheck_loose 60 compute-sanitizer --tool racecheck bin/test_device_broadphase --gtest_filter='*/loose_auto:*WithScratch*'; grep -h "RACECHECK SUMMARY\|PASSED\|FAILED" $R/racecheck_loose.txt
echo total $SECONDS s
