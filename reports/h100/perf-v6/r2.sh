#!/usr/bin/env bash
# r2.sh R: after the tile filter (bdac61d): the small path's phase profile of the Table 5
# mesh scenes (filter on / off), the leaf chunk size (kLeafChunk 256 = the bundle's
# bench_step_paths, 128 and 64 = variant builds carried in .bundle-x/), compute-sanitizer on
# the resident small path (OCTOCD_CUDA_STAGE_TIMES=0), Nsight Compute on the leaf kernels.
set -u
R=${1:?}; mkdir -p $R
X=${X:?}  # folder of the variant binaries
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
M="$S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json"
T5="$S/bunny-random-400.json $M"
for f in 1 0; do
  s prof-f$f 60 env OCTOCD_CUDA_SMALL_PROFILE=1 OCTOCD_CUDA_PERSISTENT=0 OCTOCD_CUDA_MID_TILE_FILTER=$f bin/bench_step_paths $M --midphase 1,2 --engines small --frames 1000 --repeat 1; grep -h "fused small step" $R/prof-f$f.txt
done
for i in 1 2; do for c in 256 128 64; do
  b=bin/bench_step_paths; [ $c = 256 ] || { cp $X/bsp_c$c bin/; b=bin/bsp_c$c; }
  s chunk$c-$i 120 $b $T5 --midphase 1,2 --engines persistent --frames 1000 --repeat 5; grep -h "^| [a-z]" $R/chunk$c-$i.txt
done; done
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
for sc in asian-dragon-random-60 dragon-random-250; do for tool in memcheck racecheck; do
  s san-$tool-$sc 150 env OCTOCD_CUDA_STAGE_TIMES=0 $CS --tool $tool bin/octocd run $S/$sc.json --engine cuda --midphase 1,2 --frames 200; grep -h "SUMMARY\|^steps/s\|^pipeline\|rror" $R/san-$tool-$sc.txt | head -4
done; done
NCU=$(command -v ncu || echo /usr/local/cuda/bin/ncu)
s ncu-leaf-asian 200 env OCTOCD_CUDA_SMALL=0 $NCU -k regex:mid_leaf_kernel -s 200 -c 3 --section SpeedOfLight --section WarpStateStats --section Occupancy --section LaunchStats --section SchedulerStats --section MemoryWorkloadAnalysis bin/octocd run $S/asian-dragon-random-60.json --engine cuda --midphase 1,2 --frames 300 --quiet
grep -h "Duration\|Achieved Occupancy\|Warp Cycles Per Issued\|Stall\|Block Limit\|Registers Per\|Grid Size" $R/ncu-leaf-asian.txt | head -30
echo total $SECONDS s
