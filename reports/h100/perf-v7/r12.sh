#!/usr/bin/env bash
# r12.sh R: the review commit (loose_cell_run, loose_blocks_through): GPU tests and the
# octree vs lbvh once more.
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
bin/octocd --version > $R/version.txt 2>&1; cat $R/version.txt
s test_device_broadphase 150 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -4
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -4
s test_cuda_footprint 60 bin/test_cuda_footprint; grep -h "PASSED\|FAILED" $R/test_cuda_footprint.txt | head -4
s bp 100 bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max 1000000 --json $R/bp.json
grep -h "^| octree\|^| lbvh\|identical" $R/bp.txt | head -9
echo total $SECONDS s
