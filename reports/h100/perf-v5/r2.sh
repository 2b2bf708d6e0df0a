#!/usr/bin/env bash
# r2.sh R: the small path's fused leaves (OCTOCD_CUDA_MID_FUSE unset / 0 / 1) on bunny-stack-50 and the Table 5 scenes
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
S=datasets/scenes
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; grep -h "^|" $R/$name.txt | tail -${N:-4}; }
for f in auto 0 1; do
  if [ $f = auto ]; then unset OCTOCD_CUDA_MID_FUSE; else export OCTOCD_CUDA_MID_FUSE=$f; fi
  N=3 s stack50-f$f 60 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines small,persistent --frames 2000 --repeat 5
  N=4 s table5-f$f 120 bin/bench_step_paths $S/bunny-random-400.json $S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json --midphase 1,2 --engines persistent --frames 1000 --repeat 5
  OCTOCD_CUDA_SMALL_PROFILE=1 OCTOCD_CUDA_PERSISTENT=0 N=1 s prof-f$f 60 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines small --frames 2000 --repeat 1
  grep -h "mean over" $R/prof-f$f.txt
done
echo total $SECONDS s
