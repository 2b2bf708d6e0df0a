#!/usr/bin/env bash
# r3.sh R: the leaf items split both meshes (kLeafChunk of B x kLeafAPart of A): GPU tests,
# Table 5 with [1,2] (persistent, 1000 frames, 5 reps) for the bundle's default (128 x 1024)
# and the variant builds carried in .bundle-x/v.tar.xz (bsp_cC_aP), two rounds; the small
# path's phase profile of the mesh scenes.
set -u
R=${1:?}; mkdir -p $R
X=${X:?}  # folder of the variant binaries
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
M="$S/armadillo-random-250.json $S/dragon-random-250.json $S/asian-dragon-random-60.json"
T5="$S/bunny-random-400.json $M"
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED\|tile filter" $R/test_cuda_world.txt | head -8
tar xJf $X/v.tar.xz -C bin --strip-components=1
for i in 1 2; do for b in bench_step_paths bsp_c64_a1024 bsp_c128_a512 bsp_c64_a512 bsp_c256_a1024; do
  s t5-$b-$i 120 bin/$b $T5 --midphase 1,2 --engines persistent --frames 1000 --repeat 5; grep -h "^| [a-z]" $R/t5-$b-$i.txt | cut -d'|' -f2,6-8
done; done
s prof 60 env OCTOCD_CUDA_SMALL_PROFILE=1 OCTOCD_CUDA_PERSISTENT=0 bin/bench_step_paths $M --midphase 1,2 --engines small --frames 1000 --repeat 1; grep -h "fused small step" $R/prof.txt
NCU=$(command -v ncu || echo /usr/local/cuda/bin/ncu)
for n in 1e6 4e6; do
  s ncu-octree-$n 200 $NCU --section SpeedOfLight --section LaunchStats --section Occupancy bin/bench_gpu_broadphase --only octree --sizes $n --reps 1 --warmup 0 --oracle-max 0
  grep -h "^  [a-zA-Z_:<>(), 0-9]*(.*)x(.*)\|Duration" $R/ncu-octree-$n.txt | paste - - | sed 's/  */ /g' | cut -c1-160 | head -30
done
echo total $SECONDS s
