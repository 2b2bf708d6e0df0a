#!/usr/bin/python3
"""Which planted faults each declaration leaves visible, measured (docs/validate-your-engine.md,
"What each declaration turns off"): a small engine written here steps a static floor, six 1 kg
boxes (0.2 m) sliding on it at 1 m/s in six directions on 4 corner rows each (Coulomb friction
at mu 0.5, the rows' normal impulses split so the box does not turn) and a box spinning alone
in the air at 22 rad/s (30 steps of 1 ms). Its trace is rewritten as each declaration says an engine that
declares it writes (the reported rows, the states' frame, the shapes), with one fault planted
in the run's last step on each body (so that no later step shows a planted state jumping
back), and judged on every frame: the steps before it and the bodies not planted must pass
every row.

  velocity x1.5       box 1's velocity after the step x1.5
  friction 1.2x       box 2's friction 1.2x its rows' cone: its states and its reported
                      friction (jt, jt3) both carry the extra impulse and its torque
  pulling impulse     box 3 pulled into the floor by the impulse its rows report pushing it
  energy +5%          box 4's velocity and angular velocity x sqrt(1.05)
  dropped row         box 5's most loaded row left out of the trace
  flipped normal      box 6's most loaded row's normal reversed
  teleport 1 cm       the lone box 7 moved 1 cm along x

A fault is caught by a row that fails naming its body (an item of the row's causes) at its
step. The
result is docs/validate-your-engine.md's table; tests/scene/test_engine_corpus.py checks the
page against this run. Usage: declared_faults.py OCTOCD_BIN prints the table.
"""
import json
import os
import re
import subprocess
import sys
import tempfile

import h5py
import numpy as np

DT, G, MU, H, DEPTH, INSET = 0.001, np.array([0.0, -9.81, 0.0]), 0.5, 0.1, 0.0005, 0.09
FRAMES = 30
STEP = FRAMES  # the faults' step, the run's last
BOXES = 6  # bodies 1 .. 6 slide; body 7 flies alone
FREE = 7
N = 8
I_BOX = np.eye(3) * (2 * H) ** 2 / 6  # a 1 kg cube
FAULTS = ["velocity x1.5", "friction 1.2x", "pulling impulse", "energy +5%", "dropped row", "flipped normal",
          "teleport 1 cm"]
FAULT_BODY = {f: i + 1 for i, f in enumerate(FAULTS)}
ROW_FAULTS = ("dropped row", "flipped normal")
ROWS = {"momentum-balance": "MB", "impulse-feasibility": "IF", "friction": "FR", "contact-geometry": "CG",
        "free-flight": "FF", "conservation": "CO", "contact-completeness": "CC", "penetration": "PE",
        "broadphase-completeness": "BC"}
COM = np.array([0.02, 0.0, 0.0])  # the centre of mass in the body frame, where a declaration moves it


def f32(a):
    return np.float32(a).astype(np.float64)


