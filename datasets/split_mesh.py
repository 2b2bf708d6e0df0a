#!/usr/bin/python3
"""Split a triangle mesh (OFF) 1-to-4 by edge midpoints, N times, and write an OFF.

Usage: split_mesh.py INPUT.off OUTPUT.off [--times N]

Every triangle (a, b, c) becomes (a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca),
which keeps the winding. An edge's midpoint is created once, keyed by its unordered
vertex pair, so two triangles sharing an edge share its midpoint vertex: the output is
watertight wherever the input is. Output is deterministic: the input vertices first, in
their order, then the midpoints in order of first use (faces in order, edges ab, bc, ca),
coordinates computed in float64 and written with '%.9g' (enough to round-trip float32).
"""

import argparse
import sys

import numpy as np


def read_off(path):
    """Reads an OFF file; '#' starts a comment anywhere. Returns (float64 Nx3, list of faces)."""
    tokens = []
    with open(path, "r", encoding="ascii") as f:
        for line in f:
            line = line.split("#", 1)[0]
            tokens.extend(line.split())
    if not tokens or tokens[0] != "OFF":
        sys.exit(f"split_mesh: '{path}': not an OFF file (expected 'OFF' header)")
    nv, nf = int(tokens[1]), int(tokens[2])
    pos = 4
    verts = np.array(tokens[pos:pos + 3 * nv], dtype=np.float64).reshape(nv, 3)
    pos += 3 * nv
    faces = []
    for i in range(nf):
        k = int(tokens[pos])
        idx = [int(t) for t in tokens[pos + 1:pos + 1 + k]]
        pos += 1 + k
        if k < 3:
            sys.exit(f"split_mesh: '{path}': face {i} has {k} vertices (expected >= 3)")
        for j in range(1, k - 1):  # fan-triangulate polygons
            faces.append((idx[0], idx[j], idx[j + 1]))
    return verts, faces


def split_once(verts, faces):
    nv = len(verts)
    mid = {}            # (min, max) -> new index
    pairs = []          # endpoints of each new midpoint, in creation order
    out = []

    def midpoint(a, b):
        key = (a, b) if a < b else (b, a)
        m = mid.get(key)
        if m is None:
            m = nv + len(pairs)
            mid[key] = m
            pairs.append(key)
        return m

    for a, b, c in faces:
        ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
        out.extend(((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)))
    p = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    mids = (verts[p[:, 0]] + verts[p[:, 1]]) * 0.5
    return np.vstack([verts, mids]), out


def write_off(path, verts, faces):
    with open(path, "w", encoding="ascii", newline="\n") as f:
        f.write("OFF\n%d %d 0\n" % (len(verts), len(faces)))
        f.write("".join("%.9g %.9g %.9g\n" % (x, y, z) for x, y, z in verts.tolist()))
        f.write("".join("3 %d %d %d\n" % t for t in faces))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("--times", type=int, default=1)
    args = ap.parse_args()
    if args.times < 0:
        sys.exit("split_mesh: --times must be >= 0")
    verts, faces = read_off(args.input)
    for _ in range(args.times):
        verts, faces = split_once(verts, faces)
    write_off(args.output, verts, faces)
    print("%s: %d vertices, %d triangles" % (args.output, len(verts), len(faces)))


if __name__ == "__main__":
    main()
