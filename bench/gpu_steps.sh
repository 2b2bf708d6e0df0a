#!/usr/bin/env bash
# steps/s of every Table 5 scene (and bunny-stack-50) with midphase [1,2] and aabb-only,
# for the `cpu` and `cuda` engines of one octocd binary, in one script on one machine.
# Usage: bench/gpu_steps.sh OCTOCD SCENE_DIR FRAMES OUTDIR  -> OUTDIR/steps.md, steps.json
set -eu
octocd=$1; scenes=$2; frames=$3; out=$4
tmp=$(mktemp -d)
for s in bunny-stack-50 bunny-random-400 armadillo-random-250 dragon-random-250 asian-dragon-random-60; do
  for m in 1,2 aabb-only; do
    for e in cpu cuda; do
      "$octocd" run "$scenes/$s.json" --engine $e --midphase $m --frames "$frames" --quiet \
        --summary-json "$tmp/$s.$m.$e.json" || echo "{\"failed\": true}" > "$tmp/$s.$m.$e.json"
    done
  done
done
/usr/bin/env python3 - "$tmp" "$out" <<'PY'
import json, os, sys
tmp, out = sys.argv[1], sys.argv[2]
rows, allj = [], {}
for f in sorted(os.listdir(tmp)):
    allj[f] = json.load(open(os.path.join(tmp, f)))
stages = ["integrate", "aabbs", "broadphase", "midphase", "response", "metrics"]
lines = ["| scene | midphase | cpu steps/s | cuda steps/s | cuda/cpu | cuda stage ms (" + ", ".join(stages) + ") |",
         "|---|---|---|---|---|---|"]
for key in sorted({k.rsplit(".", 2)[0] for k in allj}):
    c, g = allj.get(key + ".cpu.json", {}), allj.get(key + ".cuda.json", {})
    sc, mid = key.rsplit(".", 1)
    cs, gs = c.get("steps_per_s", 0), g.get("steps_per_s", 0)
    st = ", ".join(f"{g.get('stage_ms', {}).get(s, 0):.4f}" for s in stages)
    lines.append(f"| {sc} | {mid} | {cs:.0f} | {gs:.0f} | {gs / cs if cs else 0:.2f} | {st} |")
dev = next((j.get("device") for j in allj.values() if j.get("engine") == "cuda"), "?")
cpu = next((j.get("device") for j in allj.values() if j.get("engine") == "cpu"), "?")
open(os.path.join(out, "steps.md"), "w").write(f"GPU: {dev}; CPU: {cpu}\n\n" + "\n".join(lines) + "\n")
json.dump(allj, open(os.path.join(out, "steps.json"), "w"), indent=1)
PY
