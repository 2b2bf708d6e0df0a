#!/usr/bin/env bash
# final4.sh R: racecheck where the shared-memory code of the midphase runs: a settled pile's fused leaves
# (graph path, early exit and tile culling on) and the CudaMidphase tests (fused on/off, exit on/off).
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
s racecheck_pile10k 200 env OCTOCD_CUDA_STAGE_TIMES=0 $CS --tool racecheck bin/octocd run $S/bunny-pile-10k.json --engine cuda --frames 30 --quiet; grep -h "SUMMARY" $R/racecheck_pile10k.txt
s memcheck_pile10k 100 env OCTOCD_CUDA_STAGE_TIMES=0 $CS --tool memcheck bin/octocd run $S/bunny-pile-10k.json --engine cuda --frames 30 --quiet; grep -h "SUMMARY" $R/memcheck_pile10k.txt
s racecheck_tcw_midphase 280 env OCTOCD_GPU_TEST_FRAMES=30 $CS --tool racecheck bin/test_cuda_world --gtest_filter='CudaMidphase.*'; grep -h "SUMMARY\|PASSED\|FAILED" $R/racecheck_tcw_midphase.txt | head -5
echo total $SECONDS s
