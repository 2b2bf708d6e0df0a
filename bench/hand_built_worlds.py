#!/usr/bin/env python3
"""Writes a hand-built scene of K copies of a grid-layout scene (default bunny-stack-50), the
way it was done before `octocd run --worlds` (issue 70): one scene file, each copy in its own
open box of static boxes (mass 0, explicit positions), the copies on an x-z grid, walls
"none". It is the baseline of bench/run-worlds.sh: `--worlds K` should be as fast as this
scene (no cost for being generated).

The copies match octocd's batched worlds (core/include/octocd/worlds.hpp): the same grid
(ceil(sqrt(K)) columns on x, rows on z, copy 0 at offset zero), the same default cell (the
scene's bounds, its domain and the walls, plus a 0.5 m margin) and the same deepened octree
depth. A copy's bodies are one group with the scene group's grid layout translated by the
copy's offset (the same jitter stream), so the bodies start where the batched copies do up
to the rounding of the translation. Body order differs: every wall first, then the copies'
bodies (octocd's batched worlds are copy-major).

Usage: bench/hand_built_worlds.py --copies 8192 -o /tmp/hand-built-8192.json
"""
import argparse
import json
import math
import os
import sys


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default=os.path.join(here, "..", "datasets", "scenes", "bunny-stack-50.json"),
                    help="a scene with walls open-box and grid-layout groups (default bunny-stack-50)")
    ap.add_argument("--copies", type=int, default=8192, help="K, the number of copies (>= 1)")
    ap.add_argument("--margin", type=float, default=0.5, help="gap between neighbouring copies' bounds (m)")
    ap.add_argument("-o", "--output", required=True, help="the scene file to write")
    a = ap.parse_args()
    if a.copies < 1:
        sys.exit("--copies: %d; allowed: >= 1" % a.copies)
    with open(a.scene) as f:
        s = json.load(f)
    if s.get("walls", "floor") != "open-box":
        sys.exit("%s: walls: %r; allowed: \"open-box\" (this script builds the copies' open boxes)" % (a.scene, s.get("walls")))
    dmin, dmax = s["domain"]["min"], s["domain"]["max"]
    t = s.get("wall_thickness", 0.1)
    c = [(dmin[i] + dmax[i]) / 2 for i in range(3)]
    h = [(dmax[i] - dmin[i]) / 2 for i in range(3)]
    # The open box of core/src/model.cpp (make_walls): centre and half extents per wall.
    walls = [
        ("floor", [c[0], dmin[1] - t / 2, c[2]], [h[0] + t, t / 2, h[2] + t]),
        ("wall-x-", [dmin[0] - t / 2, c[1], c[2]], [t / 2, h[1], h[2] + t]),
        ("wall-x+", [dmax[0] + t / 2, c[1], c[2]], [t / 2, h[1], h[2] + t]),
        ("wall-z-", [c[0], c[1], dmin[2] - t / 2], [h[0], h[1], t / 2]),
        ("wall-z+", [c[0], c[1], dmax[2] + t / 2], [h[0], h[1], t / 2]),
    ]
    # Bounds: the domain and the walls (the bodies start inside the domain).
    lo = [dmin[0] - t, dmin[1] - t, dmin[2] - t]
    hi = [dmax[0] + t, dmax[1], dmax[2] + t]
    sx, sz = hi[0] - lo[0] + a.margin, hi[2] - lo[2] + a.margin
    nx = math.isqrt(a.copies - 1) + 1 if a.copies > 1 else 1
    nz = (a.copies + nx - 1) // nx
    offsets = [((k % nx) * sx, (k // nx) * sz) for k in range(a.copies)]
    groups = []
    for name, centre, half in walls:
        groups.append({"name": name, "shape": {"box": half}, "count": a.copies, "mass": 0.0,
                       "positions": [[centre[0] + ox, centre[1], centre[2] + oz] for ox, oz in offsets]})
    for g in s["groups"]:
        lay = g.get("layout", {})
        if lay.get("type", "grid") != "grid" or "min" not in lay or g.get("positions"):
            sys.exit("%s: groups: %r; allowed: grid layouts with a region (min, max)" % (a.scene, g.get("name")))
        for k, (ox, oz) in enumerate(offsets):
            gk = json.loads(json.dumps(g))
            gk["name"] = "%s@%d" % (g.get("name", "group"), k)
            gk["layout"]["min"] = [lay["min"][0] + ox, lay["min"][1], lay["min"][2] + oz]
            gk["layout"]["max"] = [lay["max"][0] + ox, lay["max"][1], lay["max"][2] + oz]
            groups.append(gk)
    out = dict(s)
    out["name"] = "%s-hand-built-x%d" % (s["name"], a.copies)
    out["description"] = ("%d copies of %s, each in its own open box of static boxes, on a %d x %d grid "
                          "(cells %.3g x %.3g m), written by bench/hand_built_worlds.py" %
                          (a.copies, s["name"], nx, nz, sx, sz))
    out["walls"] = "none"
    out["domain"] = {"min": [lo[0], lo[1], lo[2]],
                     "max": [hi[0] + (nx - 1) * sx, hi[1], hi[2] + (nz - 1) * sz]}
    bp = dict(s.get("broadphase", {}))
    depth = bp.get("depth", 2)
    # Only the octrees read the depth: deepening it for another broadphase changes nothing.
    if isinstance(depth, int):
        side_1 = max(dmax[i] - dmin[i] for i in range(3))
        dom = out["domain"]
        side_k = max(dom["max"][i] - dom["min"][i] for i in range(3))
        if side_k > side_1:
            bp["depth"] = min(10, depth + max(0, math.ceil(math.log2(side_k / side_1) - 1e-9)))
    out["broadphase"] = bp
    out["groups"] = groups
    with open(a.output, "w") as f:
        json.dump(out, f, separators=(",", ":"))
    print("%s: %d copies, %d groups, domain %s, broadphase %s" % (a.output, a.copies, len(groups), out["domain"], bp))


if __name__ == "__main__":
    main()
