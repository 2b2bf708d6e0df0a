#!/usr/bin/env bash
# final3.sh R: run from inside the bundle dir. Item 5 (device broadphase bench) and item 6 (CPU octree vs bullet-dbvt on the 16-thread host, this build and 6dc3da5's).
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1; nproc >> $R/device.txt; lscpu | grep "Model name" >> $R/device.txt
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
export OMP_NUM_THREADS=16
for v in "exit0 OCTOCD_CUDA_MID_EARLY_EXIT=0" "cull0 OCTOCD_CUDA_MID_TILE_CULL=0" "both0 OCTOCD_CUDA_MID_EARLY_EXIT=0 OCTOCD_CUDA_MID_TILE_CULL=0" "default X=1"; do
  set -- $v; n=$1; shift
  s stack50-$n 60 env "$@" bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5; grep "^| bunny" $R/stack50-$n.txt | tail -1
done
s shipped-10k 150 bin/bench_step_paths $S/boxes-random-10000.json $S/boxes-uniform-10k.json $S/bunny-pile-10k.json --engines cpu,graph --frames 300 --warmup 20 --repeat 5; grep -h "^|" $R/shipped-10k.txt | tail -6
s shipped-100k 150 bin/bench_step_paths $S/boxes-uniform-50000.json $S/boxes-uniform-100k.json $S/bunny-pile-100k.json --engines cpu,graph --frames 100 --warmup 10 --repeat 5; grep -h "^|" $R/shipped-100k.txt | tail -6
s shipped-1m 100 bin/bench_step_paths $S/boxes-uniform-1m.json --engines cpu,graph --frames 10 --warmup 2 --repeat 5; grep -h "^|" $R/shipped-1m.txt | tail -2
unset OMP_NUM_THREADS
s bp 150 bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max 1000000 --json $R/gpu-broadphase-octree-lbvh.json; grep -h "^|" $R/bp.txt | head -12
for fr in 10 100; do
  for b in bench_broadphase bench_broadphase_6dc3da5; do
    FRAMES=$fr BIN=bin/$b timeout 100 bash cpu-bp-run.sh $R/cpu-bp-$b-f$fr > /dev/null 2>&1; echo "cpu-bp $b frames=$fr rc=$?"
  done
done
echo total $SECONDS s
