#!/usr/bin/env bash
# ctest install.consumer (issue 11): installs octocd into BUILD/_install, configures and
# builds examples/consumer against that tree (find_package(octocd)), runs it and expects
# the verdict its toy engine earns: exit 3, candidate-sets naming the missed touching pair.
# Usage: consumer.sh CMAKE GENERATOR BUILD_DIR SOURCE_DIR
set -euo pipefail
cmake_bin=$1 generator=$2 build=$3 src=$4
prefix="$build/_install"
rm -rf "$prefix" "$build/_consumer"
"$cmake_bin" --install "$build" --prefix "$prefix" >/dev/null
for f in lib/cmake/octocd/octocdConfig.cmake lib/cmake/octocd/octocdConfigVersion.cmake \
         include/octocd/external.hpp include/octocd/engine.hpp lib/liboctocd_validation.a; do
  [ -e "$prefix/$f" ] || { echo "not installed: $prefix/$f"; exit 1; }
done
"$cmake_bin" -S "$src/examples/consumer" -B "$build/_consumer" -G "$generator" \
  -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_BUILD_TYPE=Release >/dev/null
"$cmake_bin" --build "$build/_consumer"
set +e
out=$("$build/_consumer/judge_frame")
rc=$?
set -e
echo "$out"
[ "$rc" -eq 3 ] || { echo "judge_frame exited $rc, expected 3"; exit 1; }
grep -q "engine 'toy-strict' misses pair (0, 1)" <<<"$out" || { echo "no missed pair (0, 1) in the verdicts"; exit 1; }
grep -q "overlap is inclusive" <<<"$out" || { echo "no hint on the inclusive overlap"; exit 1; }
echo "install.consumer: ok"