def rot(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def run(a=1.0, origin=None):
    """The clean run: states x, v, w, q ((F + 1) x n x 3 or 4) of the centres of mass and per
    step its rows, dicts of a, b, n (B to A), p, depth, jn, jt, jt3 (on A). The free body
    advances x + dt v + a g dt^2 (a = 1 semi-implicit, 0 explicit, (n + 1) / (2n) n
    substeps); the boxes x + dt v'. With `origin` (its centre of mass in the body frame) the
    free body's origin o = x - R c is integrated instead, as MuJoCo's free joint does:
    v_o' = v_o + dt (g - w x (w x R c)), o' = o + dt v_o' (its centre of mass drifts to first
    order in dt)."""
    x, v, w = np.zeros((N, 3)), np.zeros((N, 3)), np.zeros((N, 3))
    q = np.tile([1.0, 0, 0, 0], (N, 1))
    x[0] = [0, -0.1, 0]
    for k in range(BOXES):
        angle = np.radians(60 * k + 15)
        x[1 + k] = [-1.25 + 0.5 * k, H - DEPTH, 0.0]
        v[1 + k] = [np.cos(angle), 0, np.sin(angle)]
    x[FREE], v[FREE], w[FREE] = [0, 1.5, 1.0], [0.3, 0.5, 0], [0, 20.0, 10.0]
    x, v, w, q = f32(x), f32(v), f32(w), f32(q)
    if origin is not None:
        o, v_o = x[FREE] - origin, v[FREE] - np.cross(w[FREE], origin)  # R = 1 at the start
    states, rows = [(x, v, w, q)], []
    for _ in range(FRAMES):
        x1, v1, w1, q1, step = x.copy(), v + DT * G, w.copy(), q.copy(), []
        v1[0] = 0
        for b in range(1, BOXES + 1):
            d = v1[b] - v1[b][1] * np.array([0, 1.0, 0])
            d /= np.linalg.norm(d)
            normal = -v1[b][1]  # the floor's push that stops the fall (1 kg)
            points = [np.array([x[b][0] + sx * INSET, -DEPTH / 2, x[b][2] + sz * INSET]) for sx in (1, -1)
                      for sz in (1, -1)]
            # jn per row: their sum the push, their torque with the friction's (mu jn against d) zero.
            lever = [np.cross(p - x[b], [0, 1.0, 0]) - MU * np.cross(p - x[b], d) for p in points]
            a_mat = np.vstack([np.ones(4), np.array(lever).T])
            jn = np.linalg.lstsq(a_mat, np.array([normal, 0, 0, 0]), rcond=None)[0]
            assert (jn > 0).all(), jn
            for p, j in zip(points, jn):
                j = float(np.float32(j))
                step.append(dict(a=0, b=b, n=np.array([0, -1.0, 0]), p=f32(p), depth=f32(DEPTH), jn=j,
                                 jt=float(np.float32(MU * j)), jt3=f32(MU * j * d)))
        for r in step:  # the reported (float32) impulses are the ones applied: -(jn n + jt3) on the box
            b, j = r["b"], -(r["jn"] * r["n"] + r["jt3"])
            v1[b] = v1[b] + j
            w1[b] = w1[b] + np.linalg.solve(I_BOX, np.cross(r["p"] - x[b], j))
        v1, w1 = f32(v1), f32(w1)
        for b in range(1, N):
            x1[b] = x[b] + DT * v[b] + a * DT * DT * G if b == FREE else x[b] + DT * v1[b]
        assert np.abs(w1[1:BOXES + 1]).max() * DT < 1e-9  # the boxes do not turn: q stays the identity
        # The lone cube keeps w (no torque, no precession): q turned by w t from the identity.
        turn = np.linalg.norm(w1[FREE]) * DT * (len(states))
        q1[FREE] = np.concatenate([[np.cos(turn / 2)], np.sin(turn / 2) * w1[FREE] / np.linalg.norm(w1[FREE])])
        if origin is not None:
            rc = rot(q[FREE]) @ origin
            v_o = v_o + DT * (G - np.cross(w[FREE], np.cross(w[FREE], rc)))
            o = o + DT * v_o
            rc = rot(q1[FREE]) @ origin
            x1[FREE], v1[FREE] = o + rc, f32(v_o + np.cross(w1[FREE], rc))
        x, v, w, q = f32(x1), v1, w1, f32(q1)
        states.append((x, v, w, q))
        rows.append(step)
    return {"x": np.array([s[0] for s in states]), "v": np.array([s[1] for s in states]),
            "w": np.array([s[2] for s in states]), "q": np.array([s[3] for s in states]), "rows": rows}


def copy(r):
    return {"x": r["x"].copy(), "v": r["v"].copy(), "w": r["w"].copy(), "q": r["q"].copy(),
            "rows": [[dict(row) for row in step] for step in r["rows"]]}


def plant(clean):
    """Every fault of FAULTS on its own body in step STEP (module docstring)."""
    r = copy(clean)
    s, x0 = r["rows"][STEP - 1], r["x"][STEP - 1]
    b = FAULT_BODY["velocity x1.5"]
    r["v"][STEP, b] = f32(1.5 * r["v"][STEP, b])
    b = FAULT_BODY["friction 1.2x"]
    for row in s:
        if row["b"] == b:
            extra = -0.2 * row["jt3"]  # on the box
            r["v"][STEP, b] += extra
            r["w"][STEP, b] += np.linalg.solve(I_BOX, np.cross(row["p"] - x0[b], extra))
            row["jt3"], row["jt"] = f32(1.2 * row["jt3"]), float(np.float32(1.2 * row["jt"]))
    r["v"][STEP, b], r["w"][STEP, b] = f32(r["v"][STEP, b]), f32(r["w"][STEP, b])
    b = FAULT_BODY["pulling impulse"]
    r["v"][STEP, b] = f32(r["v"][STEP, b] - 2 * sum(row["jn"] for row in s if row["b"] == b) * np.array([0, 1.0, 0]))
    b = FAULT_BODY["energy +5%"]
    r["v"][STEP, b], r["w"][STEP, b] = f32(1.05 ** 0.5 * r["v"][STEP, b]), f32(1.05 ** 0.5 * r["w"][STEP, b])
    for fault in ("dropped row", "flipped normal"):
        b = FAULT_BODY[fault]
        k = max((i for i, row in enumerate(s) if row["b"] == b), key=lambda i: s[i]["jn"])
        if fault == "dropped row":
            del s[k]
        else:
            s[k]["n"] = -s[k]["n"]
    r["x"][STEP, FREE] = f32(r["x"][STEP, FREE] + [0.01, 0, 0])
    return r


def write(path, r, attrs=None, contacts="rows", incomplete=None, point_b=False, locked=False, radius=0.0,
          com=None, velocity_at="com", exact_pairs=False):
    """Writes run `r` as an external trace, version 2, as an engine declaring `attrs` does, with
    its contact rows and candidate pairs (`contacts` "rows"), none (no `/contacts`: "none"), or
    an empty `/contacts` and no pairs ("empty")."""
    x, v, w, q = r["x"].copy(), r["v"].copy(), r["w"].copy(), r["q"]
    if locked:  # a joint holds the boxes' rotation: they never turn
        w[:, 1:BOXES + 1] = 0
    lo = np.array([[-2, -0.1, -2]] + [[-H] * 3] * (N - 1))
    hi = -lo
    if com is not None:  # positions at the body frame's origin, `com` behind the centre of mass
        for f in range(len(x)):
            for b in range(1, N):
                rc = rot(q[f, b]) @ com
                x[f, b] -= rc
                if velocity_at == "origin":
                    v[f, b] -= np.cross(w[f, b], rc)
        lo[1:] += com  # the box about its centre of mass, c from the origin
        hi[1:] += com
    lo[1:] += radius
    hi[1:] -= radius
    with h5py.File(path, "w") as f:
        f.attrs.update(format="octocd-trace", version=np.int32(2), engine="zoo-declarations", dt=DT, gravity=G,
                       mu=MU, restitution=0.0, contact_margin=0.005)
        for k, val in (attrs or {}).items():
            f.attrs[k] = val
        f["bodies/local_aabb_min"], f["bodies/local_aabb_max"] = np.float32(lo), np.float32(hi)
        f["bodies/inverse_mass"] = np.float32([0] + [1] * (N - 1))
        f["bodies/inertia"] = np.float32([np.zeros((3, 3))] + [I_BOX] * (N - 1))
        if locked:
            f["bodies/locked_dofs"] = np.uint8([0] + [0b111000] * BOXES + [0])
        if radius:
            f["bodies/convex_radius"] = np.float32([0] + [radius] * (N - 1))
        if com is not None:
            f["bodies/com_offset"] = np.float32([np.zeros(3)] + [com] * (N - 1))
        for name, data in (("position", x), ("velocity", v), ("angular_velocity", w), ("orientation", q)):
            f["states/" + name] = np.float32(data)
        if contacts == "none":
            return
        rows = [row for step in r["rows"] for row in step] if contacts == "rows" else []
        f["contacts/offsets"] = np.int64(np.cumsum([0] + [len(step) for step in r["rows"]]) if rows else
                                         [0] * (FRAMES + 1))
        f["contacts/pair"] = np.int64([[row["a"], row["b"]] for row in rows]).reshape(-1, 2)
        for name, key in (("normal", "n"), ("point", "p"), ("depth", "depth"), ("jn", "jn"), ("jt", "jt"),
                          ("jt3", "jt3")):
            if not rows or key in rows[0]:
                shape = (-1, 3) if key in ("n", "p", "jt3") else (-1,)
                f["contacts/" + name] = np.float32([row[key] for row in rows]).reshape(shape)
        if point_b:
            f["contacts/point_b"] = np.float32([row["p"] for row in rows])
        if incomplete is not None:
            f["contacts/incomplete"] = np.int64(incomplete)
        if contacts == "empty":
            return
        pairs = [(0, b) for b in range(1, BOXES + 1)] if exact_pairs else \
            [(a, b) for a in range(N) for b in range(a + 1, N)]
        f["pairs/offsets"] = np.int64([len(pairs) * i for i in range(FRAMES + 1)])
        f["pairs/pair"] = np.int64(pairs * FRAMES)


def reported(r, impulses=None, depth_unknown=False, jt_along=False, scalar=False):
    """Run `r`'s rows as an engine reporting less writes them."""
    r = copy(r)
    for row in (row for step in r["rows"] for row in step):
        if scalar:  # the friction as the scalar jt alone
            del row["jt3"]
        if impulses in ("normal-only", "none"):
            row["jt"] = 0.0
            del row["jt3"]
        if impulses == "none":
            row["jn"] = 0.0
        if depth_unknown:
            row["depth"] = 0.0
        if jt_along:  # jt along +v_t: friction against the sliding is negative
            row["jt"] = -row["jt"]
    return r


# Each declaration: (its name in the table, the run's integrator a (or "origin": the lone body's origin
# integrated), write()'s and reported()'s keywords).
DECLARATIONS = [
    ("nothing (every row reported)", 1.0, {}, {}),
    ("no `/contacts` (poses only)", 1.0, {"contacts": "none"}, {}),
    ("empty `/contacts`, `contacts_complete` 0 (poses only)", 1.0,
     {"contacts": "empty", "attrs": {"contacts_complete": np.int32(0)}}, {}),
    ('`impulses` "normal-only"', 1.0, {"attrs": {"impulses": "normal-only"}}, {"impulses": "normal-only"}),
    ('`impulses` "none"', 1.0, {"attrs": {"impulses": "none"}}, {"impulses": "none"}),
    ("`impulses_complete` 0", 1.0, {"attrs": {"impulses_complete": np.int32(0)}}, {}),
    ("`contacts_complete` 0", 1.0, {"attrs": {"contacts_complete": np.int32(0)}}, {}),
    ("`/contacts/incomplete` (the faults' step listed)", 1.0, {"incomplete": [STEP]}, {}),
    ('`depth_per` "unknown" (depths 0)', 1.0, {"attrs": {"depth_per": "unknown"}}, {"depth_unknown": True}),
    ('`depth_per` "manifold"', 1.0, {"attrs": {"depth_per": "manifold"}}, {}),
    ('`friction_per` "manifold"', 1.0, {"attrs": {"friction_per": "manifold"}}, {}),
    ('`impulse_points` "witness-pair"', 1.0, {"attrs": {"impulse_points": "witness-pair"}}, {}),
    ("`/contacts/point_b`", 1.0, {"point_b": True}, {}),
    ("`friction_directions` 1 (the scalar `jt`, no `jt3`)", 1.0, {"attrs": {"friction_directions": np.int32(1)}},
     {"scalar": True}),
    ('`jt_direction` "along-sliding"', 1.0, {"attrs": {"jt_direction": "along-sliding"}}, {"jt_along": True}),
    ("`speculative` 1", 1.0, {"attrs": {"speculative": np.int32(1)}}, {}),
    ('`manifold_points` "persistent"', 1.0, {"attrs": {"manifold_points": "persistent"}}, {}),
    ("`normal_reuse_deg` 0", 1.0, {"attrs": {"normal_reuse_deg": 0.0}}, {}),
    ('`contact_geometry` "aabb"', 1.0, {"attrs": {"contact_geometry": "aabb"}}, {}),
    ("`broadphase_exact` 1", 1.0, {"attrs": {"broadphase_exact": np.int32(1)}, "exact_pairs": True}, {}),
    ('`collision_shape` "box"', 1.0, {"attrs": {"collision_shape": "box"}}, {}),
    ("`/bodies/convex_radius` 5 mm", 1.0, {"radius": 0.005}, {}),
    ('`/bodies/com_offset` 2 cm, `velocity_at` "com"', 1.0, {"com": COM, "attrs": {"velocity_at": "com"}}, {}),
    ('`integrated_point` "origin" (com_offset 2 cm; the free body\'s origin integrated)', "origin",
     {"com": COM, "velocity_at": "origin", "attrs": {"velocity_at": "origin", "integrated_point": "origin"}}, {}),
    ("`/bodies/locked_dofs` (the boxes' rotation)", 1.0, {"locked": True}, {}),
    ('`gyroscopic` "true"', 1.0, {"attrs": {"gyroscopic": "true"}}, {}),
    ('`gyroscopic` "false"', 1.0, {"attrs": {"gyroscopic": "false"}}, {}),
    ('`integrator` "semi-implicit"', 1.0, {"attrs": {"integrator": "semi-implicit"}}, {}),
    ('`integrator` "explicit"', 0.0, {"attrs": {"integrator": "explicit"}}, {}),
    ('`integrator` "substepped", `substeps` 4', 0.625,
     {"attrs": {"integrator": "substepped", "substeps": np.int32(4)}}, {}),
    ('`contact_model` "soft"', 1.0, {"attrs": {"contact_model": "soft"}}, {}),
    ('`response_scheme` "jacobi"', 1.0, {"attrs": {"response_scheme": "jacobi"}}, {}),
    ('`deactivation` "off"', 1.0, {"attrs": {"deactivation": "off"}}, {}),
    ("`velocity_clamp` 50", 1.0, {"attrs": {"velocity_clamp": 50.0}}, {}),
]


def judge(octocd, path):
    """(exit code, the rows' verdicts) on the trace at `path`, every frame judged."""
    out = path + ".json"
    r = subprocess.run([octocd, "validate", "--trace-in", path, "--threads", "1", "--json", out],
                       capture_output=True, text=True)
    if r.returncode not in (0, 3):
        raise RuntimeError(f"{path}: exit {r.returncode}\n{r.stdout}{r.stderr}")
    return r.returncode, json.load(open(out))["rows"]


def bodies(item):
    """The dynamic bodies an item names ("body 3", "pair (0, 3)": {3})."""
    return {int(i) for i in re.findall(r"\d+", item)} - {0}


def caught(rows):
    """({body: the rows (abbreviated) failing with an item that names it}, the failures that are
    no planted fault's: an example at another step, or an item naming no planted body)."""
    named, stray = {}, []
    for row in rows:
        if row["verdict"] != "fail":
            continue
        for cause in row["causes"]:
            stray += [f"{row['name']}/{cause['name']}: {e['text']}" for e in cause["examples"] if e["frame"] != STEP]
            for item in cause["items"]:
                if not bodies(item) or not bodies(item) <= set(FAULT_BODY.values()):
                    stray.append(f"{row['name']}/{cause['name']}: {item}")
                for body in bodies(item):
                    named.setdefault(body, set()).add(ROWS.get(row["name"], row["name"]))
    return named, stray


def measure(octocd, work):
    """{declaration: (the failures that are no planted fault's, {fault: the rows catching it,
    None for a fault of the rows on a trace without them})}."""
    runs = {}
    out = {}
    for i, (name, a, written, rewritten) in enumerate(DECLARATIONS):
        if a not in runs:
            runs[a] = plant(run(origin=COM) if a == "origin" else run(a))
        path = os.path.join(work, f"{i:02d}.h5")
        write(path, reported(runs[a], **rewritten), **written)
        named, stray = caught(judge(octocd, path)[1])
        rowless = written.get("contacts", "rows") != "rows"  # a row fault has no row to act on
        out[name] = (stray, {fault: None if rowless and fault in ROW_FAULTS else
                             sorted(named.get(FAULT_BODY[fault], ())) for fault in FAULTS})
    return out


HEADER = "| declared | " + " | ".join(FAULTS) + " |"


def table(measured):
    lines = [HEADER, "|---" * (len(FAULTS) + 1) + "|"]
    for name, (_, found) in measured.items():
        lines.append(f"| {name} | " + " | ".join("no rows" if found[f] is None else " ".join(found[f]) or "**missed**"
                                                 for f in FAULTS) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as work:
        result = measure(sys.argv[1], work)
    for name, (stray, _) in result.items():
        for failure in stray:
            print(f"declared {name}: {failure}", file=sys.stderr)
    print(table(result))
