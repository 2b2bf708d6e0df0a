"""Rapier and Jolt as process engines (reference/rapier, reference/jolt; docs/engines.md) on
short windows of box-stack and rot-drop-220: `octocd validate SCENE --engine NAME --trace T`
writes the run request, runs the engine and judges its version 2 trace; the clean verdict
holds only the expected failures (each an engine fault with its witness from the engine's own
API, or a rule defect named with its issue item, docs/engines.md), and each planted fault
edited into a copy of T fails its row naming the frame (`validate --trace-in`).

Run by ctest (label `corpus`) with OCTOCD_BIN and OCTOCD_SOURCE_DIR set; skipped, saying why,
where Node.js or reference/node_modules (scripts/install-deps.sh --tests) is missing.
"""
import json
import os
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

h5py = pytest.importorskip("h5py", reason="python3-h5py is not installed")

SOURCE_DIR = os.environ.get("OCTOCD_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SOURCE_DIR, "build", "octocd"))
ENGINES = {"rapier": "reference/rapier/rapier_engine.js", "jolt": "reference/jolt/jolt_engine.js"}
SCENES = {"box-stack": 60, "rot-drop-220": 80}


def engine_ready(engine):
    if shutil.which("node") is None:
        return "node is not installed (scripts/install-deps.sh --tests)"
    r = subprocess.run(["node", os.path.join(SOURCE_DIR, ENGINES[engine]), "--check"], capture_output=True, text=True)
    return None if r.returncode == 0 else f"{engine}: --check failed ({r.stderr.strip()[-200:]}; npm ci --prefix reference)"


def engine_param(e):
    why = engine_ready(e)
    return pytest.param(e, marks=pytest.mark.skipif(why is not None, reason=why or ""))


def octocd(*args):
    return subprocess.run([BIN, *args], capture_output=True, text=True)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("process-js")


_traces = {}


def run_engine(workdir, engine, scene, frames):
    """(the validate run, its trace) of the engine on the scene's first `frames` steps."""
    trace = workdir / f"{engine}--{scene}.h5"
    r = octocd("validate", os.path.join(SOURCE_DIR, "datasets", "scenes", scene + ".json"), "--engine", engine,
               "--frames", str(frames), "--trace", str(trace))
    assert r.returncode in (0, 3), r.stdout + r.stderr
    return r, trace


def clean_run(workdir, engine, scene):
    """(validate's output, the trace) of the engine's clean run, run once per module."""
    key = (engine, scene)
    if key not in _traces:
        r, trace = run_engine(workdir, engine, scene, SCENES[scene])
        _traces[key] = (r.stdout, trace)
    return _traces[key]


def clean_trace(workdir, engine, scene):
    return clean_run(workdir, engine, scene)[1]


def verdict(out, row):
    m = re.search(r"(^|\n)physics +" + re.escape(row) + r" +\S+ +\S+ +(pass|FAIL|n/a)", out)
    return m.group(2) if m else "missing"


def failing_rows(out):
    return {row for row in re.findall(r"^physics +([a-z-]+) +\S+ +\S+ +FAIL", out, re.M)}


# The rows a clean run may fail, each an engine fault witnessed from the engine's own API
# (docs/engines.md, "Rapier" and "Jolt"; WITNESSES below checks the figure in the trace).
EXPECTED = {
    ("rapier", "box-stack"): set(),
    # Rapier's reused manifold of pair (11, 79): solver contacts kept from frame 46 while the
    # shapes separate beyond the 2 cm prediction distance (contact-completeness: false contacts,
    # worst 3.096 cm apart at frame 80), and at frame 62 its solver applies 0.2205 N s on them
    # at points that ride on each body, changing the pair's angular momentum (conservation).
    ("rapier", "rot-drop-220"): {"contact-completeness", "conservation"},
    ("jolt", "box-stack"): set(),
    ("jolt", "rot-drop-220"): set(),
}


def witness_rapier_apart(f):
    """Rapier's own exact query (Shape.contactShape, parry) at the detection pose, written by
    the engine: rows on pairs it puts beyond the prediction distance, the worst distance and
    the largest impulse its solver applied on such a pair in one step."""
    assert f.attrs["rapier_apart_rows"] > 0
    assert f.attrs["rapier_apart_worst_m"] > f.attrs["contact_margin"] + 0.01  # 3.096 cm at frame 80
    assert f.attrs["rapier_apart_worst_jn_at"] == "frame 62 pair (11, 79)"
    assert f.attrs["rapier_apart_worst_jn"] > 0.2  # N s on shapes more than 2 cm apart


WITNESSES = {("rapier", "rot-drop-220"): witness_rapier_apart}


@pytest.mark.parametrize("scene", list(SCENES))
@pytest.mark.parametrize("engine", [engine_param(e) for e in ENGINES])
def test_clean_run_fails_only_the_expected_rows(workdir, engine, scene):
    out, trace = clean_run(workdir, engine, scene)
    with h5py.File(trace, "r") as f:
        assert f["states/position"].shape == (SCENES[scene] + 1, f.attrs["body_count"], 3)
        assert f.attrs["scene"] == json.loads(json.dumps(f.attrs["scene"]))
        assert f.attrs["wall_step_seconds"] > 0
        assert f.attrs["deactivation"] == "off"
        if (engine, scene) in WITNESSES:
            WITNESSES[(engine, scene)](f)
    assert failing_rows(out) == EXPECTED[(engine, scene)], out
    for row in ("contact-geometry", "penetration"):
        assert verdict(out, row) == "pass", out


def test_request_errors_name_the_field(workdir):
    if engine_ready("rapier"):
        pytest.skip(engine_ready("rapier"))
    bad = workdir / "bad.json"
    bad.write_text(json.dumps({"format": "octocd-run-request", "version": 1, "trace": str(workdir / "x.h5"),
                               "frames": -3}))
    r = subprocess.run(["node", os.path.join(SOURCE_DIR, ENGINES["rapier"]), str(bad)], capture_output=True, text=True)
    assert r.returncode == 1 and "frames: -3; allowed: an integer in [0," in r.stderr, r.stderr
    assert not (workdir / "x.h5").exists()


def rows_of(f, frame):
    off = f["/contacts/offsets"][...]
    return range(int(off[frame - 1]), int(off[frame]))


def touching(f, frame):
    pair = f["/contacts/pair"]
    return {int(b) for r in rows_of(f, frame) for b in pair[r]}


def lone_body(f):
    """(frame, body): a dynamic body without rows in that step and the next, moving."""
    w = f["/bodies/inverse_mass"][...]
    vel = f["/states/velocity"]
    for frame in range(3, f["/states/position"].shape[0] - 2):
        near = touching(f, frame) | touching(f, frame + 1)
        for i in np.nonzero(w > 0)[0]:
            if int(i) not in near and np.linalg.norm(vel[frame, i]) > 0.05:
                return frame, int(i)
    pytest.skip("no body in free flight in this trace")


def deep_row(f):
    """(frame, row): the deepest row between two bodies."""
    depth, off = f["/contacts/depth"][...], f["/contacts/offsets"][...]
    best = max(range(len(depth)), key=lambda r: depth[r])
    frame = int(np.searchsorted(off, best, side="right"))
    return frame, best


FAULTS = {"flipped normal": "contact-geometry", "velocity x1.5": "free-flight",
          "teleport into its partner": "penetration", "friction 1.2x cone": "friction"}


@pytest.mark.parametrize("fault", list(FAULTS))
@pytest.mark.parametrize("engine", [engine_param(e) for e in ENGINES])
def test_planted_faults_fail_naming_the_frame(workdir, engine, fault):
    trace = clean_trace(workdir, engine, "rot-drop-220")
    copy = trace.parent / f"{trace.stem}--{fault.replace(' ', '-')}.h5"
    shutil.copyfile(trace, copy)
    with h5py.File(copy, "r+") as f:
        if fault == "friction 1.2x cone":
            if "/contacts/jt3" not in f:
                pytest.skip(f"{engine} reports no friction impulses (declared: impulses "
                            f"{f.attrs.get('impulses', 'not complete')}): the friction row is n/a, never judged on zeros")
        if fault == "flipped normal":
            frame, r = deep_row(f)
            f["/contacts/normal"][r] = -f["/contacts/normal"][r]
            item = [f"frame {frame} pair ({', '.join(str(int(x)) for x in f['/contacts/pair'][r])})"]
        elif fault == "velocity x1.5":
            frame, i = lone_body(f)
            f["/states/velocity"][frame, i] = f["/states/velocity"][frame, i] * 1.5
            item = [f"frame {frame + k} body {i}" for k in (0, 1)]
        else:  # teleport: body B of the deepest row moved 5 cm along the normal (from B to A) into A
            frame, r = deep_row(f)
            a, b = (int(x) for x in f["/contacts/pair"][r])
            moved = b if f["/bodies/inverse_mass"][b] > 0 else a
            sign = 1.0 if moved == b else -1.0
            f["/states/position"][frame, moved] = f["/states/position"][frame, moved] + \
                sign * 0.05 * np.array(f["/contacts/normal"][r])
            item = [f"frame {frame + 1} pair ({a}, {b})"]
    r = octocd("validate", "--trace-in", str(copy))
    assert r.returncode == 3, f"{engine}, {fault} not caught:\n{r.stdout}{r.stderr}"
    assert verdict(r.stdout, FAULTS[fault]) == "FAIL", f"{engine}, {fault}: row {FAULTS[fault]}\n{r.stdout}"
    row = re.search(r"^physics +" + FAULTS[fault] + r" .*?(?=^physics|\Z)", r.stdout, re.M | re.S).group(0)
    assert any(it in row for it in item), f"{engine}, {fault}: {item} not named\n{row}"


# Rapier's faults on the engine matrix's full windows (scripts/nightly.sh --matrix full;
# scripts/nightly-expect.json names this test), each witnessed by Rapier's own exact query
# (Shape.contactShape at the detection pose) that the engine writes as root attributes.
RAPIER_MATRIX_WITNESSES = {
    # reused manifolds: pair (11, 79) loaded with 0.2205 N s at frame 62 while the shapes are
    # more than 2 cm apart (false contacts, its angular momentum); pair (162, 198) penetrating
    # 7.0 mm beyond its deepest row's depth (a frozen contactDist: contact-geometry depth).
    # Rapier's own angular momentum of the isolated groups the conservation row fails (below).
    ("rot-drop-220", 400): {"rapier_apart_worst_jn_at": "frame 62 pair (11, 79)", "apart_jn": 0.2,
                            "rapier_depth_gap_worst_at": "frame 289 pair (162, 198)", "depth_gap": 0.005,
                            "own_angular": {"(11, 79)": (0.006853, 62), "(105, 132)": (0.003542, 202),
                                            "(114, 131)": (0.001655, 128), "(71, 153)": (0.001030, 220),
                                            "(50, 57, 63)": (0.002228, 226)}},
    # a pair penetrating 4.80 mm whose manifolds hold no solver contact (missing contact); the
    # isolated pairs whose angular momentum about their centre of mass changes, in Rapier's own
    # mass, inertia and velocities (RigidBody.mass, worldCom, linvel, angvel,
    # effectiveAngularInertia), by the figures the conservation row reads from the trace: pairs
    # that meet without spin (dt 1 ms) and leave with a net angular momentum (conservation).
    ("rot-pile-1000", 150): {"rapier_missed_worst_at": "frame 150 pair (719, 896)", "missed": 0.0045,
                             "own_angular": {"(806, 938)": (0.005207, 101), "(807, 833)": (0.004656, 113),
                                             "(521, 985)": (0.003010, 108), "(624, 738)": (0.002724, 82),
                                             "(454, 762)": (0.002099, 98)}},
    # pair (12, 21) of the bunny stack: Rapier's own query finds it 2.02 cm deep at frame 388
    # and its own rows read the same depth there (penetration).
    # and coincident tracked points that both changed their impulse, which the writer cannot
    # tell apart (momentum-balance: bodies 8 and 26 at frame 530).
    ("bunny-stack-50", 600): {"rapier_deepest_at": "frame 388 pair (12, 21)", "deepest": 0.0200, "ambiguous": 100},
}


@pytest.mark.parametrize("scene,frames", list(RAPIER_MATRIX_WITNESSES))
def test_rapier_matrix_faults_witnessed_from_its_own_query(workdir, scene, frames):
    why = engine_ready("rapier")
    if why:
        pytest.skip(why)
    trace = workdir / f"rapier--{scene}--matrix.h5"
    r = octocd("run", os.path.join(SOURCE_DIR, "datasets", "scenes", scene + ".json"), "--engine", "rapier",
               "--rotation", "--frames", str(frames), "--state-every", "1", "--contacts", "--trace", str(trace),
               "--no-xdmf", "--quiet")
    assert r.returncode == 0, r.stdout + r.stderr
    w = RAPIER_MATRIX_WITNESSES[(scene, frames)]
    with h5py.File(trace, "r") as f:
        a = dict(f.attrs)
    for key in ("rapier_apart_worst_jn_at", "rapier_depth_gap_worst_at", "rapier_missed_worst_at", "rapier_deepest_at"):
        if key in w:
            assert a[key] == w[key], (key, a[key])
    if "apart_jn" in w:
        assert a["rapier_apart_worst_jn"] > w["apart_jn"] and a["rapier_apart_worst_m"] > a["contact_margin"]
    if "depth_gap" in w:
        assert a["rapier_depth_gap_worst_m"] > w["depth_gap"]
    if "missed" in w:
        assert a["rapier_missed_worst_m"] > w["missed"]
    if "ambiguous" in w:
        assert a["rapier_duplicate_ambiguous"] > w["ambiguous"]
    if "deepest" in w:
        assert a["rapier_deepest_m"] > w["deepest"]
        assert abs(a["rapier_deepest_rows_m"] - a["rapier_deepest_m"]) < 1e-4  # its rows read the depth too
    if "own_angular" in w:
        own = {m.group(1): (float(m.group(2)), int(m.group(3))) for m in re.finditer(
            r"(\([\d, ]+\)) ([0-9.e+-]+) of [0-9.e+-]+ frame (\d+)", a["rapier_own_angular_momentum_groups"])}
        for pair, (change, frame) in w["own_angular"].items():
            assert pair in own, (pair, a["rapier_own_angular_momentum_groups"])
            assert own[pair][1] == frame and abs(own[pair][0] - change) < 2e-6, (pair, own[pair])


# Jolt's faults on the engine matrix's full windows (scripts/nightly-expect.json names this
# test), each witnessed by Jolt's own API, which the engine writes as root attributes:
JOLT_MATRIX_WITNESSES = {
    # pair (6, 30) at frame 400: the manifold's normal is 80.7 deg from the penetration axis of
    # Jolt's own fresh query on the same pose (TransformedShape::CollideShape, no body-pair
    # cache), which finds the 0.056 mm overlap SAT finds: the cached manifold's normal is stale.
    ("rot-drop-220", 400): {"jolt_fresh_normal_angle_worst_at": "frame 400 pair (6, 30)", "fresh_angle": 80.0,
                            "fresh_depth": 1e-4},
    # pair (680, 817): a point of its manifold (GetWorldSpaceContactPointOn1/2) lies 5.2 cm
    # outside Jolt's own local bounds of its body's shape (Shape::GetLocalBounds at the body's
    # centre-of-mass transform); other pairs' manifold points up to 0.4 m outside.
    ("rot-pile-1000", 150): {"outside_pair": "(680, 817)", "outside": 0.05},
}


@pytest.mark.parametrize("scene,frames", list(JOLT_MATRIX_WITNESSES))
def test_jolt_matrix_faults_witnessed_from_its_own_api(workdir, scene, frames):
    why = engine_ready("jolt")
    if why:
        pytest.skip(why)
    trace = workdir / f"jolt--{scene}--matrix.h5"
    r = octocd("run", os.path.join(SOURCE_DIR, "datasets", "scenes", scene + ".json"), "--engine", "jolt",
               "--rotation", "--frames", str(frames), "--state-every", "1", "--contacts", "--trace", str(trace),
               "--no-xdmf", "--quiet")
    assert r.returncode == 0, r.stdout + r.stderr
    w = JOLT_MATRIX_WITNESSES[(scene, frames)]
    with h5py.File(trace, "r") as f:
        a = dict(f.attrs)
    if "fresh_angle" in w:
        assert a["jolt_fresh_normal_angle_worst_at"] == w["jolt_fresh_normal_angle_worst_at"]
        assert a["jolt_fresh_normal_angle_worst_deg"] > w["fresh_angle"]
        assert 0 < a["jolt_fresh_depth_at_worst_m"] < w["fresh_depth"]
    if "outside_pair" in w:
        pairs = {m.group(1): float(m.group(2)) for m in
                 re.finditer(r"(\(\d+, \d+\)) ([0-9.]+) m frame \d+", a["jolt_point_outside_own_bounds_pairs"])}
        assert pairs.get(w["outside_pair"], 0) > w["outside"], a["jolt_point_outside_own_bounds_pairs"]


def one_depth_per_manifold(src, dst):
    """Copies trace `src` to `dst` with every row carrying its manifold's one depth (the
    deepest row of its pair in its step, as Jolt's mPenetrationDepth), declared depth_per
    "manifold"; returns how many rows changed."""
    shutil.copyfile(src, dst)
    with h5py.File(dst, "r+") as f:
        offsets, pairs = f["/contacts/offsets"][:], f["/contacts/pair"][:]
        depth = f["/contacts/depth"][:]
        out = depth.copy()
        for s in range(len(offsets) - 1):
            k, end = int(offsets[s]), int(offsets[s + 1])
            while k < end:  # a manifold's rows are consecutive (docs/trace-format.md)
                e = k
                while e < end and (pairs[e] == pairs[k]).all():
                    e += 1
                out[k:e] = depth[k:e].max()
                k = e
        f["/contacts/depth"][:] = out
        f.attrs["depth_per"] = "manifold"
        return int((out != depth).sum())


def test_jolt_one_depth_per_manifold_passes_as_declared(workdir):
    """Jolt's rows with one depth per manifold, declared depth_per "manifold" (the docs'
    example for Jolt): each pair's depth is judged against the deepest point of the overlap
    along the manifold's normal, not the hulls' overlap projected on it (which read the far
    edge of the 6 m ground box under normals 0.5-1.4 deg off vertical: 87 false depth items
    of 1,104 pairs on this window); a manifold 1 cm deeper than the shapes still fails."""
    why = engine_ready("jolt")
    if why:
        pytest.skip(why)
    trace = clean_trace(workdir, "jolt", "rot-drop-220")
    copy = workdir / "jolt--rot-drop-220--manifold.h5"
    assert one_depth_per_manifold(trace, copy) > 100
    r = octocd("validate", "--trace-in", str(copy))
    assert verdict(r.stdout, "contact-geometry") == "pass", r.stdout
    assert 'depth_per "manifold"' in r.stdout, r.stdout
    with h5py.File(copy, "r+") as f:
        frame, row = deep_row(f)
        offsets, pairs = f["/contacts/offsets"][:], f["/contacts/pair"][:]
        rows = [k for k in range(int(offsets[frame - 1]), int(offsets[frame])) if (pairs[k] == pairs[row]).all()]
        for k in rows:
            f["/contacts/depth"][k] = f["/contacts/depth"][k] + 0.01
        item = f"frame {frame}: pair ({', '.join(str(int(x)) for x in pairs[row])}) manifold depth"
    r = octocd("validate", "--trace-in", str(copy))
    assert verdict(r.stdout, "contact-geometry") == "FAIL", r.stdout
    assert item in r.stdout, r.stdout
