#!/usr/bin/env bash
# gpu-bundle.sh: build octocd with the CUDA engine here and pack it, with every
# non-glibc shared library it needs, for a GPU machine that has only a CUDA driver.
#
# Usage (on the build machine, from anywhere in the repository):
#   scripts/gpu-bundle.sh [--build-dir DIR] [--out DIR] [--jobs N] [--no-build]
#     --build-dir DIR  build tree (default: build-cuda-release), configured here as
#                      Release with -DOCTOCD_CUDA=ON if it is not yet; then built (all
#                      targets: octocd, the gtest binaries, the bench programs)
#     --out DIR        bundle folder (default: .bundle, listed in .git/info/exclude)
#     --jobs N         parallel build jobs (default: 2)
#     --no-build       pack what the build tree already holds
#   Result: OUT/octocd-bundle/ and OUT/octocd-bundle.tar.xz (its size is printed).
#   OCTOCD_BUNDLE_XZ_LEVEL=1 compresses faster (default 9: smallest).
#
# On the GPU machine (Ubuntu 24.04 or any glibc >= the build machine's, x86-64, a CUDA 13
# driver; no Bullet, FCL, assimp or HDF5 needed):
#   tar xJf octocd-bundle.tar.xz && cd octocd-bundle
#   ./run-gpu-tests.sh                    # tests/gpu: cuda vs cpu on every shipped scene
#   OCTOCD_GPU_TEST_FRAMES=1000 ./run-gpu-tests.sh --gtest_filter='*CpuVsCuda*'
#   ./bin/octocd run datasets/scenes/bunny-random-400.json ...
#   ./run-tests.sh                        # every gtest binary (CPU tests too)
#   ./run-gpu-broadphase-bench.sh [OUTDIR] # bench_gpu_broadphase:
#                                          # OUTDIR/gpu-broadphase-scaling.{md,json}
#
# Layout: bin/ (octocd, test_*, bench_*, bench_gpu_broadphase among them; RPATH
# $ORIGIN/lib), bin/lib/ (shared libraries, RPATH $ORIGIN), datasets/scenes, datasets/cache,
# tests/data, bench/sweeps and the batched-worlds benchmark (bench/run-worlds.sh);
# everything stripped. The CUDA runtime is linked statically; libcuda comes from the
# driver. glibc (libc, libm, libpthread, libdl, librt, libresolv, ld-linux, ...) is the
# target's own.
set -euo pipefail

repo=$(git -C "$(dirname "$0")" rev-parse --show-toplevel)
build_dir=build-cuda-release
out_dir=.bundle
jobs=2
do_build=1
while [[ $# -gt 0 ]]; do
  case "$1" in
    --build-dir) build_dir=$2; shift 2 ;;
    --out) out_dir=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    --no-build) do_build=0; shift ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d'; exit 0 ;;
    *) echo "gpu-bundle.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
