#!/usr/bin/python3
"""Write the rod meshes of the shipped scene `rods-150` (docs/scenes.md): a capsule of length
1 and radius 0.06 (a cylinder of `RINGS` rings of `SEGMENTS` vertices between two
hemispherical caps of `CAP_RINGS` rings and a pole each), its axis along x, y or z.

Usage: make_rods.py [OUT_DIR]   (default: datasets/scenes/meshes beside this file)

Writes rod-x.obj, rod-y.obj, rod-z.obj (Wavefront OBJ, triangles wound outwards, coordinates
with '%.6f'). Deterministic: the same files on every run; they are committed, and
tests/core/test_scene.cpp loads the scene that names them.
"""

import math
import os
import sys

LENGTH = 1.0      # cylinder part plus both caps, along the axis
RADIUS = 0.06
SEGMENTS = 16     # vertices around the axis
RINGS = 33        # rings along the cylinder part
CAP_RINGS = 4     # rings of each cap between the cylinder's end ring and the pole


def capsule():
    """Vertices (u, r1, r2) with u along the axis, and triangles, wound outwards."""
    half = LENGTH / 2 - RADIUS
    rings = []  # (u, radius) from -u to +u
    for k in range(CAP_RINGS, 0, -1):
        a = k * (math.pi / 2) / (CAP_RINGS + 1)
        rings.append((-half - RADIUS * math.sin(a), RADIUS * math.cos(a)))
    for k in range(RINGS):
        rings.append((-half + 2 * half * k / (RINGS - 1), RADIUS))
    for k in range(1, CAP_RINGS + 1):
        a = k * (math.pi / 2) / (CAP_RINGS + 1)
        rings.append((half + RADIUS * math.sin(a), RADIUS * math.cos(a)))
    verts = [(-half - RADIUS, 0.0, 0.0)]
    for u, r in rings:
        for s in range(SEGMENTS):
            t = 2 * math.pi * s / SEGMENTS
            verts.append((u, r * math.cos(t), r * math.sin(t)))
    verts.append((half + RADIUS, 0.0, 0.0))
    last = len(verts) - 1
    ring = lambda i, s: 1 + i * SEGMENTS + s % SEGMENTS
    tris = []
    for s in range(SEGMENTS):
        tris.append((0, ring(0, s + 1), ring(0, s)))
    for i in range(len(rings) - 1):
        for s in range(SEGMENTS):
            a, b = ring(i, s), ring(i, s + 1)
            c, d = ring(i + 1, s), ring(i + 1, s + 1)
            tris.append((a, b, d))
            tris.append((a, d, c))
    top = len(rings) - 1
    for s in range(SEGMENTS):
        tris.append((last, ring(top, s), ring(top, s + 1)))
    return verts, tris


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), "scenes", "meshes")
    os.makedirs(out, exist_ok=True)
    verts, tris = capsule()
    # (u, r1, r2) -> (x, y, z), a right-handed cyclic permutation per axis (keeps the winding).
    axes = {"x": lambda u, p, q: (u, p, q), "y": lambda u, p, q: (q, u, p), "z": lambda u, p, q: (p, q, u)}
    for name, place in axes.items():
        path = os.path.join(out, f"rod-{name}.obj")
        with open(path, "w", encoding="ascii") as f:
            f.write(f"# octocd datasets/make_rods.py: capsule, length {LENGTH}, radius {RADIUS}, axis {name}\n")
            for v in verts:
                f.write("v %.6f %.6f %.6f\n" % place(*v))
            for a, b, c in tris:
                f.write(f"f {a + 1} {b + 1} {c + 1}\n")
        print(f"{path}: {len(verts)} vertices, {len(tris)} triangles")


if __name__ == "__main__":
    main()
