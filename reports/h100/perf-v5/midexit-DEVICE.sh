#!/usr/bin/env bash
# DEVICE.sh R: branch midexit (issue 20 item 3: the GPU midphase's per-pair early exit,
# OCTOCD_CUDA_MID_EARLY_EXIT) on the H100, run from inside an extracted bundle folder made
# by scripts/gpu-bundle.sh (bin/octocd, bin/test_cuda_world, bin/bench_step_paths,
# datasets/). Logs and JSON go to R. Every command has a timeout, each clipped to what is
# left of a 520 s budget, so the script ends within 9 minutes (expected about 6).
# Order: correctness with the exit on (the default), the Table 5 scenes with the exit on and
# off (`octocd bench`, 1000 frames x 5), bunny-pile-100k (3000 frames) on and off, the Table 5
# scenes with the tile culling off (exit on, and exit off: main's midphase), the count-equality tests with
# the exit off, compute-sanitizer racecheck / memcheck on bunny-random-400, and last (if time
# is left) bench_step_paths on the Table 5 scenes (graph and resident small path, on and off).
set -u
R=${1:?usage: DEVICE.sh RESULTS_DIR}
mkdir -p "$R"
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
cp VERSION "$R/" 2>/dev/null
timeout 20 nvidia-smi --query-gpu=name,driver_version,clocks.max.sm --format=csv > "$R/device.txt" 2>&1
BUDGET=520
# s NAME CMD...: run CMD with timeout min(TMO, what is left), output to R/NAME.txt.
s() {
  local name=$1; shift
  local left=$((BUDGET - SECONDS)); local t=${TMO:-120}; ((t > left)) && t=$left
  if ((t < 15)); then echo "$name skipped: budget spent"; return; fi
  local t0=$SECONDS; timeout "$t" "$@" > "$R/$name.txt" 2>&1; echo "$name rc=$? $((SECONDS - t0)) s (limit $t s)"
}
S=datasets/scenes
T5="bunny-random-400 armadillo-random-250 dragon-random-250 asian-dragon-random-60"

# 1. Correctness with the early exit on: the new CudaMidphase.EarlyExit* (cpu vs exit off vs
# exit on: graph, fused leaves, small path; bits, records, counts on <= off), the fused-leaf
# test, the small path's grids, and every suite on the Table 5 scenes and the piles
# (CpuVsCuda, CudaRerun incl. capacity 1, CudaOctree, CpuVsCudaScale bunny-pile-10k).
F='CudaMidphase.*:CudaSmallStep.*:*bunny_random_400*:*armadillo_random_250*:*dragon_random_250*:*asian_dragon_random_60*:*bunny_pile*'
TMO=200 s tests_exit_on env OCTOCD_CUDA_MID_EARLY_EXIT=1 bin/test_cuda_world --gtest_filter="$F"
grep -h "PASSED\|FAILED\|\[ info \].*exit on\|tests, listed" "$R/tests_exit_on.txt" | head -30

# 2. Table 5 scenes with [1,2], cuda engine, 30 + 1000 frames x 5, exit on then off.
cat > "$R/table5-12.json" <<'EOF'
{"name": "table5-12", "kind": "steps",
 "description": "Table 5 scenes with midphase [1,2] on the cuda engine (DEVICE.sh of branch midexit)",
 "engines": ["cuda"], "frames": 1000, "warmup": 30, "repeat": 5,
 "scenes": ["bunny-random-400", "armadillo-random-250", "dragon-random-250", "asian-dragon-random-60"],
 "axes": [{"name": "midphase", "values": ["1,2"], "labels": ["B"]}]}
EOF
# table5 V ENV...: the sweep with the environment ENV, result R/table5-V.json.
table5() {
  local v=$1; shift
  TMO=100 s bench_$v env "$@" OCTOCD_CUDA_STAGE_TIMES=0 bin/octocd bench "$R/table5-12.json" --quiet -o "$R/table5-$v.json"
}
# t5_table V...: steps/s median (min-max) and vertex tests per frame of each variant.
t5_table() {
  timeout 10 python3 - "$R" "$@" <<'EOF'
import json, os, sys
r, variants = sys.argv[1], sys.argv[2:]
rows = {}
for v in variants:
    f = os.path.join(r, f"table5-{v}.json")
    if not os.path.exists(f): continue
    for p in json.load(open(f))["points"]:
        if p.get("status") != "ok": print("  ", v, p["id"], p.get("status"), p.get("reason", "")); continue
        w = p["windows"]["all"]; s = w["steps_per_s"]
        rows.setdefault(p["params"]["scene"], {})[v] = (s["median"], s["min"], s["max"], w["vertex_tests"]["median"])
print("| scene | " + " | ".join(f"{v}: steps/s (min-max), vertex tests/frame" for v in variants) + " |")
print("|---|" + "---:|" * len(variants))
for sc, d in rows.items():
    cells = [f"{d[v][0]:,.0f} ({d[v][1]:,.0f}-{d[v][2]:,.0f}), {d[v][3]:,.0f}" if v in d else "-" for v in variants]
    print(f"| {sc} | " + " | ".join(cells) + " |")
EOF
}
table5 exit1 OCTOCD_CUDA_MID_EARLY_EXIT=1
table5 exit0 OCTOCD_CUDA_MID_EARLY_EXIT=0
t5_table exit1 exit0

