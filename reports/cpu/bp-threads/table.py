#!/usr/bin/env python3
"""Table of reports/cpu/bp-threads/*.json, or of the folder given as the argument (octree vs bullet-dbvt, ms per frame)."""
import glob, json, os, sys
d = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
print("| scene | threads | broadphase | mean | stddev | cv | median | min-max | dbvt/octree (mean) | dbvt/octree (median) | dbvt/octree (min) |")
print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
for f in sorted(glob.glob(os.path.join(d, "*-t*.json"))):
    j = json.load(open(f))
    frames = int(j["context"]["recorded_frames"])
    agg = {}
    reps = {}
    for b in j["benchmarks"]:
        name, stat = b["run_name"].split("/")[1], b.get("aggregate_name")
        if b.get("run_type") == "iteration":  # one repetition (files written without
            reps.setdefault(name, []).append(b["real_time"] / frames)  # aggregates-only)
            continue
        agg.setdefault(name, {})[stat] = b["real_time"] / frames  # ms per frame
    for name, v in reps.items():  # the maximum, when the file has it or its repetitions
        agg[name].setdefault("max", max(v))
    scene = os.path.basename(f).rsplit("-t", 1)[0]
    t = os.path.basename(f).rsplit("-t", 1)[1].split(".")[0]
    o, r = agg["octree"], agg["bullet-dbvt"]
    for name in ("octree", "bullet-dbvt"):
        a = agg[name]
        ratio_mean = f"{r['mean'] / o['mean']:.2f}x" if name == "octree" else ""
        ratio_median = f"{r['median'] / o['median']:.2f}x" if name == "octree" else ""
        ratio_min = f"{r['min'] / o['min']:.2f}x" if name == "octree" else ""
        hi = f"{a['max']:.3f}" if "max" in a else "?"
        print(f"| {scene} | {t} | {name} | {a['mean']:.3f} | {a['stddev']:.3f} | {100 * a['stddev'] / a['mean']:.1f} % | "
              f"{a['median']:.3f} | {a['min']:.3f}-{hi} | {ratio_mean} | {ratio_median} | {ratio_min} |")
