#!/usr/bin/env bash
# Nightly validation (docs/validation.md, "Nightly validation";
# docs/validation-output.md): `octocd
# validate` on a scene set against a committed expectations file of known failures (design.md section
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
# Every scene is validated whatever happened to the ones before it. While a case runs, a
# line at most 10 s apart gives its seconds so far and the frame its octocd reached ("frame F of N").
# A case's line gives its wall and CPU seconds (its commands' user + system), the summary both totals.
# The summary lists each expected failure whose figure lies within 10% of its allowance (the
# expectations file keeps a margin of >= 10%, or an exact figure): re-record it by that rule.
#
# Usage: scripts/nightly.sh [--build DIR] [--scenes SET] [--frames N] [--every K]
#                           [--tolerance NAME=VALUE]... [--timeout S] [--against LIST]
#                           [--out DIR] [--data-dir DIR] [--expect FILE|none]
#                           [--write-expect FILE] [--strict] [--matrix SET] [--engines LIST]
#                           [--matrix-scenes LIST]
#                           [--history DIR] [SCENE.json ...]
#   --build DIR     build folder holding `octocd` (default: build); $OCTOCD_BIN, when
#                   set, names the binary itself and wins
#   --scenes SET    default: the scenes that fit the nightly budget (15 minutes on a
#                   2-core machine: the analytic scenes, bunny-stack-50, the four Table 5
#                   scenes and the three 10^4-body scenes; measured 5-9 minutes on a 2-core
#                   VM under load 6-11, docs/validation.md); large: the 5x10^4..10^6-body scenes
#                   (hours: one check of boxes-uniform-100k takes ~12 minutes; give them a
#                   job of their own, with a larger --every); all: both; none: no scene
#                   (the engine matrix alone). SCENE.json arguments replace the set.
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
#   --matrix SET    the engine matrix (docs/engines.md, "The engine matrix"): every
#                   engine of the registry that rotates (`octocd engines --json`: the
#                   reference engines bullet, mujoco, ode, dart and the process engines of
#                   the engines files, rapier and jolt shipped; docs/bring-your-engine.md),
#                   available here (`octocd engines --available`), runs each scene it can express with
#                   rotation (`octocd run --trace --contacts --state-every 1`), and the
#                   physics tier judges its trace (`validate --trace-in`, the same
#                   expectations file, keyed by the trace's name ENGINE--SCENE.h5):
#                   full (default: rot-stack-10, rot-slope, rot-drop-220, rot-pile-1000,
#                   bunny-stack-50 with rotation, rot-spin-free over hundreds of frames),
#                   quick (the same scenes over short windows, CI's ctest `corpus`
#                   label; traces ENGINE--SCENE--quick.h5), none (the default with SCENE.json
#                   arguments). Traces go to DIR/matrix/ (--out).
#                   Each engine (and cpu, and cuda where a GPU runs it) also gets
#                   determinism rows: `validate --determinism` on rot-drop-220 and
#                   bunny-stack-50 (full: 120 frames; quick: 30 and 40), cases
#                   ENGINE--SCENE--determinism (docs/predictability.md).
#   --engines LIST  the matrix's engines restricted to LIST (comma-separated registry names,
#                   e.g. rapier,jolt; default: every engine); a name the registry lacks is
#                   exit 2. CI's ctest runs the quick matrix as several tests this way.
#   --matrix-scenes LIST  the matrix's scenes, determinism rows included, restricted to LIST
#                   (comma-separated, e.g. rot-stack-10,rot-slope; default: every scene of
#                   the set); a name the set lacks is exit 2
#   --history DIR   also add this night's verdicts (every case's `validate --json`, kept
#                   in DIR/json/ of --out) with the machine, build and date to the history
#                   folder DIR (`octocd history-append`: a new file, none rewritten);
#                   `octocd report --history DIR` draws it (docs/regression.md)
#   SCENE.json ...  scenes to validate instead of the set
set -uo pipefail

