#!/usr/bin/env bash
# r7.sh R: compute-sanitizer memcheck of the whole test_cuda_world (san.sh: 8 shards at once,
# the tests' own 200 frames per scene test), then memcheck and racecheck of a 200-frame
# bunny-random-400 run on the resident small path and on the graph path.
set -u
R=${1:?}; mkdir -p $R
D=$(dirname $(readlink -f $0))
bash $D/san.sh $R memcheck 8 420
export OCTOCD_DATA_DIR=$PWD/datasets/cache
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
for p in "resident OCTOCD_CUDA_STAGE_TIMES=0" "graph OCTOCD_CUDA_SMALL=0"; do set -- $p; n=$1; shift
  for tool in memcheck racecheck; do
    s $tool-run-$n 150 env "$@" $CS --tool $tool bin/octocd run $S/bunny-random-400.json --engine cuda --midphase 1,2 --frames 200; grep -h "SUMMARY\|^steps/s" $R/$tool-run-$n.txt | head -3
  done
done
echo total $SECONDS s