# 3. bunny-pile-100k, 3000 frames (target >= 150 steps/s), exit on and off; with the exit
# off the counts must equal main's (reports/h100/midphase-v3: the same as f70290f).
for x in 1 0; do
  TMO=80 s pile100k_exit$x env OCTOCD_CUDA_MID_EARLY_EXIT=$x OCTOCD_CUDA_STAGE_TIMES=0 bin/octocd run \
    $S/bunny-pile-100k.json --engine cuda --frames 3000 --quiet --summary-json "$R/pile100k_exit$x.json"
  [ -f "$R/pile100k_exit$x.json" ] && timeout 10 python3 - "$R/pile100k_exit$x.json" $x <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
ref = (3785953.8696666667, 572388927.6763333, 103149.49133333334, 240315.0273213507)
got = (d["mean_box_pairs"], d["mean_vertex_tests"], d["mean_contacts"], d["kinetic_energy"]["last"])
same = ("SAME as main" if ref == got else f"DIFFERENT from main {ref}") if sys.argv[2] == "0" else (
    "contacts and last KE " + ("SAME as main" if ref[2:] == got[2:] else f"DIFFERENT from main {ref[2:]}"))
print(f"  exit={sys.argv[2]}: {d['steps_per_s']:.2f} steps/s, mean step {d['mean_step_ms']:.3f} ms; box pairs {got[0]!r}, "
      f"vertex tests {got[1]!r}, contacts {got[2]!r}, last KE {got[3]!r}: {same}")
EOF
done

# 3b. The Table 5 scenes with the exit on and no tile culling (OCTOCD_CUDA_MID_TILE_CULL=0),
# then with neither the exit nor the culling (as main before this branch). (The fused leaves
# on the small path, OCTOCD_CUDA_MID_FUSE=1, measured 1.3-13x slower at 67279b5: not rerun.)
table5 exit1cull0 OCTOCD_CUDA_MID_EARLY_EXIT=1 OCTOCD_CUDA_MID_TILE_CULL=0
table5 exit0cull0 OCTOCD_CUDA_MID_EARLY_EXIT=0 OCTOCD_CUDA_MID_TILE_CULL=0
t5_table exit1 exit0 exit1cull0 exit0cull0

# 4. The exact count comparisons with the exit off (rerun and capacity 1, small path grids,
# fuse 0 vs 1): the counts are deterministic again.
F0='CudaMidphase.Leaves*:CudaSmallStep.*:*CudaRerun*bunny_random_400*:*CudaRerun*dragon_random_250*'
TMO=120 s tests_exit_off env OCTOCD_CUDA_MID_EARLY_EXIT=0 bin/test_cuda_world --gtest_filter="$F0"
grep -h "PASSED\|FAILED\|tests, listed" "$R/tests_exit_off.txt" | head -12

# 4b. Sanitizers on the new device code (the exit's checks, the deepest-first fused leaves,
# the tile boxes' shuffles): racecheck on the graph path with fused leaves and on the small
# path with fused leaves (its kFuse kernel), memcheck on the small path's leaf list;
# bunny-random-400 with 1,2 for 40 frames (contacts from the first frames).
for v in "racecheck graph 0" "racecheck small 1" "memcheck small 1"; do
  set -- $v
  TMO=70 s san_$1_$2 env OCTOCD_CUDA_SMALL=$3 OCTOCD_CUDA_STAGE_TIMES=0 OCTOCD_CUDA_MID_FUSE=$([ $1 = memcheck ] && echo 0 || echo 1) \
    compute-sanitizer --tool $1 bin/octocd run $S/bunny-random-400.json --midphase 1,2 --engine cuda --frames 40 --quiet
  grep -h "SUMMARY" "$R/san_$1_$2.txt"
done

# 5. If time is left: bench_step_paths (graph path and resident small path in one process,
# one state hash per scene and path: equal on and off).
for x in 1 0; do
  TMO=60 s paths_exit$x env OCTOCD_CUDA_MID_EARLY_EXIT=$x bin/bench_step_paths $(for n in $T5; do echo $S/$n.json; done) \
    --midphase 1,2 --engines graph,persistent --frames 1000 --repeat 3
  grep "^|" "$R/paths_exit$x.txt" | tail -10
done
echo "total $SECONDS s"
