#!/usr/bin/env bash
# r6.sh R: final figures of the session's GPU code (a cell pair of <= kLeafWholePairs vertex
# pairs one leaf item): GPU tests; Table 5 with [1,2] (persistent, two rounds; every path);
# bunny-stack-50 five runs alternating with bench_step_paths of bdac61d (.bundle-x); cuda vs
# cpu (16 threads) on the shipped scenes of >= 50 bodies that the midphase change touches
# (stack-50, Table 5, mixed pile); the settled piles (5 runs each); the device broadphases
# (octree vs lbvh, 10 reps).
set -u
R=${1:?}; mkdir -p $R
X=${X:?}
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1; nproc >> $R/device.txt; lscpu | grep "Model name" >> $R/device.txt
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
M="$S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json"
T5="$S/bunny-random-400.json $M"
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -4
s test_device_broadphase 150 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -4
s test_cuda_footprint 60 bin/test_cuda_footprint; grep -h "PASSED\|FAILED" $R/test_cuda_footprint.txt | head -4
tar xJf $X/v.tar.xz -C bin --strip-components=1
for i in 1 2; do s t5-$i 120 bin/bench_step_paths $T5 --midphase 1,2 --engines persistent --frames 1000 --repeat 5; grep "^| [a-z]" $R/t5-$i.txt | cut -d'|' -f2,4,6-8; done
s table5 150 bin/bench_step_paths $T5 --midphase 1,2 --engines graph,small,persistent --frames 1000 --repeat 5; grep "^| [a-z]" $R/table5.txt | cut -d'|' -f2,4,6-8
for i in 1 2 3 4 5; do for b in bench_step_paths bsp_bdac61d; do
  s stack50-$b-$i 60 bin/$b $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5; echo "$b: $(grep -h '^| bunny' $R/stack50-$b-$i.txt | cut -d'|' -f6-8)"
done; done
s shipped-small 200 bin/bench_step_paths $S/bunny-stack-50.json $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --engines cpu,graph,persistent --frames 3000 --warmup 0 --repeat 5; grep "^| [a-z]" $R/shipped-small.txt | cut -d'|' -f2,4,6-8
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
s bp 150 bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max 1000000 --json $R/gpu-broadphase-octree-lbvh.json; grep -h "^| [a-z]" $R/bp.txt | head -12
echo total $SECONDS s
