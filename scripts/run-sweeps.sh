#!/usr/bin/env bash
# The five named sweeps of `octocd bench` (table5, table6, tableA1, figA2,
# broadphase-scaling) into OUT/<sweep>.json, then `octocd report` into OUT/index.html and
# OUT/report.md. Re-running continues unfinished sweeps (--resume). max-instances and
# speed-accuracy run only when named (minutes per model and engine, an hour on 2 cores);
# their results join the report.
# Usage: scripts/run-sweeps.sh OCTOCD OUT [SWEEPS] [-- extra bench options]
#   e.g. scripts/run-sweeps.sh build/octocd OUT
#        scripts/run-sweeps.sh build/octocd OUT "table5 table6" -- --engines cpu,cuda
set -euo pipefail
octocd=$1; out=$2; shift 2
sweeps="table5 table6 tableA1 figA2 broadphase-scaling"
if [ $# -gt 0 ] && [ "$1" != "--" ]; then sweeps=$1; shift; fi
[ "${1:-}" = "--" ] && shift
mkdir -p "$out"
for s in $sweeps; do
  "$octocd" bench "$s" -o "$out/$s.json" --resume "$@"
done
results=()
for s in table5 table6 tableA1 figA2 broadphase-scaling max-instances speed-accuracy; do
  [ -f "$out/$s.json" ] && results+=("$out/$s.json")
done
"$octocd" report "${results[@]}" -o "$out" --title "octocd benchmarks: $(basename "$(dirname "$out")")"
