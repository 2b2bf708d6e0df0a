#!/usr/bin/python3
"""Tabulates bench/run_scenes.sh results (octocd run --summary-json files) as Markdown."""
import json
import pathlib
import sys

out = pathlib.Path(sys.argv[1])
rows = [json.loads(p.read_text()) for p in sorted(out.glob("*.json"))]
if not rows:
    sys.exit(f"no *.json results in {out}")
# Stage order of the step (core/include/octocd/world.hpp, enum Stage).
ORDER = ["integrate", "aabbs", "broadphase", "midphase", "response", "metrics"]
stages = [s for s in ORDER if s in rows[0]["stage_ms"]]
by_scene = {}
for r in rows:
    by_scene.setdefault(r["scene"], {})[r["midphase"]] = r

print(f"# CPU reference: steps/s per dataset scene\n")
print(f"Machine: {rows[0]['device']}; build {rows[0]['build_id']}; "
      f"{rows[0]['frames']} frames per run; broadphase {rows[0]['broadphase']}.\n")
print("| scene | bodies | midphase | steps/s | mean step ms | "
      + " | ".join(f"{s} %" for s in stages) + " | pairs/frame | contacts/frame |")
print("|---|---:|---|---:|---:|" + "---:|" * len(stages) + "---:|---:|")
for scene, runs in by_scene.items():
    for mp in ("1,2", "aabb-only"):
        r = runs.get(mp)
        if r is None:
            continue
        total = sum(r["stage_ms"].values()) or 1.0
        shares = " | ".join(f"{100 * r['stage_ms'][s] / total:.1f}" for s in stages)
        print(f"| {scene} | {r['bodies']} | {mp} | {r['steps_per_s']:.1f} | "
              f"{r['mean_step_ms']:.3f} | {shares} | {r['mean_pairs']:.1f} | "
              f"{r['mean_contacts']:.1f} |")
print("\nRatio [1,2] / aabb-only in steps/s:\n")
for scene, runs in by_scene.items():
    if "1,2" in runs and "aabb-only" in runs:
        print(f"- {scene}: {runs['1,2']['steps_per_s'] / runs['aabb-only']['steps_per_s']:.4f}")
