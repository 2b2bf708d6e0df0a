"""octocd.Trace on traces of format version 2 (issue 17, design.md section 13; docs/trace-format.md,
"External traces, version 2"): orientations, angular velocities, inertia, materials and
manifold contacts with points, as NumPy arrays.

Oracles: the file's own datasets read with h5py (bit for bit); closed forms (the scenes'
stated initial tilt, the solid-box inertia, the example writer's spin); the posed shapes
(every contact point lies on both bodies' boxes, placed by the orientations, within the
contact margin); Bullet's own integration (each orientation step is the angular velocity
times dt); and bad input that must raise InputError naming dataset, frame and body.
"""
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

octocd = pytest.importorskip(
    "octocd", reason="the octocd Python module is not built (configure with OCTOCD_PYTHON=ON and "
    "python3-pybind11, and put build/python on PYTHONPATH)")
h5py = pytest.importorskip("h5py", reason="python3-h5py is not installed")

SOURCE_DIR = os.environ.get("OCTOCD_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
SCENES = os.path.join(SOURCE_DIR, "datasets", "scenes")
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SOURCE_DIR, "build", "octocd"))
WRITER = os.path.join(SOURCE_DIR, "examples", "python", "rotating_writer.py")


def need_cli():
    if not os.access(BIN, os.X_OK):
        pytest.skip(f"the octocd CLI is not built at {BIN} (set OCTOCD_BIN)")


def bullet_trace(tmp_path, scene, frames):
    """`octocd run SCENE --engine bullet --rotation`: a version 2 trace of every state."""
    need_cli()
    out = str(tmp_path / (scene + ".h5"))
    subprocess.run([BIN, "run", os.path.join(SCENES, scene + ".json"), "--engine", "bullet", "--rotation",
                    "--frames", str(frames), "--state-every", "1", "--contacts", "--trace", out, "--quiet",
                    "--no-xdmf"], check=True)
    return out


def qmul(q, r):
    """Hamilton product of (..., 4) quaternions (w, x, y, z)."""
    w1, x1, y1, z1 = np.moveaxis(np.asarray(q, np.float64), -1, 0)
    w2, x2, y2, z2 = np.moveaxis(np.asarray(r, np.float64), -1, 0)
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=-1)


def rotate(q, v):
    """v rotated by the unit quaternion q (body to world)."""
    qv = np.concatenate([[0.0], v])
    return qmul(qmul(q, qv), q * np.array([1, -1, -1, -1]))[1:]


