#!/usr/bin/env bash
# Regenerates one machine's record under reports/<machine>/ (reports/README.md).
#
#   scripts/record.sh cpu [BUILD_DIR]     run here with BUILD_DIR/octocd (default build)
#   scripts/record.sh h100 OUT            convert OUT, a scripts/gpu-run.sh output folder
#                                         (also h200 or any machine name)
#
# cpu: the sweeps of $OCTOCD_RECORD_SWEEPS (default "table5 table6 figA2": about 2 minutes
# of CPU on a 2-core machine; tableA1, broadphase-scaling and max-instances take tens of
# minutes there) with engines cpu,bullet on one OpenMP thread, and `octocd validate`
# (--every 20, 1000 frames; 2000 for box-stack, bunny-stack-50 and the relaxation-pass
# copies tests/data/*-iterations-*.json) on the shipped scenes except the 10^4+ body,
# rotating and mixed-pile-1000 (6 minutes alone) scenes, then scripts/record.py.
# OCTOCD_RECORD_IN=DIR keeps the raw results in DIR instead of a temporary folder: a second
# run goes on where a stopped one ended (sweeps with --resume, finished validations kept),
# and results run apart beforehand (the shards of a long sweep, DIR/bench/NAME-<i>.json)
# join the record.
# The record names the build: $OCTOCD_RECORD_BUILD, else `git describe --always --dirty`.
# Exit 2 on a bad argument, 1 when a step fails.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
machine=${1:-}
[ -n "$machine" ] || { echo "usage: scripts/record.sh cpu [BUILD_DIR] | scripts/record.sh MACHINE GPU_RUN_OUT" >&2; exit 2; }
case "$machine" in *[!a-z0-9-]*|"") echo "record.sh: machine name '$machine': use a-z, 0-9, -" >&2; exit 2 ;; esac
out="$root/reports/$machine"
rev=${OCTOCD_RECORD_BUILD:-$(git -C "$root" describe --always --dirty 2>/dev/null || echo unknown)}

if [ "$machine" = cpu ]; then
  bin="${2:-build}"; case "$bin" in /*) ;; *) bin="$root/$bin" ;; esac; bin="$bin/octocd"
  [ -x "$bin" ] || { echo "record.sh: no octocd at $bin (build it first)" >&2; exit 2; }
  if [ -n "${OCTOCD_RECORD_IN:-}" ]; then
    work=$OCTOCD_RECORD_IN
  else
    work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
  fi
  mkdir -p "$work/bench"
  [ -s "$work/device.txt" ] || { echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
    echo "threads: $(nproc)"; echo "memory: $(free -g | awk '/Mem:/ {print $2}') GiB"
    echo "load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
    echo "os: $(. /etc/os-release && echo "$PRETTY_NAME")"; } > "$work/device.txt"
  for s in ${OCTOCD_RECORD_SWEEPS:-table5 table6 figA2}; do
    echo "record.sh: octocd bench $s"
    OMP_NUM_THREADS=1 "$bin" bench "$s" -o "$work/bench/$s.json" --engines cpu,bullet --quiet --resume
  done
  for f in "$root"/datasets/scenes/*.json "$root"/tests/data/*-iterations-*.json; do
    n=$(basename "$f" .json)
    case "$n" in boxes-*|bunny-pile-*|rot-*|mixed-pile-*) continue ;; esac
    fr=1000; case "$n" in box-stack|bunny-stack-50|*-iterations-*) fr=2000 ;; esac
    [ -s "$work/validate-$n.txt" ] && continue  # finished in an earlier run of OCTOCD_RECORD_IN
    echo "record.sh: octocd validate $n"
    # exit 3 (a validator fails) is a finding to record, not a failure of the record
    OMP_NUM_THREADS=1 "$bin" validate "$f" --frames $fr --every 20 > "$work/validate.tmp" 2>&1 || [ $? -eq 3 ]
    mv "$work/validate.tmp" "$work/validate-$n.txt"
  done
  sed -i "/^load average at end:/d" "$work/device.txt"
  echo "load average at end: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$work/device.txt"
  in=$work
  note="Made on this project's 2-core development VM, shared with other jobs: read orders and ratios where the ranges are apart, not absolute figures (each result records its load average). Sweeps: ${OCTOCD_RECORD_SWEEPS:-table5 table6 figA2}; validate: every shipped scene but the 10^4+ body, rotating and mixed-pile ones, and the relaxation-pass copies of tests/data. Not in this record (tens of minutes each on 2 cores): the sweeps tableA1, broadphase-scaling and max-instances, validate of mixed-pile-1000 (6 minutes) and of the rotating scenes with --engine bullet; add them with OCTOCD_RECORD_SWEEPS on a quiet machine."
else
  in=${2:-}
  [ -n "$in" ] || { echo "usage: scripts/record.sh $machine GPU_RUN_OUT (the folder scripts/gpu-run.sh wrote)" >&2; exit 2; }
  [ -d "$in/bench" ] || { echo "record.sh: $in/bench: no such folder (expected scripts/gpu-run.sh's output)" >&2; exit 2; }
  rev=${OCTOCD_RECORD_BUILD:-$(cat "$in/VERSION" 2>/dev/null || echo "$rev")}
  note="From the output of scripts/gpu-run.sh on the $machine (${in##*/})."
fi
# The generated files are replaced; fuzz.md (written after scripts/fuzz.sh runs) is kept.
keep=$(mktemp -d); [ -f "$out/fuzz.md" ] && cp "$out/fuzz.md" "$keep/"
rm -rf "$out"; mkdir -p "$out"
[ -f "$keep/fuzz.md" ] && cp "$keep/fuzz.md" "$out/"; rm -rf "$keep"
/usr/bin/python3 "$root/scripts/record.py" "$machine" "$in" "$out" --build "$rev" --note "${OCTOCD_RECORD_NOTE:-$note}"
