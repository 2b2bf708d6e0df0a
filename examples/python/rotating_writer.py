#!/usr/bin/python3
"""A rotating engine's external trace, version 2 (docs/trace-format.md, "Version 2"): a
static floor (body 0) and a 1 kg box of side 0.2 (body 1) spinning at 2 rad/s about y on
it, frictionless. Usage: rotating_writer.py OUT.h5 && octocd validate --trace-in OUT.h5"""
import sys
import h5py
import numpy as np

F, DT, W = 100, 0.01, 2.0  # frames, time step (s), spin (rad/s)
a = W * DT * np.arange(F + 1)  # the box's angle about y in each state row
with h5py.File(sys.argv[1], "w") as f:
    f.attrs.update(format="octocd-trace", version=2, engine="spinner", dt=DT, gravity=[0, -9.81, 0], mu=0.0)
    f["bodies/local_aabb_min"] = np.float32([[-1, -0.05, -1], [-0.1, -0.1, -0.1]])  # body frame
    f["bodies/local_aabb_max"] = np.float32([[1, 0.05, 1], [0.1, 0.1, 0.1]])
    f["bodies/inverse_mass"] = np.float32([0, 1])  # inertia: derived (solid box)
    f["states/position"] = np.float32(np.tile([[0, -0.05, 0], [0, 0.1, 0]], (F + 1, 1, 1)))
    f["states/velocity"] = np.zeros((F + 1, 2, 3), np.float32)
    q = np.zeros((F + 1, 2, 4)); q[:, 0, 0] = 1; q[:, 1, 0], q[:, 1, 2] = np.cos(a / 2), np.sin(a / 2)
    f["states/orientation"] = np.float32(q)  # (w, x, y, z), body to world
    f["states/angular_velocity"] = np.float32(np.tile([[0, 0, 0], [0, W, 0]], (F + 1, 1, 1)))  # world frame
    # Step f: a 4-row manifold at the box's bottom corners in its pre-step pose (row f-1).
    corners = [(x, z) for x in (-0.1, 0.1) for z in (-0.1, 0.1)]
    f["contacts/point"] = np.float32([[np.cos(t) * x + np.sin(t) * z, 0, np.cos(t) * z - np.sin(t) * x]
                                      for t in a[:-1] for x, z in corners])
    f["contacts/offsets"] = np.arange(0, 4 * F + 1, 4, dtype=np.int64)
    f["contacts/pair"] = np.tile(np.uint32([0, 1]), (4 * F, 1))  # (a, b) = (floor, box)
    f["contacts/normal"] = np.float32(np.tile([0, -1, 0], (4 * F, 1)))  # from B (box) to A (floor)
    f["contacts/depth"] = np.zeros(4 * F, np.float32)
    f["contacts/jn"] = np.full(4 * F, 9.81 * DT / 4, np.float32)  # m g dt over the 4 rows
    f["contacts/jt"] = np.zeros(4 * F, np.float32)  # no friction
    # The friction impulse of each row on A as a vector (world, N s; in the contact plane,
    # within 1 deg): an engine with two friction directions writes their sum here. None.
    f["contacts/jt3"] = np.zeros((4 * F, 3), np.float32)
    # What the engine collided each body as: "mesh" (the shape), "convex_hull", "box" (the
    # local box) or "sphere"; one string for every body, or f["bodies/collision_shape"].
    f.attrs["collision_shape"] = "box"