def test_bullet_rotation_trace_exposes_orientation_angular_velocity_inertia_and_manifolds(tmp_path):
    path = bullet_trace(tmp_path, "rot-slope", 60)
    with octocd.Trace(path) as t, h5py.File(path, "r") as f:
        assert t.version == 2 and t.rotating and not t.external
        n = t.body_count
        assert n == 2  # the slope (static) and the box
        # Bit for bit what the file holds.
        s = len(t.state_frames)
        assert s == 61 and list(t.state_frames) == list(range(61))
        q_all, w_all = t.orientations, t.angular_velocities
        assert q_all.shape == (61, n, 4) and q_all.dtype == np.float32
        assert w_all.shape == (61, n, 3) and w_all.dtype == np.float32
        assert np.array_equal(q_all.view(np.uint32), f["states/orientation"][:s].view(np.uint32))
        assert np.array_equal(w_all.view(np.uint32), f["states/angular_velocity"][:s].view(np.uint32))
        q30, w30 = t.rotation(30)
        assert np.array_equal(q30, q_all[30]) and np.array_equal(w30, w_all[30])
        # Closed form: both bodies start tilted 20 degrees about z (the scene says so).
        h = math.radians(20) / 2
        assert np.allclose(q_all[0], [[math.cos(h), 0, 0, math.sin(h)]] * 2, atol=1e-6)
        assert np.allclose(np.linalg.norm(q_all.astype(np.float64), axis=-1), 1.0, atol=1e-6)
        # Bullet integrates each orientation by the step's angular velocity: the rotation from
        # row f - 1 to row f is w_f dt (world frame; float32 rows: 1e-3 rad/s).
        dt = float(t.attrs["dt"])
        for fr in range(1, s):
            d = qmul(q_all[fr, 1], q_all[fr - 1, 1] * np.array([1, -1, -1, -1]))
            d = d if d[0] >= 0 else -d
            assert np.allclose(2 * d[1:] / dt, w_all[fr, 1], atol=1e-3), fr
        # Inertia: Bullet's box inertia, the solid-box closed form m/12 (b^2 + c^2), ...
        inertia = t.inertia
        assert inertia.shape == (n, 3, 3) and np.array_equal(inertia, f["bodies/inertia"][:])
        lo, hi = f["bodies/local_aabb_min"][1].astype(float), f["bodies/local_aabb_max"][1].astype(float)
        a, b, c = hi - lo
        m = 1.0 / float(f["bodies/inverse_mass"][1])
        assert np.allclose(np.diag(inertia[1]), [m / 12 * (b * b + c * c), m / 12 * (a * a + c * c),
                                                 m / 12 * (a * a + b * b)], rtol=1e-5)
        assert not inertia[0].any()  # static
        mat = t.materials
        assert mat["friction_combine"] == "product" and mat["contact_margin"] > 0
        assert np.allclose(mat["body_friction"] ** 2, mat["mu"], rtol=1e-5)  # sqrt(mu) per body
        # Manifolds: the box on the slope has several rows for the pair (0, 1), each with a
        # world point on both posed boxes (within the contact margin), at the pre-step pose.
        margin = mat["contact_margin"]
        rows_seen = 0
        for fr in range(20, 61, 10):
            c = t.contacts(fr)
            assert set(c) == {"pair", "normal", "depth", "jn", "jt", "point"}
            by_pair = t.contacts_by_pair(fr)
            assert list(by_pair) == [(0, 1)]
            k = len(by_pair[(0, 1)]["depth"])
            assert k >= 2 and k == len(c["depth"])
            assert np.array_equal(by_pair[(0, 1)]["point"], c["point"])
            assert np.allclose(np.linalg.norm(c["normal"].astype(float), axis=1), 1.0, atol=1e-3)
            assert (c["depth"] >= 0).all() and (c["jn"] >= 0).all()
            x_pre, _ = t.state(fr - 1)
            q_pre, _ = t.rotation(fr - 1)
            for p in c["point"].astype(float):
                for body in (0, 1):
                    local = rotate(q_pre[body] * np.array([1, -1, -1, -1]), p - x_pre[body])
                    lo_b = f["bodies/local_aabb_min"][body] - margin
                    hi_b = f["bodies/local_aabb_max"][body] + margin
                    assert (local >= lo_b).all() and (local <= hi_b).all(), (fr, body, p, local)
                rows_seen += 1
        assert rows_seen >= 10
    assert octocd.Trace(path).version == 2


