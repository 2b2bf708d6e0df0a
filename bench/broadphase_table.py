#!/usr/bin/python3
"""Tabulates bench_broadphase JSON outputs: ms per frame per broadphase and the ratio to
bullet-dbvt (time / bullet-dbvt's time: below 1 is faster), one table per scene. With --benchmark_repetitions the median over the
repetitions is used and the minimum shown beside it (a shared machine slows some
repetitions down; the minimum is the steadiest figure); without, the single run.
Usage: broadphase_table.py RESULT.json..."""
import json
import sys

for path in sys.argv[1:]:
    data = json.load(open(path))
    ctx = data["context"]
    runs = {}  # name -> {"median": b, "min": b, "single": b}
    order = []
    for b in data["benchmarks"]:
        scene, name = b["run_name"].split("/")[:2]
        if name not in runs:
            runs[name] = {}
            order.append(name)
        kind = b.get("aggregate_name", "single") if b.get("run_type") == "aggregate" else "single"
        if kind in ("median", "min") or (kind == "single" and "single" not in runs[name]):
            runs[name][kind] = b
    rows = []
    for name in order:
        r = runs[name]
        main = r.get("median", r.get("single"))
        low = r.get("min", main)
        ms = main["real_time"] / main["frames"]  # real_time is in ms per replay of all frames
        ms_min = low["real_time"] / low["frames"]
        reps = main.get("repetitions", 1) if "median" in r else 1
        rows.append((name, ms, ms_min, reps, main["pairs"], main["candidates"], int(main["bodies"])))
    base = next((r for r in rows if r[0] == "bullet-dbvt"), None)
    print(f"## {ctx['scene']}: {rows[0][6]} bodies, {ctx['recorded_frames']} recorded frames "
          f"after {ctx['warmup_frames']} warm-up frames\n")
    print(f"Machine: {ctx.get('host_name', '?')}, {ctx['num_cpus']} CPUs at {ctx['mhz_per_cpu']} MHz, "
          f"load average {', '.join(f'{x:.2f}' for x in ctx.get('load_avg', []))} at the start; "
          f"each broadphase first replays the frames {ctx.get('warm_replays', '0 (only its first call)')} "
          f"time(s) untimed; one thread each.\n")
    print("| broadphase | ms/frame (median) | ms/frame (min) | repetitions | / bullet-dbvt (median) "
          "| / bullet-dbvt (min) | pairs/frame | candidates/frame |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, ms, ms_min, reps, pairs, cand, _ in rows:
        ratio = f"{ms / base[1]:.2f}" if base else "-"
        speed = f"{ms_min / base[2]:.2f}" if base else "-"
        print(f"| {name} | {ms:.4f} | {ms_min:.4f} | {reps} | {ratio} | {speed} | {pairs:.1f} | {cand:.0f} |")
    print()
