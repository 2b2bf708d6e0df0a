#!/usr/bin/env bash
# r3.sh R: the final GPU code's figures: GPU tests; Table 5 with [1,2] (persistent, two
# rounds); bunny-stack-50 five runs of 5 (+ its phase profile); cuda vs cpu on the shipped
# scenes of >= 50 bodies; the settled piles (5 runs each); the device broadphase, a third
# round, and the octree's query kernels (warp / thread) at 10^4 .. 10^5 for kWarpQueryBodies.
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1; nproc >> $R/device.txt; lscpu | grep "Model name" >> $R/device.txt
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
T5="$S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json"
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -4
s test_cuda_footprint 60 bin/test_cuda_footprint; grep -h "PASSED\|FAILED" $R/test_cuda_footprint.txt | head -4
for i in 1 2; do s t5-$i 120 bin/bench_step_paths $T5 --midphase 1,2 --engines persistent --frames 1000 --repeat 5; grep "^| [a-z]" $R/t5-$i.txt | cut -d'|' -f2,4,6-8; done
for i in 1 2 3 4 5; do
  s stack50-$i 60 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5; echo "$(grep -h '^| bunny' $R/stack50-$i.txt | cut -d'|' -f6-8)"
done
s stack50-prof 60 env OCTOCD_CUDA_SMALL_PROFILE=1 OCTOCD_CUDA_PERSISTENT=0 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines small --frames 2000 --repeat 1; grep -h "^small" $R/stack50-prof.txt | cut -c1-400
s shipped-small 200 bin/bench_step_paths $S/bunny-stack-50.json $T5 --engines cpu,graph,persistent --frames 3000 --warmup 0 --repeat 5; grep "^| [a-z]" $R/shipped-small.txt | cut -d'|' -f2,4,6-8
s shipped-mixed 100 bin/bench_step_paths $S/mixed-pile-1000.json --engines cpu,graph,persistent --frames 2000 --warmup 0 --repeat 5; grep "^| [a-z]" $R/shipped-mixed.txt | cut -d'|' -f2,4,6-8
for i in 1 2 3 4 5; do s pile100k-$i 60 env OCTOCD_CUDA_STAGE_TIMES=0 bin/octocd run $S/bunny-pile-100k.json --engine cuda --frames 3000 --quiet --summary-json $R/pile100k-$i.json; done
for i in 1 2 3 4 5; do s pile1m-$i 90 env OCTOCD_CUDA_STAGE_TIMES=0 bin/octocd run $S/bunny-pile-1m.json --engine cuda --frames 1500 --quiet --summary-json $R/pile1m-$i.json; done
python3 - $R <<'PY'
import json,sys,glob
for n in ("pile100k","pile1m"):
    v=[json.load(open(f))["steps_per_s"] for f in sorted(glob.glob(f"{sys.argv[1]}/{n}-*.json"))]
    if v: print(n, len(v), "median %.2f min %.2f max %.2f" % (sorted(v)[len(v)//2], min(v), max(v)))
PY
unset OMP_NUM_THREADS
s bp-3 150 bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max 0 --json $R/bp-3.json; grep -h "^| octree\|^| lbvh" $R/bp-3.txt | head -12
for q in warp thread; do
  s bpq-$q 100 env OCTOCD_CUDA_OCTREE_QUERY=$q bin/bench_gpu_broadphase --only octree --sizes 1e4,3e4,6e4,1e5 --reps 10 --warmup 3 --oracle-max 100000 --json $R/bpq-$q.json; grep -h "^| octree\|identical" $R/bpq-$q.txt | head -6
done
echo total $SECONDS s
