#!/usr/bin/env bash
set -u
mkdir -p /tmp/d && tar xJf .bundle/small/octocd-bundle.tar.xz -C /tmp/d
cd /tmp/d/octocd-bundle || exit 9
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache
R=/tmp/r7; mkdir -p $R
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
t0=$SECONDS; timeout 200 ./bin/test_cuda_world --gtest_filter='CudaSmallStep.*:CudaDevice.*:CudaVariants.*:*_small*' > $R/test_cuda_world_small.txt 2>&1; echo "small tests rc=$? $((SECONDS-t0)) s"
grep -h "PASSED\|FAILED\|Failure" $R/test_cuda_world_small.txt | head -20
t0=$SECONDS; OMP_NUM_THREADS=16 timeout 150 ./bin/bench_step_paths datasets/scenes/bunny-stack-50.json --midphase 1,2 --small-blocks 33,66,132,264 --frames 2000 --repeat 5 > $R/bench_stack50.txt 2>&1; echo "bench stack rc=$? $((SECONDS-t0)) s"; cat $R/bench_stack50.txt | tail -12
t0=$SECONDS; OMP_NUM_THREADS=16 timeout 150 ./bin/bench_step_paths datasets/scenes/bunny-random-400.json datasets/scenes/armadillo-random-250.json datasets/scenes/dragon-random-250.json datasets/scenes/asian-dragon-random-60.json --midphase 1,2 --frames 1000 --repeat 5 > $R/bench_table5.txt 2>&1; echo "bench t5 rc=$? $((SECONDS-t0)) s"; tail -16 $R/bench_table5.txt
t0=$SECONDS; timeout 200 ./bin/test_cuda_world > $R/test_cuda_world_all.txt 2>&1; echo "all tests rc=$? $((SECONDS-t0)) s"; grep -h "PASSED\|FAILED" $R/test_cuda_world_all.txt | head
t0=$SECONDS; OCTOCD_CUDA_SMALL=1 timeout 120 compute-sanitizer --tool memcheck ./bin/test_cuda_world --gtest_filter='CudaSmallStep.AnyGrid*' > $R/memcheck_small.txt 2>&1; echo "memcheck rc=$? $((SECONDS-t0)) s"; grep -h "SUMMARY" $R/memcheck_small.txt
tar cf $OUT/results.tar -C $R .
