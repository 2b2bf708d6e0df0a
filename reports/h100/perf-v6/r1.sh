#!/usr/bin/env bash
# r1.sh R: the tile filter (OCTOCD_CUDA_MID_TILE_FILTER): GPU tests, Table 5 with [1,2]
# (persistent small path, 1000 frames, 5 reps) with the filter on and off alternately,
# bunny-stack-50, the piles, sanitizers on a 200-frame bunny-random-400 and asian-dragon run.
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
T5="$S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json"
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED\|tile filter" $R/test_cuda_world.txt | head -8
for i in 1 2; do for f in 1 0; do
  s table5-f$f-$i 120 env OCTOCD_CUDA_MID_TILE_FILTER=$f bin/bench_step_paths $T5 --midphase 1,2 --engines persistent --frames 1000 --repeat 5; grep -h "^| [a-z]" $R/table5-f$f-$i.txt
done; done
s table5-paths 150 bin/bench_step_paths $T5 --midphase 1,2 --engines graph,small,persistent --frames 1000 --repeat 5; grep -h "^| [a-z]" $R/table5-paths.txt
s stack50 60 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5; grep -h "^| bunny" $R/stack50.txt
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
for sc in bunny-random-400 asian-dragon-random-60; do for tool in memcheck racecheck; do
  s san-$tool-$sc 150 $CS --tool $tool bin/octocd run $S/$sc.json --engine cuda --midphase 1,2 --frames 200 --quiet; grep -h "ERROR SUMMARY\|RACECHECK SUMMARY\|Error" $R/san-$tool-$sc.txt | head -3
done; done
echo total $SECONDS s
