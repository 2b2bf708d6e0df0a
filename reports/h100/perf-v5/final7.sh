#!/usr/bin/env bash
# final7.sh R: compute-sanitizer memcheck of the whole test_cuda_world, 20 frames per scene test (OCTOCD_GPU_TEST_FRAMES=20)
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
t0=$SECONDS; OCTOCD_GPU_TEST_FRAMES=20 timeout 530 $CS --tool memcheck bin/test_cuda_world > $R/memcheck_tcw.txt 2>&1; echo "memcheck_tcw rc=$? $((SECONDS-t0)) s"
grep -c "^\[       OK \]" $R/memcheck_tcw.txt; grep -h "SUMMARY\|PASSED\|FAILED\|Invalid" $R/memcheck_tcw.txt | head -8; tail -3 $R/memcheck_tcw.txt