def test_rotating_writer_example_reads_as_the_closed_form(tmp_path):
    out = str(tmp_path / "spin.h5")
    subprocess.run([sys.executable, WRITER, out], check=True)
    F, DT, W = 100, 0.01, 2.0  # the writer's constants
    with octocd.Trace(out) as t:
        assert t.version == 2 and t.external and t.rotating and t.frames == {}
        assert list(t.state_frames) == list(range(F + 1))  # no /states/frame: 0..F
        for fr in (0, 1, 37, F):
            q, w = t.rotation(fr)
            a = W * DT * fr
            assert np.allclose(q, [[1, 0, 0, 0], [math.cos(a / 2), 0, math.sin(a / 2), 0]], atol=1e-6)
            assert np.array_equal(w, np.float32([[0, 0, 0], [0, W, 0]]))
        # No /bodies/inertia: derived, a solid box of side 0.2 at 1 kg; the floor is static.
        assert np.allclose(t.inertia[1], np.diag([0.08 / 12] * 3), rtol=1e-6) and not t.inertia[0].any()
        assert t.materials["mu"] == 0.0 and t.materials["body_friction"] is None
        for fr in (1, 50, F):  # step f's rows: offsets[f-1] .. offsets[f]-1
            c = t.contacts(fr)
            a = W * DT * (fr - 1)  # the pre-step pose
            corners = [(x, z) for x in (-0.1, 0.1) for z in (-0.1, 0.1)]
            expect = [[math.cos(a) * x + math.sin(a) * z, 0, math.cos(a) * z - math.sin(a) * x] for x, z in corners]
            assert np.allclose(c["point"], expect, atol=1e-6)
            m = t.contacts_by_pair(fr)
            assert list(m) == [(0, 1)] and len(m[(0, 1)]["jn"]) == 4
            assert np.allclose(m[(0, 1)]["jn"].sum(), 9.81 * DT)
        with pytest.raises(octocd.InputError, match=r"/contacts/offsets: no row for frame 101; allowed: frames 1..100"):
            t.contacts(F + 1)
    # The CLI on the example: compare with itself, then with one orientation turned 10 degrees.
    need_cli()
    assert subprocess.run([BIN, "compare", out, out], capture_output=True).returncode == 0
    turned = str(tmp_path / "turned.h5")
    shutil.copy(out, turned)
    with h5py.File(turned, "r+") as f:
        h = math.radians(10) / 2
        f["states/orientation"][40, 1] = np.float32(qmul([math.cos(h), math.sin(h), 0, 0],
                                                         f["states/orientation"][40, 1]))
    r = subprocess.run([BIN, "compare", out, turned], capture_output=True, text=True)
    assert r.returncode == 3, r.stdout + r.stderr
    assert "DIFFERENT: first at frame 40, body 1 (orientations)" in r.stdout
    with octocd.Trace(turned) as t:
        q = t.rotation(40)[0][1].astype(float)
        a = W * DT * 40
        p = np.array([math.cos(a / 2), 0, math.sin(a / 2), 0])
        assert abs(2 * math.acos(min(1.0, abs(q @ p))) - math.radians(10)) < 1e-3


def test_bad_version_2_input_names_dataset_frame_and_allowed(tmp_path):
    good = str(tmp_path / "spin.h5")
    subprocess.run([sys.executable, WRITER, good], check=True)

    def variant(name, edit):
        p = str(tmp_path / name)
        shutil.copy(good, p)
        with h5py.File(p, "r+") as f:
            edit(f)
        return p

    p = variant("v3.h5", lambda f: f.attrs.modify("version", 3))
    with pytest.raises(octocd.InputError, match=r"v3\.h5: version: 3; allowed: 1 or 2"):
        octocd.Trace(p)

    def scale(f):
        f["states/orientation"][5, 1] = f["states/orientation"][5, 1] * np.float32(1.01)
    p = variant("nonunit.h5", scale)
    with octocd.Trace(p) as t:
        t.rotation(4)  # the other rows are fine
        with pytest.raises(octocd.InputError, match=r"nonunit\.h5: /states/orientation: frame 5: body 1: .*"
                                                    r"\|q\| = 1\.01; allowed: unit quaternions"):
            t.rotation(5)
        with pytest.raises(octocd.InputError, match=r"/states/orientation: frame 5: body 1"):
            t.orientations

    p = variant("no-w.h5", lambda f: f.__delitem__("states/angular_velocity"))
    with pytest.raises(octocd.InputError, match=r"/states/angular_velocity: missing \(/states/orientation present\); "
                                                r"allowed: /states/orientation and /states/angular_velocity together"):
        octocd.Trace(p)
    p = variant("mixed.h5", lambda f: f.attrs.modify("version", 1))
    with pytest.raises(octocd.InputError, match=r"mixed\.h5: /states/orientation: a version 2 dataset in a version 1 "
                                                r"trace \(v1/v2 fields mixed\)"):
        octocd.Trace(p)

    def shape(f):
        del f["states/orientation"]
        f["states/orientation"] = np.zeros((101, 2, 3), np.float32)
    p = variant("shape.h5", shape)
    with pytest.raises(octocd.InputError, match=r"/states/orientation: shape 101 x 2 x 3; allowed: states x 2 "
                                                r"bodies x 4"):
        octocd.Trace(p)
    p = variant("inertia.h5", lambda f: f.create_dataset("bodies/inertia", data=np.zeros((2, 3), np.float32)))
    with octocd.Trace(p) as t, pytest.raises(octocd.InputError, match=r"/bodies/inertia: shape 2 x 3; allowed: 2 x 3 "
                                                                      r"x 3"):
        t.inertia


