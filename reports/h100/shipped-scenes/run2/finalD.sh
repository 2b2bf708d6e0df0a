#!/usr/bin/env bash
# finalD.sh R: cuda vs cpu on every shipped scene of >= 50 bodies (each small scene over its whole length)
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; grep -h "^|" $R/$name.txt | tail -${N:-8}; }
S=datasets/scenes
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
N=6 s stack50 100 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines cpu,graph,small,persistent --frames 2000 --repeat 5
N=14 s table5 120 bin/bench_step_paths $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --midphase 1,2 --engines graph,small,persistent --frames 1000 --repeat 5
N=17 s shipped-small 240 bin/bench_step_paths $S/bunny-stack-50.json $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --engines cpu,graph,persistent --frames 3000 --warmup 0 --repeat 5
N=5 s shipped-mixed 100 bin/bench_step_paths $S/mixed-pile-1000.json --engines cpu,graph,persistent --frames 2000 --warmup 0 --repeat 5
N=10 s shipped-10k 120 bin/bench_step_paths $S/boxes-random-10000.json $S/boxes-uniform-10k.json $S/bunny-pile-10k.json --engines cpu,graph --frames 300 --warmup 20 --repeat 5
N=10 s shipped-100k 120 bin/bench_step_paths $S/boxes-uniform-50000.json $S/boxes-uniform-100k.json $S/bunny-pile-100k.json --engines cpu,graph --frames 100 --warmup 10 --repeat 5
N=8 s shipped-1m 100 bin/bench_step_paths $S/boxes-uniform-1m.json --engines cpu,graph --frames 10 --warmup 2 --repeat 5
echo total $SECONDS s
