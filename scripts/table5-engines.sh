#!/bin/bash
# Steps/s of Bullet, Rapier and Jolt side by side on Table 5's four scenes as rotating copies.
#
#   scripts/table5-engines.sh OCTOCD OUT_DIR [REPEAT] [SCENE...]
#
# Table 5's scenes are translation-only and Bullet rotates only when the scene says so, while
# the process engines always rotate: each scene is copied with "rotation": true into a scratch
# folder (its meshes read from datasets/cache) and run with `octocd bench` as a one-scene sweep
# of the engines bullet, rapier and jolt: 10 untimed frames, then frames 11-110 timed, REPEAT
# repetitions (default 5). One scene at a time, so a scene that finishes is kept when a later
# one is cut short. OUT_DIR receives table5-engines-SCENE.json (octocd-bench results),
# table5-engines.csv (scripts/record.py's rows: each figure as median, min, max, n) and
# table5-engines-machine.txt (the machine and the load average before and after each scene).
# SCENE defaults to the four Table 5 scenes. Exit 0 ok, 1 a bench failed, 2 bad arguments.
set -euo pipefail
if [ $# -lt 2 ]; then
  sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
octocd=$(readlink -f "$1")
out=$2
repeat=${3:-5}
shift $(( $# >= 3 ? 3 : 2 ))
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(bunny-random-400 armadillo-random-250 dragon-random-250 asian-dragon-random-60)
root=$(cd "$(dirname "$0")/.." && pwd)
[ -x "$octocd" ] || { echo "table5-engines.sh: $1 is not an executable" >&2; exit 2; }
mkdir -p "$out"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/scenes"
ln -s "$(readlink -f "$root/datasets/cache")" "$work/cache"
machine="$out/table5-engines-machine.txt"
{
  echo "machine: $(hostname), $(nproc) threads, $(lscpu | sed -n 's/^Model name: *//p' | head -1)"
  echo "octocd: $("$octocd" --version 2>&1 | head -1)"
  echo "repeat: $repeat, frames 11-110 timed (warmup 10, frames 100), OMP_NUM_THREADS=1"
} > "$machine"
status=0
for s in "${scenes[@]}"; do
  python3 - "$root/datasets/scenes/$s.json" "$work/scenes/$s.json" <<'PY'
import json, sys
scene = json.load(open(sys.argv[1]))
scene["rotation"] = True
json.dump(scene, open(sys.argv[2], "w"), indent=1)
PY
  cat > "$work/sweep-$s.json" <<JSON
{"name": "table5-engines", "kind": "steps",
 "description": "Table 5's scene $s as a rotating copy: Bullet, Rapier and Jolt side by side (scripts/table5-engines.sh).",
 "scenes": ["$s"], "engines": ["bullet", "rapier", "jolt"], "warmup": 10, "frames": 100, "repeat": $repeat}
JSON
  echo "$s: start $(date -u +%FT%TZ), load average $(cut -d' ' -f1-3 /proc/loadavg)" >> "$machine"
  if ! OMP_NUM_THREADS=1 "$octocd" bench "$work/sweep-$s.json" --scene-dir "$work/scenes" \
      -o "$out/table5-engines-$s.json"; then
    status=1
  fi
  echo "$s: end $(date -u +%FT%TZ), load average $(cut -d' ' -f1-3 /proc/loadavg)" >> "$machine"
  python3 - "$root/scripts" "$out" <<'PY'
import glob, os, sys
sys.path.insert(0, sys.argv[1])
import record
rows = []
for path in sorted(glob.glob(os.path.join(sys.argv[2], "table5-engines-*.json"))):
    rows += record.bench_rows(record.load_json(path))
record.write_csv(os.path.join(sys.argv[2], "table5-engines.csv"), rows)
PY
done
exit $status
