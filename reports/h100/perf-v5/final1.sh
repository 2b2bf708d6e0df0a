#!/usr/bin/env bash
# final1.sh R: run from inside the bundle dir. GPU tests; compute-sanitizer memcheck and racecheck on a
# 200-frame bunny-random-400 run (resident small path, and the graph path) and on parts of test_cuda_world.
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -12
s test_device_broadphase 100 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -6
s test_cuda_footprint 60 bin/test_cuda_footprint; grep -h "PASSED\|FAILED" $R/test_cuda_footprint.txt | head -3
s memcheck_run_resident 120 env OCTOCD_CUDA_STAGE_TIMES=0 $CS --tool memcheck bin/octocd run $S/bunny-random-400.json --engine cuda --frames 200 --quiet; grep -h "SUMMARY" $R/memcheck_run_resident.txt
s racecheck_run_resident 150 env OCTOCD_CUDA_STAGE_TIMES=0 $CS --tool racecheck bin/octocd run $S/bunny-random-400.json --engine cuda --frames 200 --quiet; grep -h "SUMMARY\|hazard" $R/racecheck_run_resident.txt | tail -2
s memcheck_run_graph 120 env OCTOCD_CUDA_STAGE_TIMES=0 OCTOCD_CUDA_SMALL=0 $CS --tool memcheck bin/octocd run $S/bunny-random-400.json --engine cuda --frames 200 --quiet; grep -h "SUMMARY" $R/memcheck_run_graph.txt
s racecheck_run_graph 150 env OCTOCD_CUDA_STAGE_TIMES=0 OCTOCD_CUDA_SMALL=0 $CS --tool racecheck bin/octocd run $S/bunny-random-400.json --engine cuda --frames 200 --quiet; grep -h "SUMMARY\|hazard" $R/racecheck_run_graph.txt | tail -2
F='CudaMidphase.*:CudaSmallStep.*:CudaPersistent.*:*CudaRerun*bunny_stack_50*:*CudaOctree*armadillo*'
s memcheck_tcw_part 200 env OCTOCD_GPU_TEST_FRAMES=50 $CS --tool memcheck bin/test_cuda_world --gtest_filter="$F"; grep -h "SUMMARY\|PASSED\|FAILED" $R/memcheck_tcw_part.txt | head -5
echo total $SECONDS s
