#!/usr/bin/env bash
# r8.sh R: the final build: test_cuda_world; the GPU broadphase scaling table of every
# device broadphase (run-gpu-broadphase-bench.sh, the bench's defaults); racecheck of two
# more test_cuda_world tests (san3.sh, both at once, 20 frames, cut at 380 s).
set -u
R=${1:?}; mkdir -p $R
D=$(dirname $(readlink -f $0))
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -4
s scaling 150 ./run-gpu-broadphase-bench.sh $R/scaling; grep -h "^| [a-z]\|identical" $R/scaling/gpu-broadphase-scaling.md | head -30
bash $D/san3.sh $R racecheck $D/racecheck-left3.txt 380 2 20
echo total $SECONDS s
