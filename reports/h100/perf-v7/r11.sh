#!/usr/bin/env bash
# r11.sh R: bunny-stack-50 (persistent, 2000 frames x 5) side by side in one call, five
# rounds: this build with OCTOCD_CUDA_PERSISTENT_POLLERS=1 and =2, bench_step_paths of
# 02971e3 (the resident kernel before the pollers; built from that commit, .bundle-x) and of
# bdac61d (perf-v6's reference).
set -u
R=${1:?}; mkdir -p $R
X=${X:?}
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
tar xJf $X/v.tar.xz -C bin --strip-components=1
for i in 1 2 3 4 5; do
  for v in p1 p2 bsp_02971e3 bsp_bdac61d; do
    case $v in
      p1) c="env OCTOCD_CUDA_PERSISTENT_POLLERS=1 bin/bench_step_paths";;
      p2) c="env OCTOCD_CUDA_PERSISTENT_POLLERS=2 bin/bench_step_paths";;
      *) c="bin/$v";;
    esac
    s stack50-$v-$i 60 $c $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5
    echo "$v: $(grep -h '^| bunny' $R/stack50-$v-$i.txt | cut -d'|' -f6-8)"
  done
done
echo total $SECONDS s
