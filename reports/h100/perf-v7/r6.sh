#!/usr/bin/env bash
# r6.sh R: racecheck (san3.sh: 4 at a time, each cut at 270 s, 20 frames per scene test)
# of eight of the 17 test_cuda_world tests racecheck had not finished (racecheck-left2.txt).
set -u
R=${1:?}; mkdir -p $R
D=$(dirname $(readlink -f $0))
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
bash $D/san3.sh $R racecheck $D/racecheck-left2.txt 270 4 20
echo total $SECONDS s
