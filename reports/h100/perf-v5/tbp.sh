#!/usr/bin/env bash
# tbp.sh R: bplead (main + bpscale + the overflow fix): GPU tests, then bench_gpu_broadphase bplead vs main (alternating)
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
for t in test_device_broadphase test_cuda_world; do
  t0=$SECONDS; timeout 240 bin/$t > $R/$t.txt 2>&1; echo "$t rc=$? $((SECONDS-t0)) s"; grep -h "PASSED\|FAILED" $R/$t.txt | head -8
done
for i in 1 2; do
  for b in bench_gpu_broadphase bench_gpu_broadphase_main; do
    t0=$SECONDS; timeout 150 bin/$b --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 > $R/$b-$i.txt 2>&1; echo "$b-$i rc=$? $((SECONDS-t0)) s"; grep -h "^| " $R/$b-$i.txt | head -12
  done
done
