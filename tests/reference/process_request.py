"""A process engine's run request (format "octocd-run-request", version 1; docs/engines.md,
"Rapier" and "Jolt") built from octocd's own scene set-up: `octocd run SCENE --engine bullet
--rotation --frames 1` gives the bodies in octocd's order (/bodies: local boxes, inverse mass,
inertia) and state 0; every body gets the scene's material (mu_static, restitution); meshes
are placed in the body frame as the trace format does (their bounds centred on the local
box). Used by tests/reference/test_process_js.py until octocd writes requests itself.

    process_request.py OCTOCD SCENE.json FRAMES TRACE REQUEST [KEY=VALUE ...]
"""
import json
import math
import os
import subprocess
import sys
import tempfile

import h5py
import numpy as np


def icosphere(radius, subdivisions):
    """octocd's icosphere (core/src/mesh.cpp make_icosphere): vertices and triangles."""
    t = (1 + 5 ** 0.5) / 2
    base = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
            (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]

    def on(p):
        s = radius / math.sqrt(sum(c * c for c in p))
        return tuple(float(np.float32(c * s)) for c in p)
    v = [on(p) for p in base]
    tris = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
            (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
            (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        cache, out = {}, []

        def mid(i, j):
            k = (min(i, j), max(i, j))
            if k not in cache:
                a, b = v[i], v[j]
                v.append(on((a[0] + b[0], a[1] + b[1], a[2] + b[2])))
                cache[k] = len(v) - 1
            return cache[k]
        for a, b, c in tris:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            out += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        tris = out
    return np.array(v), np.array(tris)


def load_mesh(path):
    """Vertices and triangles of an OBJ or OFF file (polygons fanned)."""
    v, tris = [], []
    lines = open(path).read().split("\n")
    if path.endswith(".off"):
        head = [x for x in lines if x.strip() and not x.startswith("#")]
        nv, nf = (int(x) for x in head[1].split()[:2])
        v = [[float(x) for x in head[2 + k].split()[:3]] for k in range(nv)]
        for k in range(nf):
            idx = [int(x) for x in head[2 + nv + k].split()[1:]]
            tris += [(idx[0], idx[j], idx[j + 1]) for j in range(1, len(idx) - 1)]
    else:
        for line in lines:
            p = line.split()
            if p and p[0] == "v":
                v.append([float(x) for x in p[1:4]])
            elif p and p[0] == "f":
                idx = [int(x.split("/")[0]) - 1 for x in p[1:]]
                tris += [(idx[0], idx[j], idx[j + 1]) for j in range(1, len(idx) - 1)]
    return np.array(v), np.array(tris)


def make_request(octocd, scene_path, frames, trace, settings=None, source_dir="."):
    """The request (a dict) for `frames` steps of the scene, writing `trace`."""
    with tempfile.TemporaryDirectory() as tmp:
        probe = os.path.join(tmp, "probe.h5")
        subprocess.run([octocd, "run", scene_path, "--engine", "bullet", "--rotation", "--frames", "1",
                        "--state-every", "1", "--trace", probe, "--no-xdmf", "--quiet"], check=True,
                       capture_output=True)
        with h5py.File(probe, "r") as f:
            return _request(f, frames, trace, settings or {}, source_dir)


def _request(f, frames, trace, settings, source_dir):
    scene_json = f.attrs["scene"]
    scene = json.loads(scene_json)
    groups = {g["name"]: g for g in scene["groups"]}
    names = f["bodies/shape_names"].asstr()[:]
    sid, group = f["bodies/shape_id"][:], f["bodies/group"].asstr()[:]
    lo, hi = f["bodies/local_aabb_min"][:].astype(float), f["bodies/local_aabb_max"][:].astype(float)
    im, inertia = f["bodies/inverse_mass"][:], f["bodies/inertia"][:].astype(float)
    pos, vel = f["states/position"][0], f["states/velocity"][0]
    q, w = f["states/orientation"][0], f["states/angular_velocity"][0]
    meshes, mesh_of, bodies = [], {}, []
    for i in range(len(im)):
        shape = groups[group[i]]["shape"] if group[i] in groups else {"box": None}
        b = {"group": str(group[i]), "static": bool(im[i] == 0), "mass": 0.0 if im[i] == 0 else float(1 / im[i]),
             "inertia": inertia[i].tolist() if im[i] > 0 else [[0.0] * 3] * 3,
             "local_aabb_min": lo[i].tolist(), "local_aabb_max": hi[i].tolist(),
             "position": pos[i].astype(float).tolist(), "orientation": q[i].astype(float).tolist(),
             "velocity": vel[i].astype(float).tolist(), "angular_velocity": w[i].astype(float).tolist(),
             # the scene's material itself: each process engine combines two bodies' values by
             # its own rule and declares it (Bullet's trace holds sqrt(mu) for its product rule)
             "friction": float(f.attrs["mu"]), "restitution": float(f.attrs["restitution"])}
        if "box" in shape:
            b.update(shape="box", half_extents=((hi[i] - lo[i]) / 2).tolist())
        else:
            name = names[sid[i]]
            if name not in mesh_of:
                file = ""
                if "icosphere" in shape:
                    v, t = icosphere(shape["icosphere"]["radius"], shape["icosphere"].get("subdivisions", 2))
                else:
                    for d in ("datasets/scenes/meshes", "datasets/cache"):
                        for ext in (".obj", ".off"):
                            p = os.path.join(source_dir, d, shape["mesh"] + ext)
                            file = p if os.path.exists(p) else file
                    v, t = load_mesh(file)
                # octocd sizes a dataset mesh to its `scale` (longest side); the local box has that size
                v = v * ((hi[i] - lo[i]).max() / (v.max(0) - v.min(0)).max())
                v = v - (v.min(0) + v.max(0)) / 2 + (lo[i] + hi[i]) / 2
                mesh_of[name] = len(meshes)
                meshes.append({"name": name, "file": file, "vertices": v.tolist(), "triangles": t.tolist()})
            b.update(shape="mesh", mesh=mesh_of[name])
        bodies.append(b)
    return {"format": "octocd-run-request", "version": 1, "engine": "", "trace": os.path.abspath(trace),
            "frames": int(frames), "dt": float(scene.get("dt", 0.001)),
            "gravity": [float(x) for x in f.attrs["gravity"]], "rotation": True, "settings": dict(settings),
            "scene_name": scene["name"], "scene_json": scene_json,
            "response": {"mu": float(f.attrs["mu"]), "restitution": float(f.attrs["restitution"])},
            "meshes": meshes, "bodies": bodies}


if __name__ == "__main__":
    octocd, scene, frames, trace, out = sys.argv[1:6]
    settings = dict(a.split("=", 1) for a in sys.argv[6:])
    req = make_request(octocd, scene, int(frames), trace, settings,
                       source_dir=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
    with open(out, "w") as f:
        json.dump(req, f)