# The comment above as help: on stdout for --help (exit 0), on stderr for a wrong call.
usage() {
  if [ "$1" = 0 ]; then sed -n '2,/^set -uo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'
  else sed -n '2,/^set -uo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; fi
  exit "$1"
}

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
matrix=""
only_engines=""
only_matrix_scenes=""
history=""
is_uint() { [[ "$1" =~ ^[0-9]+$ ]] && [ "$1" -ge 1 ]; }
# An option's value: "$2" present and not empty, else exit 2 naming the option.
need() { if [ -z "${2-}" ]; then echo "nightly: $1: missing value; allowed: $3" >&2; exit 2; fi; }
while [ $# -gt 0 ]; do
  case "$1" in
    --build) need "$1" "${2-}" "a folder"; build="$2"; shift 2 ;;
    --scenes) need "$1" "${2-}" "default, large or all"; set_name="$2"; shift 2 ;;
    --frames) need "$1" "${2-}" "a number"; frames="$2"; shift 2 ;;
    --every) need "$1" "${2-}" "a number"; every="$2"; shift 2 ;;
    --tolerance) need "$1" "${2-}" "NAME=VALUE"; tolerances+=(--tolerance "$2"); shift 2 ;;
    --timeout) need "$1" "${2-}" "seconds"; timeout_s="$2"; shift 2 ;;
    --against) need "$1" "${2-}" "a list"; against="$2"; shift 2 ;;
    --out) need "$1" "${2-}" "a folder"; out="$2"; shift 2 ;;
    --data-dir) need "$1" "${2-}" "a folder"; data_dir="$2"; shift 2 ;;
    --expect) need "$1" "${2-}" "a file or none"; expect="$2"; shift 2 ;;
    --write-expect) need "$1" "${2-}" "a file"; write_expect="$2"; shift 2 ;;
    --strict) strict=(--strict); shift ;;
    --matrix) need "$1" "${2-}" "full, quick or none"; matrix="$2"; shift 2 ;;
    --engines) need "$1" "${2-}" "engine names, comma-separated"; only_engines="$2"; shift 2 ;;
    --matrix-scenes) need "$1" "${2-}" "scene names, comma-separated"; only_matrix_scenes="$2"; shift 2 ;;
    --history) need "$1" "${2-}" "a folder"; history="$2"; shift 2 ;;
    -h|--help) usage 0 ;;
    -*) echo "nightly: unknown option '$1'" >&2; usage 2 ;;
    *) scenes+=("$1"); shift ;;
  esac
