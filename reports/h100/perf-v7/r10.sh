#!/usr/bin/env bash
# r10.sh R: pollers of the resident kernel's request (OCTOCD_CUDA_PERSISTENT_POLLERS):
# test_cuda_world; bunny-stack-50 persistent, 2000 frames x 5, pollers 1 / 2 / 4 / 8
# alternately, three rounds; racecheck and memcheck of a 200-frame resident bunny-stack-50
# run with 4 pollers.
set -u
R=${1:?}; mkdir -p $R
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
nvidia-smi --query-gpu=name,driver_version --format=csv > $R/device.txt 2>&1
s() { local name=$1 t=$2; shift 2; local t0=$SECONDS; timeout $t "$@" > $R/$name.txt 2>&1; echo "$name rc=$? $((SECONDS-t0)) s"; }
S=datasets/scenes
bin/octocd --version > $R/version.txt 2>&1; cat $R/version.txt
s test_cuda_world 200 bin/test_cuda_world; grep -h "PASSED\|FAILED" $R/test_cuda_world.txt | head -4
for i in 1 2 3; do for p in 1 2 4 8; do
  s stack50-p$p-$i 60 env OCTOCD_CUDA_PERSISTENT_POLLERS=$p bin/bench_step_paths $S/bunny-stack-50.json --midphase 1,2 --engines persistent --frames 2000 --repeat 5
  echo "pollers $p: $(grep -h '^| bunny' $R/stack50-p$p-$i.txt | cut -d'|' -f6-8)"
done; done
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
for tool in racecheck memcheck; do
  s san-$tool-stack50-p4 150 env OCTOCD_CUDA_PERSISTENT_POLLERS=4 $CS --tool $tool bin/octocd run $S/bunny-stack-50.json --engine cuda --midphase 1,2 --frames 200 --quiet
  grep -h "ERROR SUMMARY\|RACECHECK SUMMARY" $R/san-$tool-stack50-p4.txt | head -2
done
echo total $SECONDS s
