#!/usr/bin/env bash
# r7.sh R: bp::PairBuffer in lbvh too: broadphase tests (+ memcheck of the pair-buffer
# test); octree vs lbvh with OCTOCD_CUDA_BP_PAIR_BUFFER=1 and =0 alternately, two rounds.
set -u
R=${1:?}; mkdir -p $R
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
s test_device_broadphase 150 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -4
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
s memcheck-pairbuffer 200 $CS --tool memcheck bin/test_device_broadphase --gtest_filter='DevicePairBuffer.*'
grep -h "PASSED\|FAILED\|ERROR SUMMARY" $R/memcheck-pairbuffer.txt | head -4
for i in 1 2; do for b in 1 0; do
  om=0; [ $i = 1 ] && om=1000000
  s bp-buf$b-$i 150 env OCTOCD_CUDA_BP_PAIR_BUFFER=$b bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,3e4,6e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max $om --json $R/bp-buf$b-$i.json
  grep -h "^| octree\|^| lbvh\|identical" $R/bp-buf$b-$i.txt | head -14
done; done
echo total $SECONDS s
