#!/usr/bin/env bash
# r9.sh R: compute-sanitizer racecheck of test_cuda_world at 20 frames per scene test
# (san.sh: 8 shards at once), every test but CudaMemory.CliExits* and CudaMidphase.EarlyExit*
# (see r8.sh), then racecheck of a 200-frame asian-dragon-random-60 run on the resident
# small path (the leaf items split both meshes there).
set -u
R=${1:?}; mkdir -p $R
D=$(dirname $(readlink -f $0))
bash $D/san.sh $R racecheck 8 470 20 '-CudaMemory.CliExits*:CudaMidphase.EarlyExit*'
export OCTOCD_DATA_DIR=$PWD/datasets/cache
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
t0=$SECONDS; timeout 80 env OCTOCD_CUDA_STAGE_TIMES=0 $CS --tool racecheck bin/octocd run datasets/scenes/asian-dragon-random-60.json --engine cuda --midphase 1,2 --frames 200 > $R/racecheck-run-asian-resident.txt 2>&1; echo "racecheck-run-asian-resident rc=$? $((SECONDS-t0)) s"
grep -h "SUMMARY\|^steps/s" $R/racecheck-run-asian-resident.txt
echo total $SECONDS s
