#!/usr/bin/env bash
# DEVICE.sh R (branch bpfix): run from the root of a bundle made by scripts/gpu-bundle.sh.
# The device octree with its block table, checked and timed: test_device_broadphase (with
# the bench-size exact-test counts, OCTOCD_BP_COUNT_LARGE=1), test_cuda_world's octree and
# capacity tests, memcheck on the test that faulted before 8e9ef46, then bench_gpu_broadphase
# octree vs lbvh, the snapped root on and off (twice each).
set -u
R=${1:?usage: DEVICE.sh RESULTS_DIR}; mkdir -p "$R"
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
nvidia-smi --query-gpu=name,driver_version --format=csv > "$R/device.txt" 2>&1
git rev-parse HEAD > "$R/revision.txt" 2>/dev/null || cat REVISION > "$R/revision.txt" 2>/dev/null
t0=$SECONDS; OCTOCD_BP_COUNT_LARGE=1 timeout 420 bin/test_device_broadphase > "$R/test_device_broadphase.txt" 2>&1
echo "test_device_broadphase rc=$? $((SECONDS-t0)) s"; grep -h "PASSED\|FAILED\|^n [0-9]" "$R/test_device_broadphase.txt" | head -12
t0=$SECONDS; timeout 300 bin/test_cuda_world --gtest_filter='*CudaOctree*:*CudaRerun*:*apacity*' > "$R/test_cuda_world-octree.txt" 2>&1
echo "test_cuda_world octree/capacity rc=$? $((SECONDS-t0)) s"; grep -h "PASSED\|FAILED" "$R/test_cuda_world-octree.txt" | head -8
t0=$SECONDS; timeout 300 compute-sanitizer --tool memcheck --error-exitcode 9 bin/test_cuda_world \
  --gtest_filter='Scenes/CudaOctree.PairsEqualFlatAndStatesEqualCpuOctree/armadillo_random_250_graph' > "$R/memcheck-armadillo-octree.txt" 2>&1
echo "memcheck rc=$? $((SECONDS-t0)) s"; grep -h "ERROR SUMMARY\|PASSED\|FAILED" "$R/memcheck-armadillo-octree.txt" | head -4
# The snapped root (default) and the domain's root (OCTOCD_CUDA_OCTREE_SNAP=0, the octree as
# on main), alternating.
for i in 1 2; do
  for snap in 1 0; do
    f="$R/bench_gpu_broadphase-snap$snap-$i.txt"
    t0=$SECONDS; OCTOCD_CUDA_OCTREE_SNAP=$snap timeout 150 bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 > "$f" 2>&1
    echo "bench snap=$snap run $i rc=$? $((SECONDS-t0)) s"; grep -h "^| " "$f" | head -12
  done
done
