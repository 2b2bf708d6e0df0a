#!/usr/bin/env bash
# Runs the GPU test suite, validation, compute-sanitizer and the benchmark sweeps on a CUDA
# machine from an extracted bundle (scripts/gpu-bundle.sh). Usage, from the repository:
#   bash scripts/gpu-run.sh BUNDLE_DIR OUTDIR [FRAMES]
# Writes OUTDIR/{device.txt, test_cuda_world.txt, validate-cuda.txt, sanitizer.txt,
# bench/<sweep>.json, gpu-broadphase-scaling.{md,json}}. OCTOCD_SWEEPS picks sweeps, OCTOCD_BENCH_OPTIONS adds bench options
# (e.g. "--repeat 2"). Exit code 0 even when a step fails: read the files.
set -u
here=$(cd "${1:?usage: gpu-run.sh BUNDLE_DIR OUTDIR [FRAMES]}" && pwd)
out=${2:?usage: gpu-run.sh BUNDLE_DIR OUTDIR [FRAMES]}
frames=${3:-1000}
repo=$(cd "$(dirname "$0")/.." && pwd)
bin=$here/bin
export OCTOCD_SOURCE_DIR=$here OCTOCD_DATA_DIR=$here/datasets/cache
mkdir -p "$out"
{ nvidia-smi; nproc; lscpu | grep 'Model name'; } > "$out/device.txt" 2>&1
cp "$here/VERSION" "$out/VERSION" 2>/dev/null || true  # the build the bundle was made from (scripts/record.sh names it)

# 1. The CUDA engine against the CPU engine (state hashes, pairs, contacts, capacity 1).
OCTOCD_GPU_TEST_FRAMES=${OCTOCD_GPU_TEST_FRAMES:-1000} timeout 1200 "$bin/test_cuda_world" > "$out/test_cuda_world.txt" 2>&1

# 2. Every validator on the GPU engine's applied state, every shipped scene.
: > "$out/validate-cuda.txt"
for s in "$here"/datasets/scenes/*.json; do
  n=$(basename "$s" .json)
  case $n in boxes-*|rot-*) continue ;; esac  # rot-*: rotating scenes, --engine bullet only
  f=300; case $n in free-fall|bounce|slide) f=1000 ;; box-stack) f=2000 ;; esac
  timeout 600 "$bin/octocd" validate "$s" --engine cuda --frames $f --every 20 >> "$out/validate-cuda.txt" 2>&1
  echo "exit $? for $n" >> "$out/validate-cuda.txt"
done

# 3. compute-sanitizer on a 200-frame bunny-random-400 run.
: > "$out/sanitizer.txt"
for tool in memcheck racecheck synccheck; do
  echo "== $tool" >> "$out/sanitizer.txt"
  timeout 900 compute-sanitizer --tool $tool --error-exitcode 9 "$bin/octocd" run \
    "$here/datasets/scenes/bunny-random-400.json" --engine cuda --frames 200 --quiet >> "$out/sanitizer.txt" 2>&1
  echo "exit $?" >> "$out/sanitizer.txt"
done

# 4. The benchmark sweeps (docs/bench-format.md): cpu (this machine's CPU, same binary), cuda
#    and bullet side by side. The report is made where matplotlib is:
#    octocd report OUTDIR/bench/*.json -o DIR; scripts/record.sh h100 OUTDIR writes reports/h100/
mkdir -p "$out/bench"
for s in ${OCTOCD_SWEEPS:-table5 table6 tableA1 figA2 broadphase-scaling}; do
  timeout 3000 "$bin/octocd" bench "$s" -o "$out/bench/$s.json" --resume --quiet ${OCTOCD_BENCH_OPTIONS:-} \
    > "$out/bench/$s.log" 2>&1
  echo "exit $? for $s" >> "$out/bench/$s.log"
done

# 5. GPU broadphase scaling (bench_gpu_broadphase, issue 8): 10^4 .. 4x10^6 random boxes,
#    every device broadphase, sorted pair sets checked; the Markdown table and the JSON.
timeout 600 "$bin/bench_gpu_broadphase" --json "$out/gpu-broadphase-scaling.json" \
  > "$out/gpu-broadphase-scaling.md" 2> "$out/gpu-broadphase-scaling.log"
echo "exit $?" >> "$out/gpu-broadphase-scaling.log"
