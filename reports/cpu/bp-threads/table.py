#!/usr/bin/env python3
"""Table of reports/cpu/bp-threads/*.json, or of the folder given as the argument (octree vs bullet-dbvt, ms per frame)."""
import glob, json, os, sys
d = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
print("| scene | threads | broadphase | mean | stddev | cv | median | min | dbvt/octree (mean) | dbvt/octree (min) |")
print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|")
for f in sorted(glob.glob(os.path.join(d, "*-t*.json"))):
    j = json.load(open(f))
    frames = int(j["context"]["recorded_frames"])
    agg = {}
    for b in j["benchmarks"]:
        name, stat = b["run_name"].split("/")[1], b.get("aggregate_name")
        agg.setdefault(name, {})[stat] = b["real_time"] / frames  # ms per frame
    scene = os.path.basename(f).rsplit("-t", 1)[0]
    t = os.path.basename(f).rsplit("-t", 1)[1].split(".")[0]
    o, r = agg["octree"], agg["bullet-dbvt"]
    for name in ("octree", "bullet-dbvt"):
        a = agg[name]
        ratio_mean = f"{r['mean'] / o['mean']:.2f}x" if name == "octree" else ""
        ratio_min = f"{r['min'] / o['min']:.2f}x" if name == "octree" else ""
        print(f"| {scene} | {t} | {name} | {a['mean']:.3f} | {a['stddev']:.3f} | {100 * a['stddev'] / a['mean']:.1f} % | "
              f"{a['median']:.3f} | {a['min']:.3f} | {ratio_mean} | {ratio_min} |")
