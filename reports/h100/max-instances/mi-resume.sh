#!/usr/bin/env bash
# mi.sh R: resume the dragon (shard 2/4) and asian-dragon (3/4) max-instances searches of reports/h100/max-instances/raw (bundle 355a0a9)
set -u
R=${1:?}; mkdir -p $R
REPO=$(dirname $(dirname $(readlink -f $0)))
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
for m in 3:asian-dragon 2:dragon; do
  sh=${m%%:*}; name=${m#*:}
  cp $REPO/reports/h100/max-instances/raw/max-instances-cuda-$name.json $R/
  t0=$SECONDS
  timeout ${TMO:-280} bin/octocd bench max-instances --engines cuda --shard $sh/4 --resolution 0.25 --search-time 220 --max-instances 4194304 -o $R/max-instances-cuda-$name.json --resume > $R/max-instances-cuda-$name.resume.log 2>&1
  echo "$name rc=$? $((SECONDS-t0)) s"; tail -4 $R/max-instances-cuda-$name.resume.log
done