done
if [ -n "$frames" ] && ! is_uint "$frames"; then echo "nightly: --frames '$frames'; allowed: an integer >= 1" >&2; exit 2; fi
if ! is_uint "$every"; then echo "nightly: --every '$every'; allowed: an integer >= 1" >&2; exit 2; fi
# SCENE.json arguments replace the whole set, the matrix too, unless --matrix is given.
if [ -z "$matrix" ]; then if [ ${#scenes[@]} -gt 0 ]; then matrix=none; else matrix=full; fi; fi
case "$matrix" in full|quick|none) ;; *) echo "nightly: --matrix '$matrix'; allowed: full, quick, none" >&2; exit 2 ;; esac
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
    none) names=() ;;
    *) echo "nightly: --scenes '$set_name'; allowed: default, large, all, none (or SCENE.json arguments)" >&2; exit 2 ;;
  esac
  for n in "${names[@]+"${names[@]}"}"; do scenes+=("$root/datasets/scenes/$n.json"); done
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
mkdir -p "$out/junit" "$out/json" || exit 2
rm -f "$out"/junit/*.xml "$out"/json/*.json  # this run's reports only

xml_escape() { sed -e 's/&/\&amp;/g' -e 's/</\&lt;/g' -e 's/>/\&gt;/g' -e 's/"/\&quot;/g' <<<"$1"; }

extra=()
if [ -n "$data_dir" ]; then extra+=(--data-dir "$data_dir"); fi
if [ "$expect" != "none" ]; then
  if [ ! -r "$expect" ]; then echo "nightly: --expect '$expect': no such file; allowed: an expectations file or none" >&2; exit 2; fi
  extra+=(--expect "$expect" "${strict[@]}")
fi
if [ -n "$write_expect" ]; then extra+=(--write-expect "$write_expect"); fi
# The matrix's runs take the data folder; its judged traces the expectations.
extra_run=()
if [ -n "$data_dir" ]; then extra_run+=(--data-dir "$data_dir"); fi
extra_trace=("${extra[@]}")
if [ -n "$data_dir" ]; then extra_trace=("${extra[@]:2}"); fi

passed=0 failed=0 broken=0 bad=0 expected=0 case_cpu_ms=0 cpu_all_ms=0
failed_list=() broken_list=() bad_list=() thin_list=()
child=0 beat=0 case_now=""
# A signal to the nightly stops the case running now (octocd stops within a second, saying
# what it keeps), waits for it, says what the nightly keeps and exits 128 + the signal.
# $1: the signal's number, $2: its name. A matrix case is a subshell: its octocd (under
# `timeout`, which passes the signal on) is stopped and waited for too, so none outlives
# the nightly; a plain case's `timeout` passes the signal on itself (one signal, not two).
stop() {
  trap - INT TERM
  local kids="" k n
  [ "$beat" -gt 0 ] && kill "$beat" 2>/dev/null
  if [ "$child" -gt 0 ]; then
    if [ "$(ps -o comm= -p "$child" 2>/dev/null)" != timeout ]; then kids="$(pgrep -P "$child" || true)"; fi
    kill -TERM "$child" $kids 2>/dev/null
    wait "$child" 2>/dev/null
    # Each ends once its octocd has (a zombie then: its parent, the subshell, is gone).
    for k in $kids; do
      while [ -d "/proc/$k" ] && ! grep -q '^State:[[:space:]]*Z' "/proc/$k/status" 2>/dev/null; do sleep 0.02; done
    done
  fi
  n=$(find "$out/junit" -maxdepth 1 -name '*.xml' 2>/dev/null | wc -l)
  echo "nightly: stopped by SIG$2${case_now:+ during case $(shown "$case_now")}; $out/junit keeps the reports of $n case(s) (no summary)" >&2
  exit $((128 + $1))
}
trap 'stop 2 INT' INT
trap 'stop 15 TERM' TERM
started_all=$(date +%s.%N)
# The JUnit report of case $1 when octocd wrote none: one errored test case of type $2 with
# message $3, taking $secs seconds.
junit_error() {
  local n msg
  n="$(xml_escape "$1")"
  msg="$(xml_escape "$3")"
  cat >"$out/junit/$1.xml" <<EOF2
<?xml version="1.0" encoding="UTF-8"?>
<testsuites name="octocd validate" tests="1" failures="0" errors="1" skipped="0" time="$secs">
  <testsuite name="$n" tests="1" failures="0" errors="1" skipped="0" time="$secs">
    <testcase classname="$n" name="octocd" time="$secs">
      <error message="$msg" type="$2">$msg</error>
    </testcase>
  </testsuite>
</testsuites>
EOF2
}
# Text for the terminal (docs/robustness.md, "Sinks"): control characters (a newline or an
# escape sequence in a scene's file name) written as \xNN, at most 2,000 characters.
shown() {
  local s="${1:0:2000}" out="" c i
  for ((i = 0; i < ${#s}; i++)); do
    c="${s:i:1}"
    if [[ "$c" == [[:cntrl:]] ]]; then printf -v c '\\x%02x' "'$c"; fi
    out+="$c"
  done
  if [ ${#1} -gt 2000 ]; then out+="... (${#1} characters)"; fi
  printf '%s' "$out"
}
# The outcome of one case (a scene, or an engine's run of a scene in the matrix): its
# JUnit report (an errored case when octocd wrote none or timed out), its line on stdout,
# the counts. Arguments: name, log, rc, t0, frames.
judge_case() {
  local name="$1" log="$2" rc="$3" t0="$4" n_frames="$5"
  local shown_name
  shown_name="$(shown "$name")"
  secs=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
  if [ $rc -eq 124 ] || [ $rc -eq 137 ]; then
    # --timeout: octocd was stopped (its partial report, if any, is replaced by the error).
    junit_error "$name" timeout "timed out after $timeout_s s (--timeout; $n_frames frames asked, see $(shown "$log"))"
    rc=124
  elif [ ! -s "$out/junit/$name.xml" ]; then
    # octocd wrote no report (it crashed, or the command line was refused): one errored case.
    junit_error "$name" "exit-$rc" "octocd validate exited $rc without a report; see $log"
  fi
  # octocd's own plain-text outcome lines (validate's stdout): expected, NEW FAILURE,
  # GROWN, fixed (never the JUnit's XML-escaped messages).
  outcomes() { grep -E "^($1) " "$log" | head -n "$2" | cut -c1-2000 | cat -v | sed 's/^/         /'; }
  n_expected=$(grep -c '^expected ' "$log")
  expected=$((expected + n_expected))
  # Expected failures whose worst figure lies within 10 % of its allowance (the expectations
  # file's rule: a margin of >= 10 % for float32 differences on another machine, or an exact
  # figure: a whole number equal to its allowance, a count or the 180-degree angle).
  while IFS= read -r t; do thin_list+=("$shown_name $t"); done < <(awk '
    /^expected [^ ]+: worst [^ ]+ <= allowed [^ ]+ / {
      w = $4 + 0; a = $7 + 0
      if (w == a && a == int(a)) next
      if (a - w < 0.1 * a) printf "%s worst %s of allowed %s (margin %.1f%%)\n", substr($2, 1, length($2) - 1), $4, $7, 100 * (a - w) / a
    }' "$log")
  case $rc in
    0) passed=$((passed + 1))
       if [ "$n_expected" -gt 0 ]; then
         echo "pass     $shown_name ($n_frames frames, ${secs} s, $(cpu_s "$case_cpu_ms") CPU-s; $n_expected expected failure(s))"
         outcomes 'expected' 10
       else
         echo "pass     $shown_name ($n_frames frames, ${secs} s, $(cpu_s "$case_cpu_ms") CPU-s)"
       fi
       outcomes 'fixed' 10 ;;
    3) failed=$((failed + 1)); failed_list+=("$shown_name"); echo "FAILED   $shown_name (a validator failed, ${secs} s, $(cpu_s "$case_cpu_ms") CPU-s: $(shown "$log"))"
       outcomes 'NEW FAILURE|GROWN' 5; outcomes 'fixed' 5; outcomes 'expected' 10 ;;
    124) broken=$((broken + 1)); broken_list+=("$shown_name"); echo "TIMEOUT  $shown_name (after $timeout_s s: $(shown "$log"))" ;;
    2) bad=$((bad + 1)); bad_list+=("$shown_name"); echo "BAD      $shown_name (bad input: $(shown "$log"))"; tail -n 3 "$log" | cut -c1-2000 | cat -v | sed 's/^/         /' ;;
    *) broken=$((broken + 1)); broken_list+=("$shown_name"); echo "ERROR    $shown_name (exit $rc: $(shown "$log"))"; tail -n 3 "$log" | cut -c1-2000 | cat -v | sed 's/^/         /' ;;
  esac
}

# Progress of case $1 while it runs (log $2, started at $3): one line every 9 s (at most 10 s
# apart on a loaded machine) with the
# seconds so far and the latest frame its octocd reported in the log (validate's "judged
# frame F of N", every 2 s; run's "frame F/N", every 10% of its frames), so a long scene is
# never silent for more than 10 s.
heartbeat() {
  local shown_name line secs_so_far
  shown_name="$(shown "$1")"
  while sleep 9 </dev/null >/dev/null 2>&1; do  # sleep holds no pipe of ours (ctest waits on them)
    line="$(tail -c 4096 "$2" 2>/dev/null | grep -aoE '(judged frame [0-9]+ of [0-9]+|^frame [0-9]+/[0-9]+)' | tail -n 1 |
            sed -E 's/^judged frame ([0-9]+) of ([0-9]+)$/validate: frame \1 of \2/; s|^frame ([0-9]+)/([0-9]+)$|run: frame \1 of \2|')"
    secs_so_far=$(awk -v a="$3" -v b="$(date +%s.%N)" 'BEGIN { printf "%.0f", b - a }')
    echo "  ...    $shown_name: ${secs_so_far} s, ${line:-starting (no frame yet)}"
  done
}
# The CPU time (user + system) of this shell's finished children, in ms, into cpu_ms: bash's
# `times` (its second line), written to a file so that no subshell runs it (a forked shell's
# children times start at zero).
children_cpu_ms() {
  local line u s t
  times >"$out/.times"
  { read -r line; read -r u s; } <"$out/.times"
  cpu_ms=0
  for t in "$u" "$s"; do  # "1m2.345s" -> 62345
    [[ "$t" =~ ^([0-9]+)m([0-9]+)[.,]([0-9]{3})s$ ]] &&
      cpu_ms=$((cpu_ms + BASH_REMATCH[1] * 60000 + 10#${BASH_REMATCH[2]} * 1000 + 10#${BASH_REMATCH[3]}))
  done
}
cpu_s() { local r=$((($1 + 50) / 100)); printf '%d.%d' $((r / 10)) $((r % 10)); }  # ms -> "12.3"
# Case $1 ($2 frames): the command "${@:3}" in the background (stop() ends it on a signal),
# its output in $out/$1.log and a progress line at most 10 s apart (heartbeat), then its outcome
# (judge_case).
run_case() {
  local name="$1" n_frames="$2" t0 rc c0
  shift 2
  t0=$(date +%s.%N)
  case_now="$name"
  children_cpu_ms; c0=$cpu_ms
  "$@" >"$out/$name.log" 2>&1 &
  child=$!
  heartbeat "$name" "$out/$name.log" "$t0" &
  beat=$!
  wait "$child"
  rc=$?
  children_cpu_ms; case_cpu_ms=$((cpu_ms - c0)); cpu_all_ms=$((cpu_all_ms + case_cpu_ms))
  child=0 case_now=""
  kill "$beat" 2>/dev/null
  wait "$beat" 2>/dev/null
  beat=0
  judge_case "$name" "$out/$name.log" "$rc" "$t0" "$n_frames"
}
# A matrix case: engine $1's run of scene $2 with rotation, traced to $out/matrix/$3.h5,
# then that trace judged (`validate --trace-in`); the run's exit code when it fails.
matrix_case() {
  local trace="$out/matrix/$3.h5"
  timeout --signal=TERM --kill-after=10 "$timeout_s" "$bin" run "$root/datasets/scenes/$2.json" --engine "$1" --rotation --frames "$n_frames" --state-every 1 \
    --contacts --trace "$trace" --no-xdmf "${extra_run[@]}" || return $?
  timeout --signal=TERM --kill-after=10 "$timeout_s" "$bin" validate --trace-in "$trace" --every "$m_every" --against "$against" --junit "$out/junit/$3.xml" \
    --json "$out/json/$3.json" "${tolerances[@]}" "${extra_trace[@]}"
}
for scene in "${scenes[@]+"${scenes[@]}"}"; do
  name="$(basename "$scene" .json)"
  n_frames="$(frames_of "$name")"
  run_case "$name" "$n_frames" timeout --signal=TERM --kill-after=10 "$timeout_s" \
    "$bin" validate "$scene" --frames "$n_frames" --every "$every" --against "$against" \
    --junit "$out/junit/$name.xml" --json "$out/json/$name.json" "${tolerances[@]}" "${extra[@]}"
done

# The engine matrix: ENGINE--SCENE cases, each a run with rotation and its judged trace.
matrix_scenes() {  # "scene frames every" per line: full or quick windows
  if [ "$matrix" = "full" ]; then
    printf '%s\n' "rot-stack-10 600 10" "rot-slope 600 10" "rot-drop-220 400 10" "rot-pile-1000 150 25" \
      "bunny-stack-50 600 10" "rot-spin-free 600 10"
  else
    printf '%s\n' "rot-stack-10 120 5" "rot-slope 120 5" "rot-drop-220 60 5" "rot-pile-1000 12 4" \
      "bunny-stack-50 80 5" "rot-spin-free 120 5"
  fi
}
# A case the full matrix leaves out, with the reason (docs/engines.md, "dart"): the
# engine expresses the scene but cannot run its window within --timeout.
matrix_skip() {  # engine scene
  if [ "$matrix" = "full" ] && [ "$1--$2" = "dart--bunny-stack-50" ]; then
    echo "DART's FCL collides each bunny hull as a BVH of its triangles: ~2200 contact rows once the bunnies land, 1 to 4 steps/s; the quick window runs"
  fi
}
matrix_engines=()
# The registry (`octocd engines --json`, asked once: it runs every engine's check), one engine a
# line: name, rotates (yes/no), available (yes/no), why not, separated by tabs.
engine_table=""
# Field $1 (1 name, 2 rotates, 3 available) of the engines whose field $2 is $3 (any: all), a line each.
engines_where() { awk -F'\t' -v f="$1" -v k="$2" -v v="$3" 'k == 0 || $k == v { print $f }' <<<"$engine_table"; }
# Why engine $1 is not available: the registry's reason.
engine_why() { awk -F'\t' -v e="$1" '$1 == e { print "unavailable: " $4 }' <<<"$engine_table"; }
if [ "$matrix" != "none" ]; then
  engine_table="$("$bin" engines --json 2>/dev/null | python3 -c 'import json, sys
yn = lambda b: "yes" if b else "no"
for e in json.load(sys.stdin)["engines"]:
    print("\t".join([e["name"], yn(e["rotates"]), yn(e["available"]), " ".join(e.get("why", "").split())]))')"
  available="$(engines_where 1 3 yes)"
  # --engines: each name must be the registry's (a typo would silently judge nothing).
  if [ -n "$only_engines" ]; then
    registry="$(engines_where 1 0 any)"
    for e in ${only_engines//,/ }; do
      grep -qxF -- "$e" <<<"$registry" || { echo "nightly: --engines '$e': not an engine of this octocd; allowed: $(paste -sd, <<<"$registry")" >&2; exit 2; }
    done
  fi
fi
# Whether engine $1 is in the matrix (--engines, default every engine).
in_matrix() { [ -z "$only_engines" ] || grep -qxF -- "$1" <<<"${only_engines//,/$'\n'}"; }
# Whether scene $1 is in the matrix (--matrix-scenes, default every scene of the set).
in_matrix_scenes() { [ -z "$only_matrix_scenes" ] || grep -qxF -- "$1" <<<"${only_matrix_scenes//,/$'\n'}"; }
# --matrix-scenes: each name must be a scene of the matrix (a typo would silently judge nothing).
if [ -n "$only_matrix_scenes" ]; then
  matrix_names="$(matrix_scenes | cut -d' ' -f1)"
  for sc in ${only_matrix_scenes//,/ }; do
    grep -qxF -- "$sc" <<<"$matrix_names" || { echo "nightly: --matrix-scenes '$sc': not a scene of the matrix; allowed: $(paste -sd, <<<"$matrix_names")" >&2; exit 2; }
  done
fi
if [ "$matrix" != "none" ]; then
  # The registry's rotating engines, built in or process engines (`octocd engines --json`).
  rotating="$(engines_where 1 2 yes)"
  for e in $rotating; do
    in_matrix "$e" || continue
    if grep -qx "$e" <<<"$available"; then
      matrix_engines+=("$e")
    else
      why="$(engine_why "$e")"
      echo "matrix   $e: not available here (${why:-not an engine of this octocd})"
    fi
  done
  mkdir -p "$out/matrix" || exit 2
fi
for e in "${matrix_engines[@]+"${matrix_engines[@]}"}"; do
  while read -r sc n_frames m_every; do
    in_matrix_scenes "$sc" || continue
    [ -r "$root/datasets/scenes/$sc.json" ] || { echo "matrix   $e--$sc: no scene $sc.json, skipped"; continue; }
    why_skip="$(matrix_skip "$e" "$sc")"
    [ -z "$why_skip" ] || { echo "matrix   $e--$sc: skipped ($why_skip)"; continue; }
    name="$e--$sc"
    [ "$matrix" = "quick" ] && name="$e--$sc--quick"
    run_case "$name" "$n_frames" matrix_case "$e" "$sc" "$name"
  done < <(matrix_scenes)
done

# The determinism rows of the matrix (docs/predictability.md): per engine, `validate
# --determinism` on rot-drop-220 and bunny-stack-50 over short windows: two runs bit for bit,
# 1 against N threads where the engine threads (cpu), cpu against cuda where a GPU runs cuda.
# octocd's engines translate only: rot-drop-220 (a rotating scene) is skipped for them.
determinism_scenes() {  # "scene frames rotates" per line
  if [ "$matrix" = "full" ]; then
    printf '%s\n' "rot-drop-220 120 yes" "bunny-stack-50 120 no"
  else
    printf '%s\n' "rot-drop-220 30 yes" "bunny-stack-50 40 no"
  fi
}
# Every engine of the registry available here (`octocd engines --json`), rotating or not.
determinism_engines=()
translating=""
if [ "$matrix" != "none" ]; then
  read -r -a all_engines <<<"$(engines_where 1 0 any | paste -sd' ')"
  translating="$(engines_where 1 2 no)"
  for e in "${all_engines[@]+"${all_engines[@]}"}"; do
    in_matrix "$e" || continue
    if grep -qx "$e" <<<"$available"; then determinism_engines+=("$e")
    else echo "matrix   $e--determinism: not available here ($(engine_why "$e"))"; fi
  done
fi
for e in "${determinism_engines[@]+"${determinism_engines[@]}"}"; do
  while read -r sc n_frames sc_rotates; do
    in_matrix_scenes "$sc" || continue
    [ -r "$root/datasets/scenes/$sc.json" ] || { echo "matrix   $e--$sc--determinism: no scene $sc.json, skipped"; continue; }
    rotation=(--rotation)
    if grep -qw "$e" <<<"$translating"; then
      rotation=()
      [ "$sc_rotates" = "yes" ] && { echo "matrix   $e--$sc--determinism: skipped ($e translates only; $sc rotates)"; continue; }
    fi
    why_skip="$(matrix_skip "$e" "$sc")"
    [ -z "$why_skip" ] || { echo "matrix   $e--$sc--determinism: skipped ($why_skip)"; continue; }
    name="$e--$sc--determinism"
    [ "$matrix" = "quick" ] && name="$e--$sc--determinism--quick"
    run_case "$name" "$n_frames" timeout --signal=TERM --kill-after=10 "$timeout_s" "$bin" validate \
      "$root/datasets/scenes/$sc.json" --engine "$e" "${rotation[@]+"${rotation[@]}"}" --frames "$n_frames" \
      --determinism --junit "$out/junit/$name.xml" --json "$out/json/$name.json" "${extra[@]}"
  done < <(determinism_scenes)
done

# One report over every scene: the <testsuite> elements of each file under one root
# (octocd writes each element on its own lines), with the totals summed.
rm -f "$out/.times"
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
echo "nightly: ${#scenes[@]} scenes and $((passed + failed + broken + bad - ${#scenes[@]})) matrix cases in $total_s s ($(cpu_s "$cpu_all_ms") CPU-s, user + system, in the cases' commands): $passed passed ($expected expected failure(s), ${expect##*/}), $failed failed, $broken errors, $bad bad input (JUnit: $merged)"
[ -n "$write_expect" ] && echo "nightly: wrote the current failures to $write_expect (edit each reason)"
[ $failed -gt 0 ] && echo "nightly: validators failed on: ${failed_list[*]}"
[ $broken -gt 0 ] && echo "nightly: runs failed on: ${broken_list[*]}"
[ $bad -gt 0 ] && echo "nightly: bad input: ${bad_list[*]}"
if [ ${#thin_list[@]} -gt 0 ]; then
  echo "nightly: ${#thin_list[@]} expected failure(s) within 10% of the allowance (re-record by the rule of ${expect##*/}):"
  printf '         %s\n' "${thin_list[@]}"
fi
if [ -n "$history" ]; then
  jsons=()
  for f in "$out"/json/*.json; do [ -e "$f" ] && jsons+=(--validation "$f"); done
  for n in "${broken_list[@]+"${broken_list[@]}"}" "${bad_list[@]+"${bad_list[@]}"}"; do
    [ -e "$out/json/$n.json" ] || jsons+=(--errored "$n")  # no verdict: an error row
  done
  "$bin" history-append "$history" --kind nightly "${jsons[@]+"${jsons[@]}"}" || echo "nightly: --history '$history': adding this night failed (above)" >&2
fi
if [ $bad -gt 0 ]; then exit 2; fi
if [ $broken -gt 0 ]; then exit 1; fi
if [ $failed -gt 0 ]; then exit 3; fi
exit 0
