#!/usr/bin/env bash
# Nightly validation (docs/validation.md, "Nightly validation";
# docs/validation-output.md): `octocd
# validate` on a scene set against a committed expectations file of known failures (SPEC
# 14b), one JUnit report per scene plus one merged report, and an exit code a CI job can
# trust:
#   0  every validator of every scene passed, or failed only as expected (within the
#      figures of --expect's file; listed as "expected" on stdout, skipped in JUnit)
#   3  a new failure, or an expected one grown beyond its figure, on some scene (and no
#      scene was bad input or failed to run); with --strict also an expected failure that
#      no longer fails
#   1  some run failed or timed out (octocd exit 1: a non-finite state, an I/O error,
#      ...; an unexpected exit code; --timeout reached), and no scene was bad input
#   2  some scene was bad input (octocd exit 2), or this script was called wrongly
# Every scene is validated whatever happened to the ones before it.
#
# Usage: scripts/nightly.sh [--build DIR] [--scenes SET] [--frames N] [--every K]
#                           [--tolerance NAME=VALUE]... [--timeout S] [--against LIST]
#                           [--out DIR] [--data-dir DIR] [--expect FILE|none]
#                           [--write-expect FILE] [--strict] [SCENE.json ...]
#   --build DIR     build folder holding `octocd` (default: build); $OCTOCD_BIN, when
#                   set, names the binary itself and wins
#   --scenes SET    default: the scenes that fit the nightly budget (15 minutes on a
#                   2-core machine: the analytic scenes, bunny-stack-50, the four Table 5
#                   scenes and the three 10^4-body scenes; measured 5-9 minutes on a 2-core
#                   VM under load 6-11, docs/validation.md); large: the 5x10^4..10^6-body scenes
#                   (hours: one check of boxes-uniform-100k takes ~12 minutes; give them a
#                   job of their own, with a larger --every); all: both. SCENE.json
#                   arguments replace the set.
#   --frames N      steps per scene (default: per scene: 1000 for the analytic scenes,
#                   2000 for box-stack, 3000 for the mesh scenes, 100 for the box and pile
#                   scenes of 10^4 bodies and more)
#   --every K       candidate sets, midphase and normals every K-th frame (default 50)
#   --tolerance NAME=VALUE  passed to `octocd validate --tolerance` (repeatable)
#   --timeout S     stop a scene's validate after S seconds (SIGTERM, then SIGKILL 10 s
#                   later): an errored JUnit case "timed out after S s" (default 900)
#   --against LIST  references for `validate --against` (default bullet,fcl)
#   --out DIR       reports folder (default nightly-out): DIR/junit/<scene>.xml,
#                   DIR/junit.xml (all scenes in one <testsuites>), DIR/<scene>.log
#   --data-dir DIR  passed to `octocd validate --data-dir`
#   --expect FILE   known failures (`octocd validate --expect`; default
#                   scripts/nightly-expect.json: octocd's own engines on the default set
#                   with the default frames, each entry with its reason); none: no
#                   expectations (every failure fails)
#   --write-expect FILE  record every scene's current failures in FILE (entries of other
#                   scenes kept; edit each reason); the scenes then count as passed
#   --strict        an expected failure that no longer fails is a failure (exit 3)
#   SCENE.json ...  scenes to validate instead of the set
set -uo pipefail

usage() { sed -n '2,/^set -uo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit "$1"; }

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="build"
frames=""
every=50
against="bullet,fcl"
out="nightly-out"
data_dir=""
set_name="default"
timeout_s=900
tolerances=()
scenes=()
expect="$root/scripts/nightly-expect.json"
write_expect=""
strict=()
is_uint() { [[ "$1" =~ ^[0-9]+$ ]] && [ "$1" -ge 1 ]; }
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build="${2:?--build needs a folder}"; shift 2 ;;
    --scenes) set_name="${2:?--scenes needs default, large or all}"; shift 2 ;;
    --frames) frames="${2:?--frames needs a number}"; shift 2 ;;
    --every) every="${2:?--every needs a number}"; shift 2 ;;
    --tolerance) tolerances+=(--tolerance "${2:?--tolerance needs NAME=VALUE}"); shift 2 ;;
    --timeout) timeout_s="${2:?--timeout needs seconds}"; shift 2 ;;
    --against) against="${2:?--against needs a list}"; shift 2 ;;
    --out) out="${2:?--out needs a folder}"; shift 2 ;;
    --data-dir) data_dir="${2:?--data-dir needs a folder}"; shift 2 ;;
    --expect) expect="${2:?--expect needs a file or none}"; shift 2 ;;
    --write-expect) write_expect="${2:?--write-expect needs a file}"; shift 2 ;;
    --strict) strict=(--strict); shift ;;
    -h|--help) usage 0 ;;
    -*) echo "nightly: unknown option '$1'" >&2; usage 2 ;;
    *) scenes+=("$1"); shift ;;
  esac
