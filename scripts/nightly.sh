#!/usr/bin/env bash
# Nightly validation (README, "Nightly validation"): `octocd validate` on every shipped
# scene (or the scenes given), one JUnit report per scene plus one merged report, and an
# exit code a CI job can trust:
#   0  every validator of every scene passed
#   3  a validator failed on some scene (and no scene was bad input or failed to run)
#   1  some run failed (octocd exit 1: a non-finite state, an I/O error, ...; or an
#      unexpected exit code), and no scene was bad input
#   2  some scene was bad input (octocd exit 2), or this script was called wrongly
# Every scene is validated whatever happened to the ones before it.
#
# Usage: scripts/nightly.sh [--build DIR] [--frames N] [--every K] [--against LIST]
#                           [--out DIR] [--data-dir DIR] [SCENE.json ...]
#   --build DIR     build folder holding `octocd` (default: build); $OCTOCD_BIN, when
#                   set, names the binary itself and wins
#   --frames N      steps per scene (default 3000, ten times CI's 300)
#   --every K       candidate sets, midphase and normals every K-th frame (default 20)
#   --against LIST  references for `validate --against` (default bullet,fcl)
#   --out DIR       reports folder (default nightly-out): DIR/junit/<scene>.xml,
#                   DIR/junit.xml (all scenes in one <testsuites>), DIR/<scene>.log
#   --data-dir DIR  passed to `octocd validate --data-dir`
#   SCENE.json ...  scenes to validate (default: datasets/scenes/*.json)
set -uo pipefail

usage() { sed -n '2,/^set -uo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit "$1"; }

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="build"
frames=3000
every=20
against="bullet,fcl"
out="nightly-out"
data_dir=""
scenes=()
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build="${2:?--build needs a folder}"; shift 2 ;;
    --frames) frames="${2:?--frames needs a number}"; shift 2 ;;
    --every) every="${2:?--every needs a number}"; shift 2 ;;
    --against) against="${2:?--against needs a list}"; shift 2 ;;
    --out) out="${2:?--out needs a folder}"; shift 2 ;;
    --data-dir) data_dir="${2:?--data-dir needs a folder}"; shift 2 ;;
    -h|--help) usage 0 ;;
    -*) echo "nightly: unknown option '$1'" >&2; usage 2 ;;
    *) scenes+=("$1"); shift ;;
  esac
done
bin="${OCTOCD_BIN:-$build/octocd}"
if [ ! -x "$bin" ]; then
  echo "nightly: no octocd binary at '$bin' (build first, or give --build DIR / \$OCTOCD_BIN)" >&2
  exit 2
fi
if [ ${#scenes[@]} -eq 0 ]; then
  scenes=("$root"/datasets/scenes/*.json)
fi
mkdir -p "$out/junit" || exit 2
rm -f "$out"/junit/*.xml  # this run's reports only

xml_escape() { sed -e 's/&/\&amp;/g' -e 's/</\&lt;/g' -e 's/>/\&gt;/g' -e 's/"/\&quot;/g' <<<"$1"; }

extra=()
if [ -n "$data_dir" ]; then extra+=(--data-dir "$data_dir"); fi

passed=0 failed=0 broken=0 bad=0
failed_list=() broken_list=() bad_list=()
for scene in "${scenes[@]}"; do
  name="$(basename "$scene" .json)"
  log="$out/$name.log"
  engine=()  # a rotating scene (rotation: true) runs only on Bullet with rotation (SPEC 13)
  if grep -q '"rotation": *true' "$scene"; then engine=(--engine bullet); fi
  "$bin" validate "$scene" --frames "$frames" --every "$every" --against "$against" \
    --junit "$out/junit/$name.xml" "${engine[@]}" "${extra[@]}" >"$log" 2>&1
  rc=$?
  if [ ! -s "$out/junit/$name.xml" ]; then
    # octocd wrote no report (it crashed, or the command line was refused): one errored case.
    n="$(xml_escape "$name")" msg="$(xml_escape "octocd validate exited $rc without a report; see $log")"
    cat >"$out/junit/$name.xml" <<EOF2
<?xml version="1.0" encoding="UTF-8"?>
<testsuites name="octocd validate" tests="1" failures="0" errors="1" skipped="0">
  <testsuite name="$n" tests="1" failures="0" errors="1" skipped="0">
    <testcase classname="$n" name="octocd" time="0">
      <error message="$msg" type="exit-$rc">$msg</error>
    </testcase>
  </testsuite>
</testsuites>
EOF2
  fi
  case $rc in
    0) passed=$((passed + 1)); echo "pass     $name" ;;
    3) failed=$((failed + 1)); failed_list+=("$name"); echo "FAILED   $name (a validator failed: $log)" ;;
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
  echo "<testsuites name=\"octocd nightly\" tests=\"$tests\" failures=\"$failures\" errors=\"$errors\" skipped=\"$skipped\">"
  for f in "$out"/junit/*.xml; do
    [ -e "$f" ] || continue
    sed -n '/^  <testsuite /,/^  <\/testsuite>/p' "$f"
  done
  echo '</testsuites>'
} >"$merged"

echo
echo "nightly: ${#scenes[@]} scenes: $passed passed, $failed failed, $broken errors, $bad bad input (JUnit: $merged)"
[ $failed -gt 0 ] && echo "nightly: validators failed on: ${failed_list[*]}"
[ $broken -gt 0 ] && echo "nightly: runs failed on: ${broken_list[*]}"
[ $bad -gt 0 ] && echo "nightly: bad input: ${bad_list[*]}"
if [ $bad -gt 0 ]; then exit 2; fi
if [ $broken -gt 0 ]; then exit 1; fi
if [ $failed -gt 0 ]; then exit 3; fi
exit 0