cd "$repo"
[[ "$build_dir" = /* ]] || build_dir="$repo/$build_dir"
[[ "$out_dir" = /* ]] || out_dir="$repo/$out_dir"

# The bundle folder stays out of git.
git_dir=$(git rev-parse --git-dir)
mkdir -p "$git_dir/info"
rel_out=${out_dir#"$repo"/}
if [[ "$rel_out" != /* ]] && ! grep -qxF "/$rel_out/" "$git_dir/info/exclude" 2>/dev/null \
   && ! grep -qxF "$rel_out/" "$git_dir/info/exclude" 2>/dev/null; then
  echo "$rel_out/" >> "$git_dir/info/exclude"
fi

for tool in patchelf strip xz ldd; do
  if ! command -v "$tool" >/dev/null; then
    if [[ "$tool" = patchelf ]] && command -v apt-get >/dev/null; then
      echo "gpu-bundle.sh: installing patchelf" >&2
      apt-get install -y patchelf >/dev/null || { apt-get update >/dev/null && apt-get install -y patchelf >/dev/null; }
    else
      echo "gpu-bundle.sh: '$tool' is needed" >&2; exit 1
    fi
  fi
done

# ---- build --------------------------------------------------------------------------
if [[ $do_build = 1 ]]; then
  if [[ ! -f "$build_dir/CMakeCache.txt" ]]; then
    cmake -S "$repo" -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DOCTOCD_CUDA=ON
  fi
  if grep -q '^OCTOCD_CUDA:STRING=OFF' "$build_dir/CMakeCache.txt"; then
    echo "gpu-bundle.sh: $build_dir is configured with OCTOCD_CUDA=OFF (reconfigure with -DOCTOCD_CUDA=ON)" >&2
    exit 1
  fi
  cmake --build "$build_dir" -j"$jobs"
fi
for needed in tests/test_cuda_world bench_gpu_broadphase; do
  [[ -x "$build_dir/$needed" ]] || {
    echo "gpu-bundle.sh: $build_dir/$needed is missing (a build with OCTOCD_CUDA=ON?)" >&2; exit 1; }
done

# ---- collect ------------------------------------------------------------------------
name=octocd-bundle
stage="$out_dir/$name"
rm -rf "$stage" "$out_dir/$name.tar.xz"
mkdir -p "$stage/bin/lib" "$stage/datasets" "$stage/tests"

binaries=("$build_dir/octocd")
while IFS= read -r f; do binaries+=("$f"); done < <(
  find "$build_dir/tests" "$build_dir" -maxdepth 1 -type f -perm -u+x \( -name 'test_*' -o -name 'bench_*' \) | sort -u)
for f in "${binaries[@]}"; do cp "$f" "$stage/bin/"; done

# Shared libraries: everything ldd resolves except glibc's own and the driver's libcuda.
is_system_lib() {
  case "$1" in
    libc.so*|libm.so*|libmvec.so*|libpthread.so*|libdl.so*|librt.so*|libresolv.so*|libutil.so*|\
    libanl.so*|libnsl.so*|libnss_*|libBrokenLocale.so*|libthread_db.so*|libc_malloc_debug.so*|\
    ld-linux*|linux-vdso*|libcuda.so*|libnvidia-*) return 0 ;;
  esac
  return 1
}
declare -A libs=()
for f in "${binaries[@]}"; do
  if ldd "$f" | grep -q 'not found'; then
    echo "gpu-bundle.sh: $f has unresolved libraries:" >&2; ldd "$f" | grep 'not found' >&2; exit 1
  fi
  while read -r soname path; do
    is_system_lib "$soname" && continue
    libs[$soname]=$path
  done < <(ldd "$f" | awk '$2 == "=>" && $3 ~ /^\// {print $1, $3}')
done
for soname in "${!libs[@]}"; do cp -L "${libs[$soname]}" "$stage/bin/lib/$soname"; done

# Strip, then set RPATH (DT_RPATH, so it also serves the libraries' own dependencies).
for f in "$stage"/bin/*; do
  [[ -f "$f" ]] || continue
  strip --strip-unneeded "$f"
  patchelf --force-rpath --set-rpath '$ORIGIN/lib' "$f"
done
for f in "$stage"/bin/lib/*; do
  chmod u+w "$f"
  strip --strip-unneeded "$f"
  patchelf --force-rpath --set-rpath '$ORIGIN' "$f"
done

# Data: scenes, the fetched meshes, the test data.
cp -r "$repo/datasets/scenes" "$stage/datasets/"
if [[ -d "$repo/datasets/cache" ]]; then
  mkdir -p "$stage/datasets/cache"
  find -L "$repo/datasets/cache" -maxdepth 1 -type f -exec cp {} "$stage/datasets/cache/" \;
else
  echo "gpu-bundle.sh: warning: datasets/cache is missing (run datasets/fetch.sh): mesh scenes will not load" >&2
fi
cp -r "$repo/tests/data" "$stage/tests/"
mkdir -p "$stage/bench" && cp -r "$repo/bench/sweeps" "$stage/bench/"  # the named sweeps of octocd bench
# The batched-worlds benchmark (docs/gpu.md, "Batched worlds"): ./bench/run-worlds.sh bin/octocd OUT
cp "$repo/bench/run-worlds.sh" "$repo/bench/hand_built_worlds.py" "$repo/bench/worlds_table.py" "$stage/bench/"

cat > "$stage/run-gpu-tests.sh" <<'EOF'
#!/usr/bin/env bash
# The CUDA engine's tests (tests/gpu/test_cuda_world.cpp): cuda vs cpu, bit for bit, on
# every shipped scene; GPU rerun determinism; buffers starting at capacity 1.
# Extra arguments go to the gtest binary (e.g. --gtest_filter=...).
# OCTOCD_GPU_TEST_FRAMES sets the frames per scene (default 200).
here=$(cd "$(dirname "$0")" && pwd)
export OCTOCD_SOURCE_DIR="$here" OCTOCD_BIN="$here/bin/octocd"
command -v nvidia-smi >/dev/null && nvidia-smi -L
exec "$here/bin/test_cuda_world" "$@"
EOF
cat > "$stage/run-tests.sh" <<'EOF'
#!/usr/bin/env bash
# Every gtest binary of the bundle, one after the other; exit status 1 if any failed.
here=$(cd "$(dirname "$0")" && pwd)
export OCTOCD_SOURCE_DIR="$here" OCTOCD_BIN="$here/bin/octocd"
status=0
for t in "$here"/bin/test_*; do
  echo "==== $(basename "$t")"
  "$t" "$@" || status=1
done
exit $status
EOF
cat > "$stage/run-gpu-broadphase-bench.sh" <<'EOF'
#!/usr/bin/env bash
# GPU broadphase scaling (bench/bench_gpu_broadphase.cpp, issue 8): the device broadphases
# on identical random boxes, 10^4 .. 4x10^6 bodies, sorted pair sets checked against each
# other and the CPU oracle. Usage: ./run-gpu-broadphase-bench.sh [OUTDIR] [bench options]
# Writes OUTDIR/gpu-broadphase-scaling.md (the Markdown table) and .json (default OUTDIR:
# results); the exit status is the bench's (3: a pair set differs).
here=$(cd "$(dirname "$0")" && pwd)
out=results
if [[ $# -gt 0 && "$1" != -* ]]; then out=$1; shift; fi
mkdir -p "$out"
command -v nvidia-smi >/dev/null && nvidia-smi -L
"$here/bin/bench_gpu_broadphase" --json "$out/gpu-broadphase-scaling.json" "$@" > "$out/gpu-broadphase-scaling.md"
status=$?
cat "$out/gpu-broadphase-scaling.md"
exit $status
EOF
chmod +x "$stage/run-gpu-tests.sh" "$stage/run-tests.sh" "$stage/run-gpu-broadphase-bench.sh"
git -C "$repo" describe --always --dirty --tags > "$stage/VERSION" 2>/dev/null || echo unknown > "$stage/VERSION"

# Every binary must resolve all its libraries from the bundle alone.
for f in "$stage"/bin/*; do
  [[ -f "$f" ]] || continue
  missing=$(env -u LD_LIBRARY_PATH ldd "$f" | awk '$2 == "=>" && $3 !~ /^\// {print $1}' | while read -r s; do
    is_system_lib "$s" || echo "$s"; done)
  if [[ -n "$missing" ]]; then echo "gpu-bundle.sh: $f misses: $missing" >&2; exit 1; fi
  outside=$(env -u LD_LIBRARY_PATH ldd "$f" | awk '$2 == "=>" && $3 ~ /^\// {print $1, $3}' | while read -r s p; do
    is_system_lib "$s" || [[ "$p" == "$stage/bin/lib/"* ]] || echo "$s ($p)"; done)
  if [[ -n "$outside" ]]; then echo "gpu-bundle.sh: $f loads from outside the bundle: $outside" >&2; exit 1; fi
done

# ---- compress -----------------------------------------------------------------------
tar -C "$out_dir" -cf - "$name" | xz -T0 "-${OCTOCD_BUNDLE_XZ_LEVEL:-9}" > "$out_dir/$name.tar.xz"
echo "bundle: $out_dir/$name.tar.xz ($(du -h "$out_dir/$name.tar.xz" | cut -f1)," \
     "$(stat -c %s "$out_dir/$name.tar.xz") bytes; ${#binaries[@]} programs, ${#libs[@]} libraries)"
echo "on the GPU machine: tar xJf $name.tar.xz && cd $name && ./run-gpu-tests.sh"