done
if [ -n "$frames" ] && ! is_uint "$frames"; then echo "nightly: --frames '$frames'; allowed: an integer >= 1" >&2; exit 2; fi
if ! is_uint "$every"; then echo "nightly: --every '$every'; allowed: an integer >= 1" >&2; exit 2; fi
if ! is_uint "$timeout_s"; then echo "nightly: --timeout '$timeout_s'; allowed: seconds, an integer >= 1" >&2; exit 2; fi
bin="${OCTOCD_BIN:-$build/octocd}"
if [ ! -x "$bin" ]; then
  echo "nightly: no octocd binary at '$bin' (build first, or give --build DIR / \$OCTOCD_BIN)" >&2
  exit 2
fi
default_set=(free-fall bounce slide box-stack bunny-stack-50 bunny-random-400 armadillo-random-250
             dragon-random-250 asian-dragon-random-60 boxes-random-10000 boxes-uniform-10k bunny-pile-10k)
large_set=(boxes-uniform-50000 boxes-uniform-100k boxes-uniform-1m bunny-pile-100k bunny-pile-1m)
if [ ${#scenes[@]} -eq 0 ]; then
  case "$set_name" in
    default) names=("${default_set[@]}") ;;
    large) names=("${large_set[@]}") ;;
    all) names=("${default_set[@]}" "${large_set[@]}") ;;
    *) echo "nightly: --scenes '$set_name'; allowed: default, large, all (or SCENE.json arguments)" >&2; exit 2 ;;
  esac
  for n in "${names[@]}"; do scenes+=("$root/datasets/scenes/$n.json"); done
