#!/usr/bin/env bash
# Fetches, verifies (SHA-256) and caches the octocd mesh datasets (design.md section 10).
#
#   datasets/fetch.sh                 # all datasets
#   datasets/fetch.sh --only bunny    # a subset: bunny armadillo dragon asian-dragon
#
# Cache: datasets/cache/ (git-ignored; override with OCTOCD_DATA_DIR). Idempotent: a file
# already in the cache with the right checksum is reused ("cached"). Every checksum, of
# the downloaded sources and of the produced meshes, is in datasets/SHA256SUMS.
# Needs: npm + node (bunny), apt-get + dpkg-deb + tar (armadillo, dragons),
# /usr/bin/python3 with numpy (dragons). It installs nothing; see datasets/README.md.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
CACHE="${OCTOCD_DATA_DIR:-$HERE/cache}"
SRC="$CACHE/sources"
SUMS="$HERE/SHA256SUMS"
PYTHON=/usr/bin/python3
ALL=(bunny armadillo dragon asian-dragon)

BUNNY_PKG="bunny@1.0.1"
CGAL_DEB="libcgal-demo"
CGAL_DATA="usr/share/doc/libcgal-dev/data.tar.gz"

die() { echo "fetch.sh: error: $*" >&2; exit 1; }

usage() {
  sed -n '2,11p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
}

