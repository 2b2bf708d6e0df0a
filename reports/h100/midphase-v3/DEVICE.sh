#!/usr/bin/env bash
# DEVICE.sh R: branch pilemid (issue 20 items 3-4, the midphase) on the H100, run from inside
# an extracted bundle folder (bin/octocd, bin/test_cuda_world, bin/bench_step_paths,
# datasets/). Logs and JSON go to R. Every command has a timeout, each clipped to what is
# left of a 530 s budget, so the script ends within 9 minutes (expected about 6-7).
# Order: correctness first (tests, sanitizers on the fused leaves), then the piles, the
# Table 5 scenes, and last (only if time is left) the piles with OCTOCD_CUDA_MID_FUSE=0 so
# the fused and list leaves can be compared.
set -u
R=${1:?usage: DEVICE.sh RESULTS_DIR}
mkdir -p "$R"
export OCTOCD_SOURCE_DIR=$PWD OCTOCD_BIN=$PWD/bin/octocd OCTOCD_DATA_DIR=$PWD/datasets/cache OMP_NUM_THREADS=16
cp REVISION "$R/" 2>/dev/null
timeout 20 nvidia-smi --query-gpu=name,driver_version,clocks.max.sm --format=csv > "$R/device.txt" 2>&1
BUDGET=530
# s NAME CMD...: run CMD with timeout min(TMO, what is left), output to R/NAME.txt.
s() {
  local name=$1; shift
  local left=$((BUDGET - SECONDS)); local t=${TMO:-120}; ((t > left)) && t=$left
  if ((t < 15)); then echo "$name skipped: budget spent"; return; fi
  local t0=$SECONDS; timeout "$t" "$@" > "$R/$name.txt" 2>&1; echo "$name rc=$? $((SECONDS - t0)) s (limit $t s)"
}
# pile NAME SCENE FRAMES: OCTOCD_CUDA_STAGE_TIMES=0 timed run, summary JSON R/NAME.json
# (PILE_ENV: more VAR=VALUE for the run).
pile() {
  local name=$1 scene=$2 frames=$3
  s "$name" env ${PILE_ENV:-} OCTOCD_CUDA_STAGE_TIMES=0 bin/octocd run "datasets/scenes/$scene.json" --engine cuda --frames "$frames" \
    --quiet --summary-json "$R/$name.json"
  [ -f "$R/$name.json" ] && timeout 10 python3 - "$R/$name.json" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
# The same bits and counts as main (reports/h100/step-paths/run2, f70290f): the counts and
# the last kinetic energy are fingerprints of the whole run.
ref = {"bunny-pile-100k": (3785953.8696666667, 572388927.6763333, 103149.49133333334, 240315.0273213507),
       "bunny-pile-1m": (27133463.027333334, 4304770550.49, 704094.562, 15083889.653146317)}.get(d["scene"])
got = (d["mean_box_pairs"], d["mean_vertex_tests"], d["mean_contacts"], d["kinetic_energy"]["last"])
same = "n/a" if ref is None or d["frames"] != {"bunny-pile-100k": 3000, "bunny-pile-1m": 1500}[d["scene"]] else (
    "SAME as main" if ref == got else f"DIFFERENT from main {ref}")
print(f"  {d['scene']} {d['frames']} frames: {d['steps_per_s']:.2f} steps/s, mean step {d['mean_step_ms']:.2f} ms; "
      f"box pairs {got[0]!r}, vertex tests {got[1]!r}, contacts {got[2]!r}, last KE {got[3]!r}: {same}")
EOF
}

# 1. Correctness: every GPU test (CPU vs CUDA bit for bit on every scene and path; the new
# CudaMidphase test runs OCTOCD_CUDA_MID_FUSE=0 and =1 against the CPU, counts equal).
TMO=150 s test_cuda_world bin/test_cuda_world
grep -h "PASSED\|FAILED\|CudaMidphase" "$R/test_cuda_world.txt" | head -12
# 2. Sanitizers on the graph path with the leaves run by the last expand step (shared
# tiles in mid_expand_last_kernel; OCTOCD_CUDA_MID_FUSE=1) and on the small path (the list
# leaves, mid_leaf_items), bunny-stack-50: mesh-mesh and mesh-box contacts from the start.
TMO=70 s memcheck_fused env OCTOCD_CUDA_SMALL=0 OCTOCD_CUDA_STAGE_TIMES=0 OCTOCD_CUDA_MID_FUSE=1 \
  compute-sanitizer --tool memcheck bin/octocd run datasets/scenes/bunny-stack-50.json --engine cuda --frames 200 --quiet
grep -h "SUMMARY" "$R/memcheck_fused.txt"
TMO=70 s racecheck_fused env OCTOCD_CUDA_SMALL=0 OCTOCD_CUDA_STAGE_TIMES=0 OCTOCD_CUDA_MID_FUSE=1 \
  compute-sanitizer --tool racecheck bin/octocd run datasets/scenes/bunny-stack-50.json --engine cuda --frames 100 --quiet
grep -h "SUMMARY" "$R/racecheck_fused.txt"
TMO=60 s racecheck_small env OCTOCD_CUDA_SMALL=1 OCTOCD_CUDA_STAGE_TIMES=0 \
  compute-sanitizer --tool racecheck bin/octocd run datasets/scenes/bunny-stack-50.json --engine cuda --frames 100 --quiet
grep -h "SUMMARY" "$R/racecheck_small.txt"
# 3. The settled piles (targets 150 and 30 steps/s; main: 58.1 and 8.49).
TMO=150 pile pile100k bunny-pile-100k 3000
TMO=300 pile pile1m bunny-pile-1m 1500
# 4. Table 5 scenes with [1,2] (target 15,000 steps/s each; main small path: armadillo 10,104,
# dragon 8,581, asian-dragon 3,787, bunny-random-400 16,393): graph and small paths in one
# process, 1000 frames x 5, one state hash per scene.
TMO=150 s table5 bin/bench_step_paths datasets/scenes/bunny-random-400.json datasets/scenes/armadillo-random-250.json \
  datasets/scenes/dragon-random-250.json datasets/scenes/asian-dragon-random-60.json --midphase 1,2 \
  --engines graph,small --frames 1000 --repeat 5
grep "^|" "$R/table5.txt" | tail -10
# The final state hashes of main's run (reports/h100/step-paths/run2/table5.txt): the same bits.
for h in 2daa51a7162926d0 d60aafcb59e7411f d3b6771b90787e67 fb1307ac00df391b; do
  printf '  hash %s: %s lines\n' "$h" "$(grep -c "$h" "$R/table5.txt" 2>/dev/null)"
done
# 5. If time is left: the list leaves on the 100k pile (the fused leaves' effect).
PILE_ENV=OCTOCD_CUDA_MID_FUSE=0 TMO=150 pile pile100k_fuse0 bunny-pile-100k 3000
echo "total $SECONDS s"
