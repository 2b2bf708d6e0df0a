#!/usr/bin/env bash
# final2.sh R: run from inside the bundle dir. Item 2 (small scenes), 3 (Table 5), 4 (piles), 5 (broadphase), 6 (CPU octree vs dbvt on the 16-thread host).
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1; nproc >> $R/device.txt; lscpu | grep "Model name" >> $R/device.txt
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
s stack50 100 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines cpu,graph,small,persistent --frames 2000 --repeat 5; grep "^|" $R/stack50.txt | tail -4
s table5 150 bin/bench_step_paths $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --midphase 1,2 --engines graph,small,persistent --frames 1000 --repeat 5; grep "^|" $R/table5.txt | tail -12
s shipped-small 200 bin/bench_step_paths $S/bunny-stack-50.json $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --engines cpu,graph,persistent --frames 3000 --warmup 0 --repeat 5; grep "^|" $R/shipped-small.txt | tail -15
s shipped-mixed 100 bin/bench_step_paths $S/mixed-pile-1000.json --engines cpu,graph,persistent --frames 2000 --warmup 0 --repeat 5; grep "^|" $R/shipped-mixed.txt | tail -3
for i in 1 2 3 4 5; do
  s pile100k-$i 60 env OCTOCD_CUDA_STAGE_TIMES=0 bin/octocd run $S/bunny-pile-100k.json --engine cuda --frames 3000 --quiet --summary-json $R/pile100k-$i.json
done
for i in 1 2 3 4 5; do
  s pile1m-$i 90 env OCTOCD_CUDA_STAGE_TIMES=0 bin/octocd run $S/bunny-pile-1m.json --engine cuda --frames 1500 --quiet --summary-json $R/pile1m-$i.json
done
python3 - $R <<'PY'
import json,sys,glob
for n in ("pile100k","pile1m"):
    v=[json.load(open(f))["steps_per_s"] for f in sorted(glob.glob(f"{sys.argv[1]}/{n}-*.json"))]
    if v: print(n, len(v), "median %.2f min %.2f max %.2f" % (sorted(v)[len(v)//2], min(v), max(v)))
PY
echo total $SECONDS s
