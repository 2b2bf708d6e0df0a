#!/usr/bin/env bash
# r1.sh R: the occupancy map of the device octree (OCTOCD_CUDA_OCTREE_OCCUPANCY): broadphase
# tests, bench_gpu_broadphase octree vs lbvh with the map on and off alternately (two rounds),
# ncu of the query kernel and of one find's kernels at 10^6 and 4x10^6.
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
s test_device_broadphase 200 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -8
for i in 1 2; do for o in 1 0; do
  om=0; [ $i = 1 ] && om=1000000
  s bp-occ$o-$i 150 env OCTOCD_CUDA_OCTREE_OCCUPANCY=$o bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max $om --json $R/bp-occ$o-$i.json
  grep -h "^| octree\|^| lbvh\|identical" $R/bp-occ$o-$i.txt | head -12
done; done
NCU=$(command -v ncu || echo /usr/local/cuda/bin/ncu)
for n in 1e6 4e6; do
  s ncu-query-$n 200 $NCU -k regex:loose_query_kernel -c 1 --section SpeedOfLight --section MemoryWorkloadAnalysis --section WarpStateStats --section Occupancy --section SchedulerStats --section LaunchStats bin/bench_gpu_broadphase --only octree --sizes $n --reps 1 --warmup 0 --oracle-max 0
  grep -h "Duration\|Hit Rate\|DRAM Throughput\|Memory Throughput\|Achieved Occupancy\|Warp Cycles Per Issued\|Eligible Warps" $R/ncu-query-$n.txt | head -14
  s ncu-octree-$n 200 $NCU --section SpeedOfLight bin/bench_gpu_broadphase --only octree --sizes $n --reps 1 --warmup 0 --oracle-max 0
  grep -h "^  [a-zA-Z_:<>(), 0-9]*(.*)x(.*)\|Duration" $R/ncu-octree-$n.txt | paste - - | sed 's/  */ /g' | cut -c1-160 | head -30
done
echo total $SECONDS s
