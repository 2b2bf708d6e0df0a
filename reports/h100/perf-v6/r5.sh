#!/usr/bin/env bash
# r5.sh R: leaf chunks of B by A's split (kLeafChunk 64, kLeafChunkSplit 128 when A's cell
# is split into kLeafAPart parts): GPU tests; Table 5 with [1,2] (persistent, 1000 frames, 5
# reps) against variant builds in .bundle-x/v.tar.xz (bsp_cC_sS: C, S the two chunk sizes;
# c128_s128 = r4's default), two rounds; Table 5 on every step path; bunny-stack-50.
set -u
R=${1:?}; mkdir -p $R
X=${X:?}
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1; nproc >> $R/device.txt; lscpu | grep "Model name" >> $R/device.txt
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
M="$S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json"
T5="$S/bunny-random-400.json $M"
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED\|tile filter" $R/test_cuda_world.txt | head -4
s test_device_broadphase 150 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -4
s test_cuda_footprint 60 bin/test_cuda_footprint; grep -h "PASSED\|FAILED" $R/test_cuda_footprint.txt | head -4
tar xJf $X/v.tar.xz -C bin --strip-components=1
for i in 1 2; do for b in bench_step_paths bsp_c128_s128 bsp_c96_s96 bsp_c64_s256; do
  s t5-$b-$i 120 bin/$b $T5 --midphase 1,2 --engines persistent --frames 1000 --repeat 5; echo "$b: $(grep -h '^| [a-z]' $R/t5-$b-$i.txt | awk -F'|' '{printf "%s ", $6}')"
done; done
s table5 150 bin/bench_step_paths $T5 --midphase 1,2 --engines graph,small,persistent --frames 1000 --repeat 5; grep "^| [a-z]" $R/table5.txt | cut -d'|' -f2,4,6-8
for i in 1 2 3; do s stack50-$i 60 bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5; grep -h "^| bunny" $R/stack50-$i.txt | cut -d'|' -f2,4,6-8; done
s prof 60 env OCTOCD_CUDA_SMALL_PROFILE=1 OCTOCD_CUDA_PERSISTENT=0 bin/bench_step_paths $M --midphase 1,2 --engines small --frames 1000 --repeat 1; grep -h "fused small step" $R/prof.txt
echo total $SECONDS s
