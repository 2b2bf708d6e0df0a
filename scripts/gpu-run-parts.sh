#!/usr/bin/env bash
# The steps of scripts/gpu-run.sh as parts that resume, for GPU time lent in short calls
# (a batch queue's wall-time limit, a device lent for minutes): each call runs the named
# parts until DEADLINE_S seconds have passed, keeps what OUT already holds, and stops a
# part cut short so that the next call goes on with it. Usage, from the repository:
#   bash scripts/gpu-run-parts.sh BUNDLE_DIR OUT DEADLINE_S PART...
# PART: tests (test_cuda_world), validate (validate --engine cuda on every shipped scene but
# boxes-*, rot-* and bunny-pile-100k/1m, one scene at a time, the finished ones skipped),
# gpubp (bench_gpu_broadphase), or a sweep with bench options: SWEEP[:OPTIONS] (e.g.
# table5:--engines=cpu,cuda), written to OUT/bench/SWEEP.json with --resume; NAME@SWEEP:OPTIONS
# writes OUT/bench/NAME.json instead (a shard: table5-bullet-0@table5:--engines=bullet
# --shard=0/2; scripts/record.py merges NAME-<i>.json shards). A sweep keeps only finished
# points (every repetition runs before a point is stored), so give a sweep or shard a call
# long enough for one round of its points. OUT/parts.log says what each part did.
# scripts/record.sh h100 OUT then writes the record. Exit 0 even when a part fails.
set -u
here=$(cd "${1:?usage: gpu-run-parts.sh BUNDLE_DIR OUT DEADLINE_S PART...}" && pwd)
out=${2:?usage: gpu-run-parts.sh BUNDLE_DIR OUT DEADLINE_S PART...}
deadline=$(( $(date +%s) + ${3:?usage: gpu-run-parts.sh BUNDLE_DIR OUT DEADLINE_S PART...} ))
shift 3
bin=$here/bin
export OCTOCD_SOURCE_DIR=$here OCTOCD_DATA_DIR=$here/datasets/cache OCTOCD_BIN=$here/bin/octocd
mkdir -p "$out/bench"
[ -f "$out/device.txt" ] || { nvidia-smi; nproc; lscpu | grep 'Model name'; } > "$out/device.txt" 2>&1
cp "$here/VERSION" "$out/VERSION" 2>/dev/null || true
left() { echo $(( deadline - $(date +%s) )); }
log() { echo "$*" >> "$out/parts.log"; }
for part in "$@"; do
  [ "$(left)" -gt 10 ] || { log "no time left for $part"; continue; }
  t0=$(date +%s)
  case $part in
    tests)
      [ -f "$out/test_cuda_world.txt" ] && continue
      timeout "$(left)" "$bin/test_cuda_world" > "$out/test_cuda_world.tmp" 2>&1; e=$?
      [ $e -eq 124 ] || mv "$out/test_cuda_world.tmp" "$out/test_cuda_world.txt"
      log "tests: exit $e in $(( $(date +%s) - t0 )) s" ;;
    validate)
      for s in "$here"/datasets/scenes/*.json; do
        n=$(basename "$s" .json)
        case $n in boxes-*|rot-*|bunny-pile-100k|bunny-pile-1m) continue ;; esac
        grep -q "^exit .* for $n\$" "$out/validate-cuda.txt" 2>/dev/null && continue
        f=300; case $n in free-fall|bounce|slide) f=1000 ;; box-stack) f=2000 ;; esac
        timeout "$(left)" "$bin/octocd" validate "$s" --engine cuda --frames $f --every 20 > "$out/validate.tmp" 2>&1; e=$?
        [ $e -eq 124 ] && { log "validate $n: cut short by the deadline"; break; }
        { cat "$out/validate.tmp"; echo "exit $e for $n"; } >> "$out/validate-cuda.txt"
      done
      rm -f "$out/validate.tmp"
      log "validate: $(grep -c '^exit ' "$out/validate-cuda.txt" 2>/dev/null || echo 0) scenes done in $(( $(date +%s) - t0 )) s" ;;
    gpubp)
      [ -f "$out/gpu-broadphase-scaling.json" ] && continue
      timeout "$(left)" "$bin/bench_gpu_broadphase" --json "$out/gpu-broadphase-scaling.json" \
        > "$out/gpu-broadphase-scaling.md" 2> "$out/gpu-broadphase-scaling.log"
      log "gpubp: exit $? in $(( $(date +%s) - t0 )) s" ;;
    *)
      name=${part%%@*}; spec=${part#*@}; sweep=${spec%%:*}; opts=""
      [ "$spec" != "$sweep" ] && opts=${spec#*:}
      [ "$name" = "$part" ] && name=$(basename "$sweep" .json)
      # shellcheck disable=SC2086  # OPTIONS are words
      timeout "$(left)" "$bin/octocd" bench "$sweep" -o "$out/bench/$name.json" --resume --quiet $opts \
        > "$out/bench/$name.log" 2>&1
      log "bench $name: exit $? in $(( $(date +%s) - t0 )) s, load $(cut -d' ' -f1-3 /proc/loadavg)" ;;
  esac
done
cat "$out/parts.log"
