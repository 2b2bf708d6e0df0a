#!/usr/bin/env bash
# r5.sh R: the warp query below 32,768 bodies: GPU tests; bench octree vs lbvh (two rounds)
# and the warp / thread query at 3x10^4 .. 6x10^4; memcheck of test_device_broadphase's
# octree tests and of the bench at 10^5 and 4x10^6 (the thread query's local pair buffer).
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
s test_device_broadphase 150 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -4
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -4
unset OMP_NUM_THREADS
for i in 1 2; do
  om=0; [ $i = 1 ] && om=1000000
  s bp-$i 150 bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,3e4,6e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max $om --json $R/bp-$i.json
  grep -h "^| octree\|^| lbvh\|identical" $R/bp-$i.txt | head -14
done
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
s memcheck-bp-tests 300 $CS --tool memcheck bin/test_device_broadphase --gtest_filter='*oose*:*ctree*'
grep -h "PASSED\|FAILED\|ERROR SUMMARY" $R/memcheck-bp-tests.txt | head -4
s memcheck-bench 200 $CS --tool memcheck bin/bench_gpu_broadphase --only octree --sizes 1e5,4e6 --reps 1 --warmup 0 --oracle-max 100000
grep -h "identical\|ERROR SUMMARY" $R/memcheck-bench.txt | head -4
echo total $SECONDS s
