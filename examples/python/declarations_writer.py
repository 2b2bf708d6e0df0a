#!/usr/bin/python3
"""An engine that declares what it is (docs/trace-format.md, "Declarations"; design.md section 13b.12):
explicit Euler (`integrator`), a gyroscopic term (`gyroscopic`), compliant contacts
(`contact_model`) and joints locking rotation (`/bodies/locked_dofs`). Body 0: a static
floor; body 1: a flat box (0.4 x 0.2 x 0.1 m, 1 kg) spinning alone in the air about a
non-principal axis; body 2: a 1 kg cube whose rotation a joint locks, sliding on the floor
on 4 corner rows with Coulomb friction (mu 0.5). Usage:
declarations_writer.py OUT.h5 && octocd validate --trace-in OUT.h5"""
import sys
import h5py
import numpy as np

F, DT, G, MU = 100, 0.002, np.array([0.0, -9.81, 0.0]), 0.5
H = np.array([[2, 0.1, 2], [0.2, 0.1, 0.05], [0.1, 0.1, 0.1]])  # half extents
INV_MASS = np.array([0.0, 1.0, 1.0])
I_BODY = [np.diag([(b[1] ** 2 + b[2] ** 2), (b[0] ** 2 + b[2] ** 2), (b[0] ** 2 + b[1] ** 2)]) * 4 / 12 for b in H]


def qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def rot(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def advance(q, w, dt):  # q turned by w dt (exponential map, world frame)
    a = np.linalg.norm(w) * dt
    if a == 0:
        return q
    d = np.concatenate([[np.cos(a / 2)], np.sin(a / 2) * w / np.linalg.norm(w)])
    q = qmul(d, q)
    return q / np.linalg.norm(q)


x = np.float32([[0, -0.1, 0], [0, 1.0, 0], [-0.5, 0.0995, 0]]).astype(float)
v = np.float32([[0, 0, 0], [0.3, 0.5, 0], [1.5, 0, 0]]).astype(float)
w = np.float32([[0, 0, 0], [2, 5, 1], [0, 0, 0]]).astype(float)
q = np.array([[1.0, 0, 0, 0], [np.cos(0.2), np.sin(0.2), 0, 0], [1.0, 0, 0, 0]])
X, V, W, Q, rows = [x], [v], [w], [q], []
for f in range(F):
    x1, v1, w1, q1, step = x.copy(), v.copy(), w.copy(), q.copy(), []
    # Body 1, alone: gravity; the gyroscopic term w' = w - dt I_w^-1 (w x I_w w).
    iw = rot(q[1]) @ I_BODY[1] @ rot(q[1]).T
    v1[1] = v[1] + DT * G
    w1[1] = w[1] - DT * np.linalg.solve(iw, np.cross(w[1], iw @ w[1]))
    # Body 2 on the floor (0.5 mm deep): 4 corners carry m g dt; friction opposes the sliding.
    jn = np.float32(9.81 * DT / 4)
    vx = v[2][0]
    jt = np.float32(min(MU * 4 * jn, abs(vx)) / 4)
    v1[2] = v[2] + DT * G + [-np.sign(vx) * 4 * jt, 4 * jn, 0]
    for cx in (-0.1, 0.1):
        for cz in (-0.1, 0.1):
            depth = 0.1 - x[2][1]
            step.append(([0, 2], [0, -1, 0], [x[2][0] + cx, -depth / 2, cz], depth, jn, jt))
    # Explicit Euler: positions and orientations advance with the velocities before the step.
    for i in (1, 2):
        x1[i] = x[i] + DT * v[i]
        q1[i] = advance(q[i], w[i], DT)
    x, v, w, q = (np.float32(a).astype(float) for a in (x1, v1, w1, q1))
    X.append(x), V.append(v), W.append(w), Q.append(q), rows.append(step)

with h5py.File(sys.argv[1], "w") as f:
    f.attrs.update(format="octocd-trace", version=2, engine="declared", dt=DT, gravity=G, mu=MU,
                   restitution=0.0, contact_margin=0.005)
    # The declarations (design.md section 13b.12): strings; gyroscopic may also be the integer 1 / 0
    # (not a numpy/Python bool, which HDF5 stores as an enum).
    f.attrs["integrator"] = "explicit"      # x' = x + dt v, q' = q advanced by w dt
    f.attrs["gyroscopic"] = "true"          # w' = w - dt I_w^-1 (w x I_w w) without contacts
    f.attrs["contact_model"] = "soft"       # energy judged per contact episode, not per step
    f.attrs["friction_directions"] = np.int32(1)  # one friction impulse per row, along -v_t: jt is all of it
    f["bodies/locked_dofs"] = np.uint8([0, 0, 0b111000])  # body 2: rotation about x, y, z locked
    f["bodies/local_aabb_min"] = np.float32(-H)
    f["bodies/local_aabb_max"] = np.float32(H)
    f["bodies/inverse_mass"] = np.float32(INV_MASS)
    f["states/position"] = np.float32(X)
    f["states/velocity"] = np.float32(V)
    f["states/angular_velocity"] = np.float32(W)
    f["states/orientation"] = np.float32(Q)
    f["contacts/offsets"] = np.int64(np.cumsum([0] + [len(s) for s in rows]))
    flat = [r for s in rows for r in s]
    f["contacts/pair"] = np.int64([r[0] for r in flat])
    f["contacts/normal"] = np.float32([r[1] for r in flat])  # from B (the cube) to A (the floor)
    f["contacts/point"] = np.float32([r[2] for r in flat])
    f["contacts/depth"] = np.float32([r[3] for r in flat])
    f["contacts/jn"] = np.float32([r[4] for r in flat])
    f["contacts/jt"] = np.float32([r[5] for r in flat])  # along -v_t: >= 0 when it opposes sliding
