#!/usr/bin/env bash
# r4.sh R: bunny-stack-50 on the resident small path at grids of 16 .. 66 blocks
# (--small-blocks, OCTOCD_CUDA_SMALL_BLOCKS), two rounds; then racecheck (san2.sh, 20
# frames per scene test) of the 23 test_cuda_world tests r9/r10 of perf-v6 did not reach,
# each its own process, cut at 450 s.
set -u
R=${1:?}; mkdir -p $R
D=$(dirname $(readlink -f $0))
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
for i in 1 2; do
  s stack50-blocks-$i 120 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines persistent --small-blocks 16,24,33,44,66 --frames 2000 --repeat 5
  grep -h '^| bunny' $R/stack50-blocks-$i.txt | cut -d'|' -f4-8
done
bash $D/san2.sh $R racecheck $D/racecheck-left.txt 450 20
echo total $SECONDS s
