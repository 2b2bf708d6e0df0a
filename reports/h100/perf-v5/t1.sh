#!/usr/bin/env bash
# t1.sh R: the GPU tests
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
for t in test_cuda_world test_device_broadphase; do
  t0=$SECONDS; timeout 300 bin/$t > $R/$t.txt 2>&1; echo "$t rc=$? $((SECONDS-t0)) s"; grep -h "PASSED\|FAILED\|tests ran" $R/$t.txt | head -12
done
