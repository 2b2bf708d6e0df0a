#!/usr/bin/env bash
# final6.sh R: the lean small kernel (bunny-stack-50, 55 bodies): memcheck and racecheck of a 200-frame run; 3 more bench runs
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
s memcheck_stack50 120 env OCTOCD_CUDA_STAGE_TIMES=0 $CS --tool memcheck bin/octocd run $S/bunny-stack-50.json --engine cuda --frames 200 --quiet; grep -h "SUMMARY" $R/memcheck_stack50.txt
s racecheck_stack50 150 env OCTOCD_CUDA_STAGE_TIMES=0 $CS --tool racecheck bin/octocd run $S/bunny-stack-50.json --engine cuda --frames 200 --quiet; grep -h "SUMMARY" $R/racecheck_stack50.txt
for i in 1 2 3; do
  s stack50-$i 60 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5; grep "^| bunny" $R/stack50-$i.txt
done
echo total $SECONDS s
