#!/usr/bin/env bash
# final5.sh R: the lean small kernel (<= 64 bodies) and the snapped octree root (bpfix): tests, stack-50, broadphase bench snap on/off
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
s stack50 60 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines cpu,graph,small,persistent --frames 2000 --repeat 5; grep "^| bunny" $R/stack50.txt
s stack50-b 60 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5; grep "^| bunny" $R/stack50-b.txt
for i in 1 2; do for snap in 1 0; do
  s bp-snap$snap-$i 60 env OCTOCD_CUDA_OCTREE_SNAP=$snap bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max 1000000; grep -h "^| octree\|^| lbvh" $R/bp-snap$snap-$i.txt
done; done
s test_device_broadphase 100 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -6
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -8
echo total $SECONDS s