fi
# Frames per scene when --frames is not given (docs/validation.md, "Nightly validation").
frames_of() {
  if [ -n "$frames" ]; then echo "$frames"; return; fi
  case "$1" in
    free-fall|bounce|slide) echo 1000 ;;  # the bounce happens at frame ~320, the slide stops at ~410
    box-stack) echo 2000 ;;               # the resting check needs its settling frames
    boxes-*|bunny-pile-*) echo 100 ;;
    *) echo 3000 ;;                       # the mesh scenes: ten times CI's 300
  esac
}
mkdir -p "$out/junit" || exit 2
rm -f "$out"/junit/*.xml  # this run's reports only

xml_escape() { sed -e 's/&/\&amp;/g' -e 's/</\&lt;/g' -e 's/>/\&gt;/g' -e 's/"/\&quot;/g' <<<"$1"; }

extra=()
if [ -n "$data_dir" ]; then extra+=(--data-dir "$data_dir"); fi
if [ "$expect" != "none" ]; then
  if [ ! -r "$expect" ]; then echo "nightly: --expect '$expect': no such file; allowed: an expectations file or none" >&2; exit 2; fi
  extra+=(--expect "$expect" "${strict[@]}")
fi
if [ -n "$write_expect" ]; then extra+=(--write-expect "$write_expect"); fi

passed=0 failed=0 broken=0 bad=0 expected=0
failed_list=() broken_list=() bad_list=()
child=0
stop() {  # a signal to the nightly stops the scene running now (octocd stops within a second)
  trap - INT TERM
  echo "nightly: stopped by a signal" >&2
  [ "$child" -gt 0 ] && kill -TERM "$child" 2>/dev/null && wait "$child"
  exit 130
}
trap stop INT TERM
started_all=$(date +%s.%N)
for scene in "${scenes[@]}"; do
  name="$(basename "$scene" .json)"
  log="$out/$name.log"
  n_frames="$(frames_of "$name")"
  t0=$(date +%s.%N)
  timeout --signal=TERM --kill-after=10 "$timeout_s" \
    "$bin" validate "$scene" --frames "$n_frames" --every "$every" --against "$against" \
    --junit "$out/junit/$name.xml" "${tolerances[@]}" "${extra[@]}" >"$log" 2>&1 &
  child=$!
  wait "$child"
  rc=$?
  child=0
  secs=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
  if [ $rc -eq 124 ] || [ $rc -eq 137 ]; then
    # --timeout: octocd was stopped (its partial report, if any, is replaced by the error).
    n="$(xml_escape "$name")"
    msg="$(xml_escape "timed out after $timeout_s s (--timeout; $n_frames frames asked, see $log)")"
    cat >"$out/junit/$name.xml" <<EOF2
<?xml version="1.0" encoding="UTF-8"?>
<testsuites name="octocd validate" tests="1" failures="0" errors="1" skipped="0" time="$secs">
  <testsuite name="$n" tests="1" failures="0" errors="1" skipped="0" time="$secs">
    <testcase classname="$n" name="octocd" time="$secs">
      <error message="$msg" type="timeout">$msg</error>
    </testcase>
  </testsuite>
</testsuites>
EOF2
    rc=124
  elif [ ! -s "$out/junit/$name.xml" ]; then
    # octocd wrote no report (it crashed, or the command line was refused): one errored case.
    n="$(xml_escape "$name")" msg="$(xml_escape "octocd validate exited $rc without a report; see $log")"
    cat >"$out/junit/$name.xml" <<EOF2
<?xml version="1.0" encoding="UTF-8"?>
<testsuites name="octocd validate" tests="1" failures="0" errors="1" skipped="0" time="$secs">
  <testsuite name="$n" tests="1" failures="0" errors="1" skipped="0" time="$secs">
    <testcase classname="$n" name="octocd" time="$secs">
      <error message="$msg" type="exit-$rc">$msg</error>
    </testcase>
  </testsuite>
</testsuites>
EOF2
  fi
  # octocd's own plain-text outcome lines (validate's stdout): expected, NEW FAILURE,
  # GROWN, fixed (never the JUnit's XML-escaped messages).
  outcomes() { grep -E "^($1) " "$log" | head -n "$2" | sed 's/^/         /'; }
  n_expected=$(grep -c '^expected ' "$log")
  expected=$((expected + n_expected))
  case $rc in
    0) passed=$((passed + 1))
       if [ "$n_expected" -gt 0 ]; then
         echo "pass     $name ($n_frames frames, ${secs} s; $n_expected expected failure(s))"
         outcomes 'expected' 10
       else
         echo "pass     $name ($n_frames frames, ${secs} s)"
       fi
       outcomes 'fixed' 10 ;;
    3) failed=$((failed + 1)); failed_list+=("$name"); echo "FAILED   $name (a validator failed, ${secs} s: $log)"
       outcomes 'NEW FAILURE|GROWN' 5; outcomes 'fixed' 5; outcomes 'expected' 10 ;;
    124) broken=$((broken + 1)); broken_list+=("$name"); echo "TIMEOUT  $name (after $timeout_s s: $log)" ;;
    2) bad=$((bad + 1)); bad_list+=("$name"); echo "BAD      $name (bad input: $log)"; tail -n 3 "$log" | sed 's/^/         /' ;;
    *) broken=$((broken + 1)); broken_list+=("$name"); echo "ERROR    $name (exit $rc: $log)"; tail -n 3 "$log" | sed 's/^/         /' ;;
  esac
done

# One report over every scene: the <testsuite> elements of each file under one root
# (octocd writes each element on its own lines), with the totals summed.
merged="$out/junit.xml"
{
  tests=0 failures=0 errors=0 skipped=0
  for f in "$out"/junit/*.xml; do
    [ -e "$f" ] || continue
    read -r t fl e s < <(sed -n 's/.*<testsuite name="[^"]*" tests="\([0-9]*\)" failures="\([0-9]*\)" errors="\([0-9]*\)" skipped="\([0-9]*\)".*/\1 \2 \3 \4/p' "$f" | head -n 1)
    tests=$((tests + ${t:-0})); failures=$((failures + ${fl:-0})); errors=$((errors + ${e:-0})); skipped=$((skipped + ${s:-0}))
  done
  echo '<?xml version="1.0" encoding="UTF-8"?>'
  total_s=$(awk -v a="$started_all" -v b="$(date +%s.%N)" 'BEGIN { printf "%.3f", b - a }')
  echo "<testsuites name=\"octocd nightly\" tests=\"$tests\" failures=\"$failures\" errors=\"$errors\" skipped=\"$skipped\" time=\"$total_s\">"
  for f in "$out"/junit/*.xml; do
    [ -e "$f" ] || continue
    sed -n '/^  <testsuite /,/^  <\/testsuite>/p' "$f"
  done
  echo '</testsuites>'
} >"$merged"

echo
echo "nightly: ${#scenes[@]} scenes in $total_s s: $passed passed ($expected expected failure(s), ${expect##*/}), $failed failed, $broken errors, $bad bad input (JUnit: $merged)"
[ -n "$write_expect" ] && echo "nightly: wrote the current failures to $write_expect (edit each reason)"
[ $failed -gt 0 ] && echo "nightly: validators failed on: ${failed_list[*]}"
[ $broken -gt 0 ] && echo "nightly: runs failed on: ${broken_list[*]}"
[ $bad -gt 0 ] && echo "nightly: bad input: ${bad_list[*]}"
if [ $bad -gt 0 ]; then exit 2; fi
if [ $broken -gt 0 ]; then exit 1; fi
if [ $failed -gt 0 ]; then exit 3; fi
exit 0
