#!/usr/bin/env bash
# ctest install.consumer (issues 11, 17): installs octocd into BUILD/_install, configures and
# builds examples/consumer against that tree (find_package(octocd)), runs it and expects
# the verdicts of its two engines: the toy engine's strict overlap test misses the
# touching pair (exit 3, candidate-sets naming it); the rotating engine's frame (two
# rotated boxes with orientations, angular velocities and a manifold) is judged, every row
# with its tier.
# Then the same with CUDA hidden (issue 17): no nvcc on PATH, CUDAToolkit_ROOT pointing
# nowhere, find_package(CUDAToolkit) disabled. The package must configure, build and run
# for such a CPU-only consumer. Where this build has no CUDA engine the package is made to
# look like one that has it (OCTOCD_BUILT_WITH_CUDA ON, a CUDA targets file that must not
# be loaded), so the test judges the CUDA branch of octocdConfig.cmake on any machine.
# Usage: consumer.sh CMAKE GENERATOR BUILD_DIR SOURCE_DIR
set -euo pipefail
cmake_bin=$1 generator=$2 build=$3 src=$4
prefix="$build/_install"
rm -rf "$prefix" "$build/_consumer" "$build/_install_cpu_only" "$build/_consumer_cpu_only"
"$cmake_bin" --install "$build" --prefix "$prefix" >/dev/null
for f in lib/cmake/octocd/octocdConfig.cmake lib/cmake/octocd/octocdConfigVersion.cmake \
         include/octocd/external.hpp include/octocd/engine.hpp include/octocd/pose.hpp \
         include/octocd/physics.hpp lib/liboctocd_validation.a include/octocd/results_table.hpp \
         lib/liboctocd_harness.a; do
  [ -e "$prefix/$f" ] || { echo "not installed: $prefix/$f"; exit 1; }
done

# Builds examples/consumer against PREFIX into DIR (extra cmake arguments after) and
# checks judge_frame's verdicts.
consume() {
  local pfx=$1 dir=$2
  shift 2
  "$cmake_bin" -S "$src/examples/consumer" -B "$dir" -G "$generator" \
    -DCMAKE_PREFIX_PATH="$pfx" -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
  "$cmake_bin" --build "$dir"
  set +e
  out=$("$dir/judge_frame")
  rc=$?
  set -e
  echo "$out"
  [ "$rc" -eq 3 ] || { echo "judge_frame exited $rc, expected 3"; exit 1; }
  grep -q "engine 'toy-strict' declares an exact AABB broadphase but misses pair (0, 1)" <<<"$out" || { echo "no missed pair (0, 1) in the verdicts"; exit 1; }
  grep -q "overlap is inclusive" <<<"$out" || { echo "no hint on the inclusive overlap"; exit 1; }
  grep -q "^rotating engine 'spinner'" <<<"$out" || { echo "the rotating engine's frame was not judged"; exit 1; }
  # Every row of its table names its tier.
  rows=$(sed -n "/^rotating engine 'spinner'/,\$p" <<<"$out" | grep -cE "^(physics|model) ") || true
  [ "$rows" -ge 6 ] || { echo "the rotating engine's table has $rows rows with a tier, expected >= 6"; exit 1; }
}
consume "$prefix" "$build/_consumer"

# CUDA hidden.
cpu_prefix="$build/_install_cpu_only"
cp -r "$prefix" "$cpu_prefix"
config="$cpu_prefix/lib/cmake/octocd/octocdConfig.cmake"
if grep -q "set(OCTOCD_BUILT_WITH_CUDA OFF)" "$config"; then
  sed -i "s/set(OCTOCD_BUILT_WITH_CUDA OFF)/set(OCTOCD_BUILT_WITH_CUDA ON)/" "$config"
  echo 'message(FATAL_ERROR "octocdCudaTargets.cmake loaded without the CUDA toolkit")' \
    >"$cpu_prefix/lib/cmake/octocd/octocdCudaTargets.cmake"
fi
grep -q "set(OCTOCD_BUILT_WITH_CUDA ON)" "$config" || { echo "octocdConfig.cmake: no OCTOCD_BUILT_WITH_CUDA"; exit 1; }
no_nvcc_path=$(tr ':' '\n' <<<"$PATH" | while read -r d; do [ -x "$d/nvcc" ] || printf '%s:' "$d"; done)
PATH="${no_nvcc_path%:}" CUDAToolkit_ROOT=/nonexistent/cuda CUDA_PATH=/nonexistent/cuda CUDACXX= \
  consume "$cpu_prefix" "$build/_consumer_cpu_only" -DCMAKE_DISABLE_FIND_PACKAGE_CUDAToolkit=ON \
    -DCUDAToolkit_ROOT=/nonexistent/cuda
# Asking for the CUDA engine there must fail with the reason, not silently.
set +e
msg=$(PATH="${no_nvcc_path%:}" "$cmake_bin" -S "$src/examples/consumer" -B "$build/_consumer_cpu_only_cuda" \
  -G "$generator" -DCMAKE_PREFIX_PATH="$cpu_prefix" -DCMAKE_DISABLE_FIND_PACKAGE_CUDAToolkit=ON \
  -DOCTOCD_CONSUMER_NEEDS_CUDA=ON 2>&1)
rc=$?
set -e
rm -rf "$build/_consumer_cpu_only_cuda"
[ "$rc" -ne 0 ] || { echo "find_package(octocd COMPONENTS cuda) succeeded without the CUDA toolkit"; exit 1; }
grep -q "needs the CUDA toolkit" <<<"$msg" || { echo "no reason given:"; echo "$msg"; exit 1; }
echo "install.consumer: ok (also with CUDA hidden)"
