#!/usr/bin/python3
"""Tabulates bench_broadphase JSON outputs: ms per frame per broadphase and the ratio to
bullet-dbvt, one table per scene. Usage: broadphase_table.py RESULT.json..."""
import json
import sys

for path in sys.argv[1:]:
    data = json.load(open(path))
    ctx = data["context"]
    rows = []
    for b in data["benchmarks"]:
        scene, name = b["run_name"].split("/")[:2]
        ms = b["real_time"] / b["frames"]  # real_time is in ms per replay of all frames
        rows.append((name, ms, b["pairs"], b["candidates"], int(b["bodies"])))
    base = next((ms for name, ms, *_ in rows if name == "bullet-dbvt"), None)
    print(f"## {ctx['scene']}: {rows[0][4]} bodies, {ctx['recorded_frames']} recorded frames "
          f"after {ctx['warmup_frames']} warm-up frames\n")
    print(f"Machine: {ctx.get('host_name', '?')}, {ctx['num_cpus']} CPUs at {ctx['mhz_per_cpu']} MHz; "
          f"first call of each broadphase made before timing.\n")
    print("| broadphase | ms/frame | / bullet-dbvt | pairs/frame | candidates/frame |")
    print("|---|---:|---:|---:|---:|")
    for name, ms, pairs, cand, _ in rows:
        ratio = f"{ms / base:.2f}" if base else "-"
        print(f"| {name} | {ms:.4f} | {ratio} | {pairs:.1f} | {cand:.0f} |")
    print()
