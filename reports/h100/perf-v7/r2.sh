#!/usr/bin/env bash
# r2.sh R: the warp-aggregated pair append of loose_query_kernel: broadphase tests, bench
# octree vs lbvh (two rounds), ncu of the query at 4x10^6 with warp stall sampling.
set -u
R=${1:?}; mkdir -p $R
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
s test_device_broadphase 200 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -8
for i in 1 2; do
  om=0; [ $i = 1 ] && om=1000000
  s bp-$i 150 bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max $om --json $R/bp-$i.json
  grep -h "^| octree\|^| lbvh\|identical" $R/bp-$i.txt | head -12
done
NCU=$(command -v ncu || echo /usr/local/cuda/bin/ncu)
for n in 1e6 4e6; do
  s ncu-query-$n 200 $NCU -k regex:loose_query_kernel -c 1 --section SpeedOfLight --section MemoryWorkloadAnalysis --section WarpStateStats --section Occupancy --section SchedulerStats --section SourceCounters bin/bench_gpu_broadphase --only octree --sizes $n --reps 1 --warmup 0 --oracle-max 0
  grep -h "Duration\|Hit Rate\|DRAM Throughput\|Achieved Occupancy\|Warp Cycles Per Issued\|Eligible Warps" $R/ncu-query-$n.txt | head -14
done
s ncu-octree-4e6 200 $NCU --section SpeedOfLight bin/bench_gpu_broadphase --only octree --sizes 4e6 --reps 1 --warmup 0 --oracle-max 0
grep -h "^  [a-zA-Z_:<>(), 0-9]*(.*)x(.*)\|Duration" $R/ncu-octree-4e6.txt | paste - - | sed 's/  */ /g' | cut -c1-160 | head -16
echo total $SECONDS s
