#!/usr/bin/env bash
# ctest install.pip (issue 32 item 7): `pip install --no-build-isolation --target DIR .`
# builds the Python package with the project's CMake build (setup.py: the target
# octocd_python in SOURCE/build-pip/cmake, CUDA off here) and installs it into a temporary
# folder; then, from another folder and with nothing else on PYTHONPATH, `import octocd`
# must come from that folder and step a shipped box scene (a body in free fall moves down
# by g t^2 / 2 within float32 rounding). Exit 77 (skipped, with the reason) when Debian's
# python3-pip, python3-setuptools or python3-wheel is missing.
# Usage: pip.sh PYTHON SOURCE_DIR
set -euo pipefail
py=$1 src=$(realpath "$2")
missing=()
for p in python3-pip python3-setuptools python3-wheel; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "install.pip: skipped: Debian's ${missing[*]} not installed (scripts/install-deps.sh installs them)"
  exit 77
fi

work=$(mktemp -d "${TMPDIR:-/tmp}/octocd-pip.XXXXXX")
trap 'cd /; rm -rf --one-file-system "$work"' EXIT
args="-DOCTOCD_CUDA=OFF"
if command -v ccache >/dev/null 2>&1; then
  args="$args -DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache"
fi
cd "$src"
start=$(date +%s)
CMAKE_ARGS="$args" CMAKE_BUILD_PARALLEL_LEVEL="${CMAKE_BUILD_PARALLEL_LEVEL:-2}" \
  "$py" -m pip install --no-build-isolation --no-deps --no-index --target "$work/site" . >"$work/pip.log" 2>&1 ||
  { tail -40 "$work/pip.log"; echo "install.pip: pip install failed"; exit 1; }
echo "install.pip: pip install took $(( $(date +%s) - start )) s"
ls "$work"/site/octocd/_octocd*.so >/dev/null || { echo "no extension in $work/site/octocd"; exit 1; }

mkdir "$work/cwd"
cd "$work/cwd"
PYTHONPATH="$work/site" "$py" - "$work/site" "$src/datasets/scenes/free-fall.json" <<'PY'
import os, sys
import octocd
site, scene = sys.argv[1], sys.argv[2]
where = os.path.dirname(os.path.abspath(octocd.__file__))
assert where == os.path.join(site, "octocd"), f"octocd imported from {where}, not from {site}"
assert "cpu" in octocd.engines, octocd.engines
s = octocd.load_scene(scene)
e = octocd.Engine(s, engine="cpu")
y0 = float(e.positions[0][1])
e.step(10)
y = float(e.positions[0][1])
t = 10 * s.dt
# Explicit Euler (Eq. 1-3): after k steps y = y0 + v0 t - g dt^2 k (k + 1) / 2, with v0 = 0 here.
g = -s.gravity[1]
want = y0 - g * s.dt * s.dt * 10 * 11 / 2
assert abs(y - want) <= 1e-6 * max(1.0, abs(y0)), (y0, y, want)
print(f"install.pip: octocd {octocd.build_id} from {where}: free fall {y0:.6f} -> {y:.6f} m in {t:g} s")
PY
