#!/usr/bin/env bash
# finalC.sh R: settled piles x5 and the shipped scenes (cuda vs cpu)
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s test_cuda_world 150 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -12
s test_device_broadphase 100 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -5
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
