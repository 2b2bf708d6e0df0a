#!/usr/bin/env bash
# Regenerates reports/cpu/validate-*.txt: `octocd validate` with default tolerances on the
# shipped scenes (1000 frames; box-stack, bunny-stack-50 and mixed-pile-1000: 2000) and on
# the relaxation-pass copies of tests/data (2000 frames, issue 18), checks every 20 frames,
# against Bullet and FCL. Each file ends with the run's wall and CPU time.
# Usage: reports/cpu/validate-all.sh [BUILD_DIR] [SCENE_NAME ...]
set -u
build=${1:-build}
shift || true
root=$(cd "$(dirname "$0")/../.." && pwd)
out="$root/reports/cpu"
declare -A frames=([box-stack]=2000 [bunny-stack-50]=2000 [mixed-pile-1000]=2000)
scenes=("$@")
if [ ${#scenes[@]} -eq 0 ]; then
  for f in "$root"/datasets/scenes/*.json; do
    n=$(basename "$f" .json)
    case "$n" in boxes-*|bunny-pile-*|rot-*) continue ;; esac  # scale scenes (bench) and rotating ones (--engine bullet)
    scenes+=("$n")
  done
  for f in "$root"/tests/data/*-iterations-*.json; do scenes+=("$(basename "$f" .json)"); done
fi
for n in "${scenes[@]}"; do
  file="$root/datasets/scenes/$n.json"
  [ -f "$file" ] || file="$root/tests/data/$n.json"
  fr=${frames[$n]:-1000}
  case "$n" in *-iterations-*) fr=2000 ;; esac
  TIMEFORMAT='%R %U %S'
  { time "$root/$build/octocd" validate "$file" --frames "$fr" --every 20 > "$out/validate-$n.txt" 2>&1 ; } \
    2> /tmp/validate-all.$$
  verdict=$(tail -1 "$out/validate-$n.txt" | grep -q "all validators pass" && echo "all pass" || echo "a validator FAILED")
  read -r real user sys < /tmp/validate-all.$$
  printf '\nwall %s s, CPU %s s user + %s s sys on %s (2 cores shared with other jobs; load %s)\n' \
    "$real" "$user" "$sys" "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')" \
    "$(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/validate-$n.txt"
  echo "$n: $verdict"
done
rm -f /tmp/validate-all.$$
