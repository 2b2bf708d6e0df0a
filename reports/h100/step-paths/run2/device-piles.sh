#!/usr/bin/env bash
# usage: device9.sh BUNDLE_TAR TAG  (the settled piles)
set -u
B=$1; TAG=$2
mkdir -p /tmp/d && { [ -d /tmp/d/octocd-bundle ] || tar xJf $B -C /tmp/d; }
cd /tmp/d/octocd-bundle || exit 9
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
R=/tmp/r-$TAG; mkdir -p $R
s() { local name=$1; shift; local t0=$SECONDS; timeout ${TMO:-150} "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
TMO=150 s pile100k bash -c "OCTOCD_CUDA_STAGE_TIMES=0 bin/octocd run datasets/scenes/bunny-pile-100k.json --engine cuda --frames 3000 --quiet --summary-json $R/pile100k.json"; tail -5 $R/pile100k.txt
TMO=300 s pile1m bash -c "OCTOCD_CUDA_STAGE_TIMES=0 bin/octocd run datasets/scenes/bunny-pile-1m.json --engine cuda --frames 1500 --quiet --summary-json $R/pile1m.json"; tail -5 $R/pile1m.txt
tar cf $OUT/results.tar -C $R .
