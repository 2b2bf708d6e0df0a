#!/usr/bin/env bash
# usage: device12.sh BUNDLE_TAR TAG   (issue 20 item 2: cuda vs cpu on every shipped scene of >= 50 bodies)
set -u
B=$1; TAG=$2
mkdir -p /tmp/d && { [ -d /tmp/d/octocd-bundle ] || tar xJf $B -C /tmp/d; }
cd /tmp/d/octocd-bundle || exit 9
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
R=/tmp/r-$TAG; mkdir -p $R
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1; cp REVISION VERSION $R/ 2>/dev/null
s() { local name=$1; shift; local t0=$SECONDS; timeout ${TMO:-150} "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; grep -h "^|" $R/$name.txt | tail -${N:-8}; }
S=datasets/scenes
N=17 TMO=240 s shipped-small bin/bench_step_paths $S/bunny-stack-50.json $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --engines cpu,graph,small --frames 3000 --warmup 0 --repeat 5
N=5 TMO=100 s shipped-mixed bin/bench_step_paths $S/mixed-pile-1000.json --engines cpu,graph,small --frames 2000 --warmup 0 --repeat 5
N=10 TMO=150 s shipped-10k bin/bench_step_paths $S/boxes-random-10000.json $S/boxes-uniform-10k.json $S/bunny-pile-10k.json --engines cpu,graph --frames 300 --warmup 20 --repeat 5
N=10 TMO=150 s shipped-100k bin/bench_step_paths $S/boxes-uniform-50000.json $S/boxes-uniform-100k.json $S/bunny-pile-100k.json --engines cpu,graph --frames 100 --warmup 10 --repeat 5
N=8 TMO=200 s shipped-1m bin/bench_step_paths $S/boxes-uniform-1m.json $S/bunny-pile-1m.json --engines cpu,graph --frames 20 --warmup 5 --repeat 5
tar cf $OUT/results.tar -C $R .
