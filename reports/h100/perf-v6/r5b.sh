#!/usr/bin/env bash
# r5b.sh R: B's leaf chunk kLeafChunk x ceil(A's parts / 2), append_chunks as append where
# every lane has at most one copy: GPU tests; Table 5 with [1,2] (persistent, 1000 frames,
# 5 reps, two rounds; every path once); bunny-stack-50 (2000 frames, 5 reps) five runs each,
# alternating with bench_step_paths built from bdac61d (the tile filter alone; in
# .bundle-x/v.tar.xz as bsp_bdac61d).
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
tar xJf $X/v.tar.xz -C bin --strip-components=1
for i in 1 2; do s t5-$i 120 bin/bench_step_paths $T5 --midphase 1,2 --engines persistent --frames 1000 --repeat 5; grep "^| [a-z]" $R/t5-$i.txt | cut -d'|' -f2,4,6-8; done
s table5 150 bin/bench_step_paths $T5 --midphase 1,2 --engines graph,small,persistent --frames 1000 --repeat 5; grep "^| [a-z]" $R/table5.txt | cut -d'|' -f2,4,6-8
for i in 1 2 3 4 5; do for b in bench_step_paths bsp_bdac61d; do
  s stack50-$b-$i 60 bin/$b $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5; echo "$b: $(grep -h '^| bunny' $R/stack50-$b-$i.txt | cut -d'|' -f6-8)"
done; done
s prof 60 env OCTOCD_CUDA_SMALL_PROFILE=1 OCTOCD_CUDA_PERSISTENT=0 bin/bench_step_paths $M --midphase 1,2 --engines small --frames 1000 --repeat 1; grep -h "fused small step" $R/prof.txt
echo total $SECONDS s
