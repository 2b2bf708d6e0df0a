#!/usr/bin/env bash
# finalA.sh R: run from inside the bundle dir. GPU tests, memcheck of the small (resident) path, step paths, broadphase bench.
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -12
s test_device_broadphase 200 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -8
s test_cuda_footprint 60 bin/test_cuda_footprint; grep -h "PASSED\|FAILED" $R/test_cuda_footprint.txt | head -3
s memcheck_run_resident 100 env OCTOCD_CUDA_STAGE_TIMES=0 compute-sanitizer --tool memcheck bin/octocd run $S/bunny-random-400.json --engine cuda --frames 200 --quiet; grep -h "SUMMARY" $R/memcheck_run_resident.txt
s stack50 120 bin/bench_step_paths $S/bunny-stack-50.json --engines cpu,graph,small,persistent --frames 2000 --repeat 5; grep "^|" $R/stack50.txt | tail -5
s table5 150 bin/bench_step_paths $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --midphase 1,2 --engines graph,small,persistent --frames 1000 --repeat 5; grep "^|" $R/table5.txt | tail -12
s bp 200 bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max 1000000 --json $R/gpu-broadphase-octree-lbvh.json; grep -h "^|" $R/bp.txt | head -14
echo total $SECONDS s