def test_external_version_1_trace_reads_unrotated(tmp_path):
    """examples/python/toy_engine.py writes an external trace of version 1: no /frames, no
    /states/frame, contacts by position; it reads as unrotated with the solid-box inertia."""
    out = str(tmp_path / "toy.h5")
    subprocess.run([sys.executable, os.path.join(SOURCE_DIR, "examples", "python", "toy_engine.py"), out],
                   check=True, capture_output=True)
    with octocd.Trace(out) as t, h5py.File(out, "r") as f:
        n = t.body_count
        assert t.version == 1 and t.external and not t.rotating and t.frames == {}
        s = len(t.state_frames)
        q, w = t.rotation(s - 1)
        assert np.array_equal(q, np.tile(np.float32([1, 0, 0, 0]), (n, 1))) and not w.any()
        assert t.orientations.shape == (s, n, 4) and not t.angular_velocities.any()
        off = f["contacts/offsets"][:]
        for fr in range(1, s):
            c = t.contacts(fr)
            assert "point" not in c
            assert np.array_equal(c["pair"], f["contacts/pair"][off[fr - 1]:off[fr]])
            assert sum(len(v["jn"]) for v in t.contacts_by_pair(fr).values()) == len(c["jn"])
        half = (f["bodies/local_aabb_max"][:] - f["bodies/local_aabb_min"][:]) / 2
        m = np.where(f["bodies/inverse_mass"][:] > 0, 1 / np.maximum(f["bodies/inverse_mass"][:], 1e-30), 0)
        assert np.allclose(t.inertia[:, 1, 1], m / 3 * (half[:, 0] ** 2 + half[:, 2] ** 2), rtol=1e-6)


def test_attrs_holds_every_declaration_docs_list(tmp_path):
    """Trace.attrs gives every root-attribute declaration of docs/validate-your-engine.md's
    table (its first column's names, datasets aside) that a trace carries: a declaration
    added to the reader and the docs but not to the Python reader fails here."""
    doc = open(os.path.join(SOURCE_DIR, "docs", "validate-your-engine.md"), encoding="utf-8").read()
    table = doc[doc.index("| declaration | values |"):].split("\n\n")[0]
    names = set()
    for row in table.splitlines()[2:]:
        first = row.split("|")[1]
        names.update(n for n in first.replace("`", " ").replace(",", " ").split() if not n.startswith("/"))
    assert {"integrated_point", "impulse_points", "contact_model", "speculative"} <= names
    out = str(tmp_path / "toy.h5")
    subprocess.run([sys.executable, os.path.join(SOURCE_DIR, "examples", "python", "toy_engine.py"), out],
                   check=True, capture_output=True)
    with h5py.File(out, "a") as f:
        for k in names:
            f.attrs[k] = "declared-" + k
    with octocd.Trace(out) as t:
        missing = sorted(k for k in names if t.attrs.get(k) != "declared-" + k)
    assert not missing, f"Trace.attrs lacks {missing}"
