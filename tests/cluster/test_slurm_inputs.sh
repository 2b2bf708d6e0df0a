#!/usr/bin/env bash
# ctest slurm.inputs (issue 68): scripts/slurm/ on hostile input, without a Slurm: sbatch is a
# stub on PATH that records its arguments and answers a job id.
#   1. --run-dir with a % (sbatch's --output pattern character): --output gets %% for it,
#      so the shards' logs land in the run folder (before: "%j" was replaced by the job id);
#      a backslash (which turns off sbatch's patterns) is refused with exit 2 naming it;
#   2. join.sbatch (run by hand) on malformed shard results (settings a list, points a
#      string, a deep nesting, non-UTF-8, a stop text with escapes): exit 1 naming each shard,
#      never a Python traceback, no control character in its output.
# Usage: test_slurm_inputs.sh OCTOCD SOURCE_DIR
set -uo pipefail
octocd=${1:?usage: test_slurm_inputs.sh OCTOCD SOURCE_DIR}
src=${2:?usage: test_slurm_inputs.sh OCTOCD SOURCE_DIR}
tmp=$(mktemp -d /tmp/octocd-slurm-inputs.XXXXXX) || exit 1
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

mkdir -p "$tmp/bin"
cat >"$tmp/bin/sbatch" <<'STUB'
#!/bin/bash
printf '%s\n' "$@" >>"$SBATCH_ARGS"
echo 4242
STUB
chmod +x "$tmp/bin/sbatch"
export PATH="$tmp/bin:$PATH" SBATCH_ARGS="$tmp/sbatch-args.txt"

# 1. A % in --run-dir.
run="$tmp/run-100%j"
out=$(bash "$src/scripts/slurm/submit.sh" sweep small --octocd "$octocd" --run-dir "$run" --shards 2 2>&1)
rc=$?
[ $rc = 0 ] || fail "submit.sh with a % in --run-dir: exit $rc: $out"
grep -qxF -- "--output=$tmp/run-100%%j/logs/shard-%a.log" "$SBATCH_ARGS" || fail "shard --output not escaped: $(grep -- --output "$SBATCH_ARGS")"
grep -qxF -- "--output=$tmp/run-100%%j/logs/join.log" "$SBATCH_ARGS" || fail "join --output not escaped: $(grep -- --output "$SBATCH_ARGS")"
[ -d "$run/logs" ] || fail "the run folder $run was not made"
out=$(bash "$src/scripts/slurm/submit.sh" sweep small --octocd "$octocd" --run-dir "$tmp/a\\b" --shards 2 2>&1)
rc=$?
[ $rc = 2 ] || fail "a backslash in --run-dir: exit $rc (want 2): $out"
[[ "$out" == *"holds a backslash"* ]] || fail "a backslash in --run-dir: $out"
[ ! -e "$tmp/a\\b" ] || fail "a refused --run-dir was created"

# 2. The join on malformed results: one run folder of 6 shards, each malformed its own way.
run="$tmp/join"
mkdir -p "$run/status" "$run/shards" "$run/logs"
n=6
printf '{"format": "octocd-bench", "settings": [], "complete": true}' >"$run/shards/part-0.json"
printf '{"format": "octocd-bench", "settings": {"shard": {"index": 1, "count": 6}}, "complete": true, "points": "abc"}' >"$run/shards/part-1.json"
python3 -c 'import sys; sys.stdout.write("[" * 100000 + "]" * 100000)' >"$run/shards/part-2.json"
printf '\xff\xfe{"format": 1}' >"$run/shards/part-3.json"
printf '{"format": "octocd-bench", "settings": {"shard": {"index": 4, "count": 6}}, "complete": false, "stopped": "SIG\\u001b]0;pwned\\u0007INT"}' >"$run/shards/part-4.json"
printf '{"format": "octocd-bench", "settings": {"shard": "4/6"}, "complete": true, "points": [1, 2]}' >"$run/shards/part-5.json"
for ((i = 0; i < n; i++)); do echo 0 >"$run/status/$i.rc"; done
out=$(bash "$src/scripts/slurm/join.sbatch" sweep "$run" "$n" 99 "$octocd" 2>&1)
rc=$?
[ $rc = 1 ] || fail "join on malformed results: exit $rc (want 1): $out"
[[ "$out" != *Traceback* ]] || fail "join printed a traceback: $out"
for ((i = 0; i < n; i++)); do
  [[ "$out" == *"shard $i/$n ("* ]] || fail "join does not name shard $i: $out"
done
[[ "$out" == *"stopped by SIG\\x1b]0;pwned\\x07INT"* ]] || fail "the stop text is not escaped: $out"
if LC_ALL=C grep -q $'[\x01-\x08\x0b-\x1f\x7f]' <<<"$out"; then fail "a control character in the join's output: $out"; fi
echo "PASS: % escaped and backslash refused in --run-dir; the join named 6 malformed shards without a traceback"
