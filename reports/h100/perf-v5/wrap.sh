#!/usr/bin/env bash
# usage: wrap.sh BUNDLE_TAR SCRIPT TAG  : extract the bundle (once per bundle path), run SCRIPT R from inside it, return R
B=$1; S=$2; TAG=$3
D=/tmp/d-$(echo $B | md5sum | cut -c1-8)
mkdir -p $D && { [ -d $D/octocd-bundle ] || tar xJf $B -C $D; }
R=/tmp/r-$TAG; mkdir -p $R
SP=$(readlink -f $S)
cd $D/octocd-bundle || exit 9
cat VERSION > $R/VERSION 2>/dev/null
bash $SP $R
tar cf $OUT/results.tar -C $R .
