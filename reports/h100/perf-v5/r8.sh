#!/usr/bin/env bash
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
S=datasets/scenes
timeout 100 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines persistent --small-blocks 44,66,132 --front-bodies 0,64 --frames 2000 --repeat 5 > $R/stack50.txt 2>&1
grep -h "^| bunny" $R/stack50.txt
OCTOCD_CUDA_SMALL_PROFILE=1 OCTOCD_CUDA_PERSISTENT=0 timeout 60 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines small --front-bodies 64 --small-blocks 66 --frames 2000 --repeat 1 > $R/prof.txt 2>&1
grep -h "mean over\|^| bunny" $R/prof.txt
timeout 150 bin/bench_step_paths $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --midphase 1,2 --engines persistent --small-blocks 66,132 --frames 1000 --repeat 3 > $R/table5.txt 2>&1
grep -h "^| [a-z]" $R/table5.txt
