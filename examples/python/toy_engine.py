#!/usr/bin/python3
"""A toy rigid-body engine that writes an external octocd trace (docs/trace-format.md,
"External traces"), to be judged by `octocd validate --trace-in FILE.h5`.

Seven axis-aligned boxes: a static floor (body 0), a box falling onto it (1), a stack of
two boxes resting on it (2, 3), a box flying sideways (4) and two boxes colliding in
mid-air (5, 6). Each step follows design.md section 4's order: semi-implicit Euler, world AABBs, all
pairs with overlapping AABBs (inclusive, Eq. 6), one contact per pair (least-overlap
axis, normal from B to A), position correction down to the slop and an inelastic normal
impulse, Jacobi style. No friction.

The planted fault: at frame 7 the broadphase loses pair (2, 3), so octocd's
candidate-sets validator fails naming frame 7 and the pair; `--no-plant` writes a clean
run that passes.

    /usr/bin/python3 examples/python/toy_engine.py toy.h5 && ./build/octocd validate --trace-in toy.h5
"""
import argparse

import h5py
import numpy as np

F32 = np.float32
DT = F32(0.01)
GRAVITY = np.array([0.0, -9.81, 0.0], dtype=F32)
SLOP = F32(0.001)  # delta of design.md section 6 (the scene-less default the validators use)
FRAMES = 20
PLANTED_FRAME, PLANTED_PAIR = 7, (2, 3)


def bodies():
    """Local boxes (half extents), inverse masses and initial state."""
    half = np.array([[1.0, 0.05, 1.0]] + [[0.1, 0.1, 0.1]] * 6, dtype=F32)
    w = np.array([0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.5], dtype=F32)  # 1/kg; body 6 weighs 2 kg
    x = np.array([[0.0, -0.05, 0.0],    # floor, top at y = 0
                  [-0.6, 0.15, 0.0],    # falls onto the floor
                  [0.0, 0.1, 0.0],      # rests on the floor
                  [0.0, 0.3, 0.0],      # rests on body 2
                  [0.6, 1.0, 0.5],      # flies sideways, touches nothing
                  [-0.3, 1.5, -0.6],    # body 5 and 6 close in on each other along x
                  [0.0, 1.5, -0.6]], dtype=F32)
    v = np.zeros_like(x)
    v[4] = [0.5, 0.0, 0.0]
    v[5] = [1.0, 0.0, 0.0]
    v[6] = [-1.0, 0.0, 0.0]
    return half, w, x, v


def step(frame, half, w, x, v, plant):
    """One step: returns (aabb_min, aabb_max, pairs, contacts, x, v) after the step."""
    dyn = w > 0
    v = v.copy()
    x = x.copy()
    v[dyn] = v[dyn] + DT * GRAVITY
    x[dyn] = x[dyn] + DT * v[dyn]
    lo, hi = x - half, x + half
    n = len(x)
    pairs = [(a, b) for a in range(n) for b in range(a + 1, n)
             if np.all(lo[a] <= hi[b]) and np.all(hi[a] >= lo[b])]
    if plant and frame == PLANTED_FRAME:
        pairs.remove(PLANTED_PAIR)  # the planted miss
    contacts = []
    dx_sum, dv_sum, count = np.zeros_like(x), np.zeros_like(v), np.zeros(n, dtype=np.int64)
    for a, b in pairs:
        sep = np.minimum(hi[a] - lo[b], hi[b] - lo[a])  # distance that separates them per axis
        if np.any(sep <= 0) or w[a] + w[b] == 0:
            continue
        k = int(np.argmin(sep))
        normal = np.zeros(3, dtype=F32)
        normal[k] = 1.0 if x[a][k] - x[b][k] >= 0 else -1.0  # from B to A
        depth = sep[k]
        c = max(depth - SLOP, F32(0)) * normal
        wsum = w[a] + w[b]
        dx_sum[a] += w[a] / wsum * c
        dx_sum[b] -= w[b] / wsum * c
        vn = float(np.dot(v[a] - v[b], normal))
        jn = -vn / wsum if vn < 0 else 0.0  # inelastic
        dv_sum[a] += w[a] * jn * normal
        dv_sum[b] -= w[b] * jn * normal
        count[a] += 1
        count[b] += 1
        contacts.append(((a, b), normal, depth, jn, 0.0))
    for i in range(n):
        if dyn[i] and count[i] > 0:
            x[i] += dx_sum[i] / F32(count[i])
            v[i] += dv_sum[i]
    return lo, hi, pairs, contacts, x, v


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="trace file to write (HDF5)")
    ap.add_argument("--no-plant", action="store_true", help="do not lose pair (2, 3) at frame 7")
    args = ap.parse_args()

    half, w, x, v = bodies()
    n = len(x)
    positions, velocities = [x], [v]
    aabb_min, aabb_max = [], []
    pair_rows, pair_offsets = [], [0]
    c_pair, c_normal, c_depth, c_jn, c_jt, c_offsets = [], [], [], [], [], [0]
    for frame in range(1, FRAMES + 1):
        lo, hi, pairs, contacts, x, v = step(frame, half, w, x, v, plant=not args.no_plant)
        positions.append(x)
        velocities.append(v)
        aabb_min.append(lo)
        aabb_max.append(hi)
        pair_rows += pairs
        pair_offsets.append(len(pair_rows))
        for pair, normal, depth, jn, jt in contacts:
            c_pair.append(pair)
            c_normal.append(normal)
            c_depth.append(depth)
            c_jn.append(jn)
            c_jt.append(jt)
        c_offsets.append(len(c_pair))

    with h5py.File(args.out, "w") as f:
        f.attrs["format"] = "octocd-trace"
        f.attrs["version"] = np.int32(1)
        f.attrs["engine"] = "toy-engine"
        f.attrs["dt"] = float(DT)
        b = f.create_group("bodies")
        b["local_aabb_min"] = -half
        b["local_aabb_max"] = half
        b["inverse_mass"] = w
        s = f.create_group("states")
        s["frame"] = np.arange(FRAMES + 1, dtype=np.int64)
        s["position"] = np.array(positions, dtype=F32)
        s["velocity"] = np.array(velocities, dtype=F32)
        a = f.create_group("aabbs")
        a["min"] = np.array(aabb_min, dtype=F32)
        a["max"] = np.array(aabb_max, dtype=F32)
        p = f.create_group("pairs")
        p["offsets"] = np.array(pair_offsets, dtype=np.int64)
        p["pair"] = np.array(pair_rows, dtype=np.uint32).reshape(-1, 2)
        c = f.create_group("contacts")
        c["offsets"] = np.array(c_offsets, dtype=np.int64)
        c["pair"] = np.array(c_pair, dtype=np.uint32).reshape(-1, 2)
        c["normal"] = np.array(c_normal, dtype=F32).reshape(-1, 3)
        c["depth"] = np.array(c_depth, dtype=F32)
        c["jn"] = np.array(c_jn, dtype=F32)
        c["jt"] = np.array(c_jt, dtype=F32)
    print(f"{args.out}: {n} bodies, {FRAMES} frames, {len(pair_rows)} pairs, {len(c_pair)} contacts"
          + ("" if args.no_plant else f"; pair {PLANTED_PAIR} lost at frame {PLANTED_FRAME}"))


if __name__ == "__main__":
    main()
