#!/usr/bin/env bash
# r9.sh R: the final build (02971e3): GPU tests; memcheck and racecheck of a 200-frame
# bunny-random-400 run on the graph path (its device octree, depth 2, with the occupancy map)
# and memcheck of a 30-frame boxes-random-10000 run with the thread query forced (the map and
# bp::PairBuffer); the octree and lbvh once more.
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
bin/octocd --version > $R/version.txt 2>&1; cat $R/version.txt
s test_device_broadphase 150 bin/test_device_broadphase; grep -h "PASSED\|FAILED" $R/test_device_broadphase.txt | head -4
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -4
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
for tool in memcheck racecheck; do
  s san-$tool-bunny400-graph 150 env OCTOCD_CUDA_SMALL=0 $CS --tool $tool bin/octocd run $S/bunny-random-400.json --engine cuda --midphase 1,2 --frames 200 --quiet
  grep -h "ERROR SUMMARY\|RACECHECK SUMMARY" $R/san-$tool-bunny400-graph.txt | head -2
done
s san-memcheck-boxes10k-thread 150 env OCTOCD_CUDA_OCTREE_QUERY=thread $CS --tool memcheck bin/octocd run $S/boxes-random-10000.json --engine cuda --frames 30 --quiet
grep -h "ERROR SUMMARY" $R/san-memcheck-boxes10k-thread.txt | head -2
s bp 100 bin/bench_gpu_broadphase --only octree,lbvh --sizes 1e4,1e5,1e6,4e6 --reps 10 --warmup 3 --oracle-max 0 --json $R/bp.json
grep -h "^| octree\|^| lbvh" $R/bp.txt | head -8
echo total $SECONDS s
