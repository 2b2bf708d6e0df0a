#!/usr/bin/env bash
# dbp.sh R: which engine faults with the sorted octree (bplead = main + bpscale)
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
CS=$(command -v compute-sanitizer || ls /usr/local/cuda/bin/compute-sanitizer)
for w in oct tiny2 tiny; do
  DIAG_ENGINE=$w timeout 60 bin/test_cuda_world --gtest_filter='CudaOctreeDiag.*' > $R/diag-$w.txt 2>&1; echo "$w rc=$?"; grep -c "\[diag\]" $R/diag-$w.txt; grep -m3 -i "error\|fail" $R/diag-$w.txt
done
DIAG_ENGINE=tiny timeout 120 $CS --tool memcheck bin/test_cuda_world --gtest_filter='CudaOctreeDiag.*' > $R/memcheck-tiny.txt 2>&1; echo "memcheck tiny rc=$?"; grep -m12 "Invalid\|at \|by thread\|\[diag\]" $R/memcheck-tiny.txt | tail -12
timeout 120 bin/test_device_broadphase > $R/tdb.txt 2>&1; echo "tdb rc=$?"; tail -3 $R/tdb.txt
timeout 200 bin/test_cuda_world --gtest_filter='*CudaOctree.*:*CudaRerun*' > $R/tcw.txt 2>&1; echo "tcw rc=$?"; grep "PASSED\|FAILED" $R/tcw.txt | head