# ---- arguments ---------------------------------------------------------------
WANT=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --only)
      shift
      [[ $# -gt 0 && "$1" != -* ]] || die "--only needs at least one name (${ALL[*]})"
      while [[ $# -gt 0 && "$1" != -* ]]; do WANT+=("$1"); shift; done
      ;;
    -h|--help) usage; exit 0 ;;
    *) die "unknown argument '$1' (expected --only NAME... or --help)" ;;
  esac
done
[[ ${#WANT[@]} -gt 0 ]] || WANT=("${ALL[@]}")
for n in "${WANT[@]}"; do
  [[ " ${ALL[*]} " == *" $n "* ]] || die "unknown dataset '$n' (expected one of: ${ALL[*]})"
done

# ---- helpers -----------------------------------------------------------------
[[ -f "$SUMS" ]] || die "checksum list '$SUMS' is missing"
command -v sha256sum >/dev/null || die "sha256sum not found (coreutils)"

expected_sum() {  # file name -> its SHA-256 from SHA256SUMS
  local s
  s="$(awk -v f="$1" '$2 == f || $2 == "*"f { print $1 }' "$SUMS")"
  [[ -n "$s" ]] || die "no checksum for '$1' in $SUMS"
  echo "$s"
}

sum_ok() {  # path name -> 0 when the file exists with the expected checksum
  [[ -f "$1" ]] && [[ "$(sha256sum "$1" | cut -d' ' -f1)" == "$(expected_sum "$2")" ]]
}

verify() {  # dataset path name source: dies on mismatch
  local got want
  got="$(sha256sum "$2" | cut -d' ' -f1)"
  want="$(expected_sum "$3")"
  if [[ "$got" != "$want" ]]; then
    rm -f "$2"
    die "dataset '$1': checksum mismatch for '$3' from $4 (expected $want, got $got)"
  fi
}

need_tools() {  # dataset tool...
  local d="$1" t; shift
  for t in "$@"; do
    command -v "$t" >/dev/null 2>&1 || \
      die "dataset '$d': '$t' not found; install it first (see datasets/README.md)"
  done
}

TMP=""
cleanup() { [[ -z "$TMP" ]] || rm -rf "$TMP"; }
trap cleanup EXIT
tmpdir() { [[ -n "$TMP" ]] || TMP="$(mktemp -d "${TMPDIR:-/tmp}/octocd-fetch.XXXXXX")"; }

mkdir -p "$CACHE" "$SRC"

# ---- sources -----------------------------------------------------------------
# The CGAL data files: data/meshes/<file> from libcgal-demo's data.tar.gz, into sources/.
cgal_source() {  # dataset file
  local d="$1" f="$2" from="Debian package $CGAL_DEB ($CGAL_DATA: data/meshes/$2)"
  if sum_ok "$SRC/$f" "$f"; then return 0; fi
  need_tools "$d" apt-get dpkg-deb tar
  tmpdir
  local deb_dir="$TMP/deb"
  if ! compgen -G "$deb_dir/${CGAL_DEB}_*.deb" >/dev/null; then
    mkdir -p "$deb_dir"
    chmod 755 "$TMP" && chmod 777 "$deb_dir"  # lets apt's sandbox user write there
    echo "  downloading Debian package $CGAL_DEB ..."
    if ! (cd "$deb_dir" && apt-get download "$CGAL_DEB" >"$TMP/apt.log" 2>&1); then
      echo "  apt-get download failed; running apt-get update and retrying ..."
      if ! { apt-get update >>"$TMP/apt.log" 2>&1 &&
             (cd "$deb_dir" && apt-get download "$CGAL_DEB" >>"$TMP/apt.log" 2>&1); }; then
        tail -n 5 "$TMP/apt.log" >&2
        die "dataset '$d': cannot download Debian package $CGAL_DEB (apt-get download; see above)"
      fi
    fi
    dpkg-deb -x "$deb_dir"/${CGAL_DEB}_*.deb "$TMP/root" ||
      die "dataset '$d': cannot unpack $CGAL_DEB .deb"
    [[ -f "$TMP/root/$CGAL_DATA" ]] ||
      die "dataset '$d': $CGAL_DEB has no $CGAL_DATA (package layout changed?)"
  fi
  tar -xzf "$TMP/root/$CGAL_DATA" -C "$TMP" "data/meshes/$f" ||
    die "dataset '$d': '$f' not found in $from"
  verify "$d" "$TMP/data/meshes/$f" "$f" "$from"
  mv "$TMP/data/meshes/$f" "$SRC/$f"
}

# ---- datasets ----------------------------------------------------------------
# Each builds $CACHE/<out> from its sources; the caller verifies the result.

build_bunny() {  # npm bunny@1.0.1: index.js exports {positions, cells} -> OBJ
  local tgz="bunny-1.0.1.tgz" from="npm package $BUNNY_PKG"
  need_tools bunny npm node tar
  tmpdir
  if ! sum_ok "$SRC/$tgz" "$tgz"; then
    echo "  npm pack $BUNNY_PKG ..."
    mkdir -p "$TMP/npm"
    (cd "$TMP/npm" && npm pack --loglevel=error --fetch-retries=1 --fetch-retry-mintimeout=2000 \
        --fetch-retry-maxtimeout=5000 --fetch-timeout=60000 "$BUNNY_PKG" >"$TMP/npm.log" 2>&1) || {
      tail -n 5 "$TMP/npm.log" >&2
      die "dataset 'bunny': cannot fetch $from from the npm registry (npm pack; see above)"
    }
    [[ -f "$TMP/npm/$tgz" ]] || die "dataset 'bunny': npm pack did not produce $tgz"
    verify bunny "$TMP/npm/$tgz" "$tgz" "$from"
    mv "$TMP/npm/$tgz" "$SRC/$tgz"
  fi
  mkdir -p "$TMP/bunny"
  tar -xzf "$SRC/$tgz" -C "$TMP/bunny"
  node -e '
    const b = require(process.argv[1]);
    const out = ["# bunny: npm package bunny@1.0.1 (index.js positions/cells)"];
    for (const p of b.positions) out.push("v " + p[0] + " " + p[1] + " " + p[2]);
    for (const c of b.cells) {
      if (c.length !== 3) throw new Error("non-triangle cell");
      out.push("f " + (c[0] + 1) + " " + (c[1] + 1) + " " + (c[2] + 1));
    }
    process.stdout.write(out.join("\n") + "\n");
  ' "$TMP/bunny/package/index.js" >"$CACHE/bunny.obj.tmp" ||
    die "dataset 'bunny': converting $from to OBJ failed"
  mv "$CACHE/bunny.obj.tmp" "$CACHE/bunny.obj"
}

build_armadillo() {
  cgal_source armadillo armadillo.off
  cp "$SRC/armadillo.off" "$CACHE/armadillo.off.tmp"
  mv "$CACHE/armadillo.off.tmp" "$CACHE/armadillo.off"
}

build_split_dragon() {  # dataset times
  cgal_source "$1" ChineseDragon-10kv.off
  [[ -x "$PYTHON" ]] || die "dataset '$1': $PYTHON not found"
  "$PYTHON" -c 'import numpy' 2>/dev/null || die "dataset '$1': numpy missing for $PYTHON"
  "$PYTHON" "$HERE/split_mesh.py" "$SRC/ChineseDragon-10kv.off" "$CACHE/$1.off.tmp" \
    --times "$2" >/dev/null || die "dataset '$1': split_mesh.py failed"
  mv "$CACHE/$1.off.tmp" "$CACHE/$1.off"
}

build_dragon() { build_split_dragon dragon 1; }
build_asian-dragon() { build_split_dragon asian-dragon 2; }

out_file() {
  case "$1" in
    bunny) echo bunny.obj ;;
    *) echo "$1.off" ;;
  esac
}

source_of() {
  case "$1" in
    bunny) echo "npm package $BUNNY_PKG, converted to OBJ" ;;
    armadillo) echo "Debian package $CGAL_DEB (data/meshes/armadillo.off)" ;;
    dragon) echo "$CGAL_DEB ChineseDragon-10kv.off split 1-to-4 once by split_mesh.py" ;;
    asian-dragon) echo "$CGAL_DEB ChineseDragon-10kv.off split 1-to-4 twice by split_mesh.py" ;;
  esac
}

counts() {  # file -> "vertices triangles" as written in the file
  case "$1" in
    *.obj) awk '$1 == "v" { v++ } $1 == "f" { f += NF - 3 } END { print v + 0, f + 0 }' "$1" ;;
    *.off) awk '{ sub(/#.*/, "") } NF == 0 { next } !h { h = 1; if ($1 == "OFF" && NF == 1) next;
                 if ($1 == "OFF") { print $2, $3; exit } }
                h { print $1, $2; exit }' "$1" ;;
  esac
}

for n in "${WANT[@]}"; do
  out="$(out_file "$n")"
  if sum_ok "$CACHE/$out" "$out"; then
    echo "$n: cached ($CACHE/$out)"
    continue
  fi
  echo "$n: fetching from $(source_of "$n") ..."
  "build_$n"
  verify "$n" "$CACHE/$out" "$out" "$(source_of "$n")"
  echo "$n: ok ($CACHE/$out)"
done

echo
printf '%-14s %10s %10s  %s\n' dataset vertices triangles file
for n in "${WANT[@]}"; do
  out="$(out_file "$n")"
  read -r v t < <(counts "$CACHE/$out")
  printf '%-14s %10s %10s  %s\n' "$n" "$v" "$t" "$out"
done
