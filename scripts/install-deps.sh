#!/usr/bin/env bash
# Installs octocd's dependencies from Debian 12's packages: what building `octocd`, its
# reports and its Python package need; with `--tests`, also what only the test suite runs
# (a headless browser, DART, a single-node Slurm). Idempotent: apt-get skips what is
# already installed. Runs apt-get through sudo when not root. `--list` prints the package
# list (with `--tests`: both sets) and exits.
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
PACKAGES=(
  # toolchain
  cmake ninja-build g++ pkg-config git xz-utils ca-certificates
  # the field's libraries
  libbullet-dev libfcl-dev libccd-dev libeigen3-dev libassimp-dev libqhull-dev
  libhdf5-dev hdf5-tools nlohmann-json3-dev libcli11-dev libfmt-dev libspdlog-dev
  # the linear programme of the physics tier's impulse-feasibility row (COIN-OR CLP)
  coinor-libclp-dev
  # the reference engines beyond Bullet (reference/mujoco, reference/ode; docs/engines.md):
  # 6.5 MB installed with their libraries (qhull, tinyxml2, lodepng), seconds of apt
  libmujoco-dev libode-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev libxml2-dev
  # reports (Debian's /usr/bin/python3) and the dataset split
  python3 python3-numpy python3-h5py python3-matplotlib python3-scipy
  # the Python package `import octocd` (python/, OCTOCD_PYTHON) and its pytest tests
  python3-dev python3-pybind11 python3-pytest
  # `octocd view` (three.js, inlined in its pages)
  libjs-three
  # `pip install --no-build-isolation .` (pyproject.toml, setup.py; docs/install.md)
  python3-pip python3-setuptools python3-wheel
)
# Only the test command's (README): each is large or a service, and nothing but a test uses it.
TEST_PACKAGES=(
  # `octocd view`'s headless-browser test (PIL reads the screenshot): chromium is ~300 MB
  chromium python3-pil
  # the reference engine DART (reference/dart; docs/engines.md): libdart-dev pulls in Boost
  libdart-dev
  # the single-node Slurm of the cluster test (scripts/slurm; docs/cluster.md)
  slurm-wlm munge
  # the process engines Rapier and Jolt (reference/rapier, reference/jolt; docs/engines.md):
  # Node.js runs them; their npm packages are pinned in reference/package-lock.json
  nodejs
)
LIST=0
TESTS=0
for arg in "$@"; do
  case "$arg" in
    --list) LIST=1 ;;
    --tests) PACKAGES+=("${TEST_PACKAGES[@]}"); TESTS=1 ;;
    *) echo "install-deps: unknown argument '$arg'; allowed: --tests, --list" >&2; exit 2 ;;
  esac
done
if [ "$LIST" = 1 ]; then echo "${PACKAGES[@]}"; exit 0; fi
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# datasets/fetch.sh needs npm (for the `bunny` package) and dpkg-deb.
command -v npm >/dev/null 2>&1 || missing+=(npm)
if [ "${#missing[@]}" -gt 0 ]; then
  echo "install-deps: installing ${missing[*]}"
  $SUDO apt-get update
  $SUDO apt-get install -y --no-install-recommends "${missing[@]}"
else
  echo "install-deps: all packages present"
fi
# The process engines' npm packages (reference/package-lock.json, into reference/node_modules),
# installed here and never at run time: skipped while both engines' --check passes.
if [ "$TESTS" = 1 ]; then
  ref="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/reference"
  if node "$ref/rapier/rapier_engine.js" --check >/dev/null 2>&1 && node "$ref/jolt/jolt_engine.js" --check >/dev/null 2>&1; then
    echo "install-deps: reference/node_modules present"
  else
    echo "install-deps: npm ci --prefix reference"
    npm ci --prefix "$ref" --no-audit --no-fund
  fi
fi
