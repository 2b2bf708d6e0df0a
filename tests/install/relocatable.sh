#!/usr/bin/env bash
# ctest install.relocatable (issue 32 item 7): an installed octocd needs no source tree.
# Installs the build's component `runtime` (bin/octocd, share/octocd) into a temporary
# prefix with `cmake --install` (nothing else is copied from the source tree), copies that prefix elsewhere and removes the first one (the
# install may be moved), then, with OCTOCD_SOURCE_DIR unset, the current folder outside
# both trees and, where a mount namespace can be made (unshare), the source tree hidden
# under an empty tmpfs, runs from the copy:
#   octocd bench table6 (cpu, 1 frame, 1 repetition)   its named sweep and scenes from share/octocd
#   octocd report on that result                       report/make_report.py and its
#                                                      report_*.py modules from share/octocd
#   octocd validate share/octocd/.../free-fall.json    an installed scene
#   share/octocd/datasets/fetch.sh --help              the installed fetch script
# and checks their outputs. The meshes come from OCTOCD_DATA_DIR (default: the source
# tree's datasets/cache, reached before the tree is hidden); without them bench table6 is
# left out, saying so. Usage: relocatable.sh CMAKE BUILD_DIR SOURCE_DIR
set -euo pipefail
cmake_bin=$1 build=$2 src=$(realpath "$3")

# Re-run inside a private mount namespace when one can be made, to hide the source tree.
# The inner run gets the outer namespace's id and mounts only when its own differs.
outer_ns=${OCTOCD_RELOCATABLE_OUTER_NS:-}
if [ -z "$outer_ns" ]; then
  for flags in -m -rm; do
    if unshare "$flags" true 2>/dev/null; then
      exec unshare "$flags" env OCTOCD_RELOCATABLE_OUTER_NS="$(readlink /proc/self/ns/mnt)" bash "$0" "$@"
    fi
  done
fi
if [ -n "$outer_ns" ] && [ "$(readlink /proc/self/ns/mnt)" != "$outer_ns" ]; then
  hide=""
else
  hide="no mount namespace (unshare failed): the source tree stays reachable, OCTOCD_SOURCE_DIR unset and cwd elsewhere only"
fi

work=$(mktemp -d "${TMPDIR:-/tmp}/octocd-relocatable.XXXXXX")
trap 'cd /; rm -rf --one-file-system "$work"' EXIT
"$cmake_bin" --install "$build" --prefix "$work/installed" --component runtime >/dev/null
cp -a "$work/installed" "$work/moved"
rm -rf "$work/installed"
prefix="$work/moved"
share="$prefix/share/octocd"
for f in bin/octocd share/octocd/bench/sweeps/table6.json share/octocd/datasets/scenes/bunny-random-400.json \
         share/octocd/datasets/scenes/free-fall.json share/octocd/report/make_report.py \
         share/octocd/report/paper_tables.json share/octocd/datasets/fetch.sh share/octocd/datasets/SHA256SUMS; do
  [ -e "$prefix/$f" ] || { echo "not installed: $prefix/$f"; exit 1; }
done
[ -x "$share/datasets/fetch.sh" ] || { echo "$share/datasets/fetch.sh is not executable"; exit 1; }
# Every module of the report (report/report_*.py in the source tree) beside make_report.py.
for m in "$src"/report/report_*.py; do
  [ -e "$share/report/$(basename "$m")" ] || { echo "not installed: $share/report/$(basename "$m")"; exit 1; }
done

data=$(realpath -m "${OCTOCD_DATA_DIR:-$src/datasets/cache}")
have_meshes=1
for m in bunny.obj armadillo.off dragon.off asian-dragon.off; do [ -s "$data/$m" ] || have_meshes=0; done
if [ -z "$hide" ]; then
  # The meshes stay reachable through an open descriptor (no mount: nothing under $work
  # may lead into the data, which the cleanup would then delete); then the source tree
  # (and a build tree inside it) is replaced by an empty folder for everything run here.
  if [ "$have_meshes" = 1 ]; then
    exec 9<"$data"
    data=/proc/self/fd/9
  fi
  mount -t tmpfs -o size=1m octocd-hidden "$src"
  [ -z "$(ls -A "$src")" ] || { echo "the source tree $src is still visible"; exit 1; }
  echo "install.relocatable: source tree $src hidden (empty tmpfs)"
else
  echo "install.relocatable: $hide"
fi

mkdir "$work/cwd"
cd "$work/cwd"
unset OCTOCD_SOURCE_DIR OCTOCD_REPORT_SCRIPT
export OCTOCD_DATA_DIR="$data"
octocd="$prefix/bin/octocd"

# validate: an installed box scene, every validator passes (exit 0), the JSON names it.
rc=0
"$octocd" validate "$share/datasets/scenes/free-fall.json" --frames 100 --json v.json >validate.txt 2>&1 || rc=$?
[ "$rc" -eq 0 ] || { cat validate.txt; echo "validate exited $rc, expected 0"; exit 1; }
grep -q "all validators pass" validate.txt || { cat validate.txt; echo "validate: no 'all validators pass'"; exit 1; }

# fetch.sh runs from the prefix (its usage; fetching itself needs the network).
"$share/datasets/fetch.sh" --help | grep -q "datasets" || { echo "fetch.sh --help printed no usage"; exit 1; }

# bench: the named sweep from share/octocd; without the meshes, a stand-in result of the
# same format for report (tests/data is not reachable: a one-point steps sweep on a box scene).
if [ "$have_meshes" = 1 ]; then
  "$octocd" bench table6 --engines cpu --frames 1 --warmup 0 --repeat 1 -o t6.json --quiet
  /usr/bin/python3 - t6.json <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
assert r["sweep"]["name"] == "table6" and r["sweep"]["origin"] == "sweep 'table6'", r["sweep"]
assert r["complete"] is True
ids = [p["id"] for p in r["points"]]
want = [f"{s} | midphase={m} | cpu" for s in ("bunny-random-400", "armadillo-random-250", "dragon-random-250",
        "asian-dragon-random-60") for m in ("aabb-only", "0,1,2")]
assert ids == want, ids
assert all(p["status"] == "ok" for p in r["points"]), [(p["id"], p.get("reason")) for p in r["points"]]
PY
  result=t6.json
else
  echo "install.relocatable: bench table6 left out: the meshes are not in $data (datasets/fetch.sh)"
  "$octocd" bench "$share/bench/sweeps/table6.json" --print >/dev/null
  cat >one.json <<EOF
{"name": "one", "scenes": ["$share/datasets/scenes/free-fall.json"], "engines": ["cpu"], "frames": 2, "warmup": 0, "repeat": 1}
EOF
  "$octocd" bench one.json -o t6.json --quiet
  result=t6.json
fi

# report: the generator from share/octocd writes index.html and report.md.
rc=0
"$octocd" report "$result" -o report >report.txt 2>&1 || rc=$?
[ "$rc" -eq 0 ] || { cat report.txt; echo "report exited $rc, expected 0"; exit 1; }
for f in report/index.html report/report.md; do [ -s "$f" ] || { echo "report: $f missing or empty"; exit 1; }; done
if [ "$have_meshes" = 1 ]; then
  grep -q "bunny-random-400" report/report.md || { echo "report.md does not name bunny-random-400"; exit 1; }
fi
echo "install.relocatable: ok (prefix moved; bench, report, validate and fetch.sh from $prefix)"
