"""Traces keep their meaning (ctest label `corpus`; docs/validate-your-engine.md,
"Declarations" and "What a trace must carry"):

- a version 2 trace written to an earlier docs/trace-format.md (scalar `jt`, no `jt3`, no
  declarations; tests/scene/legacy_trace.py makes one from a real engine's run) is judged
  on what it carries: clean it passes, planted faults fail where the rows stay judged, and
  rows needing what it lacks are n/a naming the dataset to add, never failed;
- `validate --trace-in T --check-only` lists each row judged or n/a with what to add;
- what an engine is comes from declarations, never from its name: octocd's own traces
  declare their conventions, a renamed engine is judged the same, an octocd trace written
  before the declarations is read as then;
- `/states/sleeping` and `deactivation`: a body the engine put to sleep is judged not to
  move, not as free-flying.

Run by ctest with OCTOCD_BIN and OCTOCD_SOURCE_DIR set.
"""
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

h5py = pytest.importorskip("h5py", reason="python3-h5py is not installed")

import test_engine_corpus as corpus  # noqa: E402  (its engine runs and helpers)
from legacy_trace import make_legacy  # noqa: E402


def _row_table():
    """Every row's name in the row table's order, and the physics tier's
    (validation/include/octocd/validation_rows.def)."""
    with open(os.path.join(corpus.SOURCE_DIR, "validation", "include", "octocd", "validation_rows.def")) as f:
        rows = re.findall(r'^OCTOCD_ROW\(\w+, "([a-z0-9-]+)", (\w+),', f.read(), re.M)
    assert len(rows) >= 16, rows
    return [name for name, _ in rows], [name for name, tier in rows if tier == "Physics"]


ROWS, PHYSICS_ROWS = _row_table()
CONTACT_ROWS = ["contact-completeness", "contact-geometry", "friction", "conservation", "momentum-balance",
                "free-flight"]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("meaning")


def check_only(trace):
    """{row: 'judged ...' or 'n/a ...'} from `validate --trace-in T --check-only`."""
    r = corpus.octocd("validate", "--trace-in", str(trace), "--check-only")
    assert r.returncode == 0, r.stdout + r.stderr
    return {m.group(1): m.group(2) for m in re.finditer(r"^(?:physics|model) +([a-z0-9-]+) +(\S.*)$", r.stdout, re.M)}


def detail(out, row):
    m = re.search(r"^(?:physics|model) +" + re.escape(row) + r" .*\n +(.*)$", out, re.M)
    return m.group(1) if m else ""


def failures(out):
    return set(re.findall(r"^NEW FAILURE ([a-z-]+)/([a-z-]+):", out, re.M))


def edited(trace, name, edit):
    copy = trace.parent / f"{trace.stem}--{name}.h5"
    shutil.copyfile(trace, copy)
    with h5py.File(copy, "r+") as f:
        frame = edit(f)
    return corpus.judge(copy), frame


# ---- a version 2 trace of an earlier format, from a real engine's run -----------------

@pytest.mark.parametrize("engine", [corpus.engine_param(e) for e in ("bullet", "ode")])
def test_an_earlier_version_2_trace_is_judged_on_what_it_carries(workdir, engine):
    clean = corpus.base_trace(workdir, engine, corpus.DROP, 120)
    legacy = make_legacy(clean, workdir / f"{engine}--legacy.h5")
    with h5py.File(legacy, "r") as f:
        assert "/contacts/jt3" not in f and "contact_model" not in f.attrs and "/contacts/jt" in f
    plan = check_only(legacy)
    assert list(plan) == ROWS, plan
    assert plan["friction"].startswith("judged; partly: add /contacts/jt3"), plan["friction"]
    # Its scalar jt is the friction's component along the sliding only: an engine with two
    # friction directions (ODE) leaves the second out, so momentum-balance needs jt3 or the
    # declaration that there is one direction.
    assert plan["momentum-balance"].startswith("n/a    add /contacts/jt3"), plan["momentum-balance"]
    assert "friction_directions = 1" in plan["momentum-balance"], plan["momentum-balance"]
    for row in PHYSICS_ROWS:
        assert plan[row].startswith("judged" if row != "momentum-balance" else "n/a"), (row, plan[row])
    r = corpus.judge(legacy)
    assert corpus.verdict(r.stdout, "momentum-balance") == "n/a", r.stdout
    assert "to judge it, add /contacts/jt3" in detail(r.stdout, "momentum-balance"), r.stdout
    assert r.returncode in (0, 3), r.stdout + r.stderr
    assert failures(r.stdout) <= corpus.ENGINE_FAULTS.get(engine, set()), r.stdout
    if corpus.verdict(r.stdout, "friction") == "pass":
        assert "rule jt3 on 0 pairs" in detail(r.stdout, "friction"), r.stdout
    for row in PHYSICS_ROWS:  # n/a only for what the run holds (conservation: no isolated group) or names what to add
        assert corpus.verdict(r.stdout, row) != "missing", (row, r.stdout)
        assert ("to judge it, add" in detail(r.stdout, row)) == (row == "momentum-balance"), (row, r.stdout)

    # Planted faults still fail on it, naming the frame.
    def velocity(f):
        frame, i = corpus.free_body(f)
        f["/states/velocity"][frame, i] = f["/states/velocity"][frame, i] * 1.5
        return frame

    def flipped(f):
        frame, k = corpus.loaded_row(f, min_depth=1e-3)
        f["/contacts/normal"][k] = -f["/contacts/normal"][k]
        return frame

    def cone(f):  # the scalar jt of the pair's first row 1.2 x the pair's cone, the others 0
        frame, k = corpus.loaded_row(f)
        a, b = (int(x) for x in f["/contacts/pair"][k])
        rows = [s for s in corpus.rows_of(f, frame) if tuple(f["/contacts/pair"][s]) == (a, b)]
        total = sum(float(f["/contacts/jn"][s]) for s in rows)
        for s in rows:
            f["/contacts/jt"][s] = 0.0
        f["/contacts/jt"][k] = 1.2 * corpus.pair_mu(f, a, b) * total
        return frame

    def dropped(f):
        frame, k = corpus.loaded_row(f, dynamic_pair=True, rows_in_pair=2)
        f["/contacts/jn"][k] = 0.0
        f["/contacts/jt"][k] = 0.0
        return frame

    def declared_dropped(f):  # Bullet: one friction direction along the sliding, declared
        f.attrs["friction_directions"] = np.int32(1)
        return dropped(f)

    plants = [("velocity", velocity, "free-flight"), ("flipped", flipped, "contact-geometry"),
              ("cone", cone, "friction")]
    if engine == "bullet":
        plants.append(("dropped", declared_dropped, "momentum-balance"))
    for name, edit, row in plants:
        out, frame = edited(legacy, name, edit)
        assert out.returncode == 3, f"{engine} legacy, {name} at frame {frame} not caught:\n{out.stdout}"
        assert corpus.verdict(out.stdout, row) == "FAIL", f"{engine} legacy, {name}: row {row}\n{out.stdout}"
        assert f"frame {frame}" in out.stdout, f"{engine} legacy, {name}: frame {frame} not named\n{out.stdout}"


@pytest.mark.parametrize("engine", [corpus.engine_param(e) for e in ("bullet",)])
def test_rows_needing_what_a_trace_lacks_are_na_naming_it(workdir, engine):
    clean = corpus.base_trace(workdir, engine, corpus.DROP, 120)
    # No candidate pairs: broadphase-completeness n/a, naming /pairs.
    nopairs = make_legacy(clean, workdir / f"{engine}--nopairs.h5", drop=["/pairs"])
    assert check_only(nopairs)["broadphase-completeness"].startswith("n/a    add /pairs/offsets and /pairs/pair")
    r = corpus.judge(nopairs)
    assert r.returncode == 0, r.stdout
    assert corpus.verdict(r.stdout, "broadphase-completeness") == "n/a"
    assert "/pairs/offsets" in detail(r.stdout, "broadphase-completeness"), r.stdout

    # No contacts at all: every row that needs them is n/a naming /contacts, never failed
    # (bodies resting on the floor are not free-flying bodies that stopped).
    bare = make_legacy(clean, workdir / f"{engine}--nocontacts.h5", drop=["/pairs", "/contacts"])
    plan = check_only(bare)
    r = corpus.judge(bare)
    assert r.returncode == 0, r.stdout
    for row in CONTACT_ROWS:
        assert plan[row].startswith("n/a    add /contacts"), (row, plan[row])
        assert corpus.verdict(r.stdout, row) == "n/a", (row, r.stdout)
        assert "to judge it, add /contacts" in detail(r.stdout, row), (row, r.stdout)
    assert plan["penetration"] == "judged" and corpus.verdict(r.stdout, "penetration") == "pass", r.stdout

    # ... while penetration, still judged, catches a body sunk 3 cm into the floor.
    def sunk(f):
        frame, i = 60, int(np.nonzero(f["/bodies/inverse_mass"][...] > 0)[0][0])
        lo = f["/bodies/local_aabb_min"][i]
        f["/states/position"][frame, i] = [f["/states/position"][frame, i][0], -lo[1] - 0.03,
                                           f["/states/position"][frame, i][2]]
        return frame + 1  # the pose of state row f is step f + 1's detection pose

    out, frame = edited(bare, "sunk", sunk)
    assert out.returncode == 3 and corpus.verdict(out.stdout, "penetration") == "FAIL", out.stdout
    assert f"frame {frame}" in out.stdout, out.stdout


# ---- declarations, not names: octocd's own traces -------------------------------------

OCTOCD_DECLARATIONS = {"contact_geometry": "aabb", "broadphase_exact": 1, "contact_margin_rule": "theta",
                       "jt_direction": "along-sliding", "response_scheme": "jacobi", "integrator": "semi-implicit",
                       "contact_model": "rigid", "deactivation": "off", "friction_directions": 1}


def table(out):
    """The verdict table without its title line (which names the file)."""
    return [line for line in out.splitlines()[1:] if line.strip()]


def test_octocd_traces_declare_what_the_rules_read(workdir):
    trace = workdir / "cpu--box-stack.h5"
    r = corpus.octocd("run", os.path.join(corpus.SOURCE_DIR, "datasets", "scenes", "box-stack.json"), "--frames",
                      "100", "--state-every", "1", "--contacts", "--trace", str(trace), "--no-xdmf", "--quiet")
    assert r.returncode == 0, r.stdout + r.stderr
    with h5py.File(trace, "r") as f:
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
        for k, v in OCTOCD_DECLARATIONS.items():
            assert attrs.get(k) == v, (k, attrs.get(k))
        assert attrs["impulses_complete"] == 0  # box-stack: response.iterations 8
        assert attrs["velocity_clamp"] > 0
    declared = corpus.judge(trace)
    assert declared.returncode == 0, declared.stdout

    # The engine's name decides nothing: renamed, the same verdicts.
    def rename(f):
        f.attrs["engine"] = "someone-elses"
    renamed, _ = edited(trace, "renamed", rename)
    assert table(renamed.stdout)[1:] == table(declared.stdout)[1:], renamed.stdout

    # Written before the declarations (a version 1 trace of octocd's writer without them):
    # read as octocd's conventions, judged as then.
    def undeclare(f):
        for k in list(f.attrs):
            if k in OCTOCD_DECLARATIONS or k in ("velocity_clamp", "impulses_complete"):
                del f.attrs[k]
    old, _ = edited(trace, "undeclared", undeclare)
    assert table(old.stdout) == table(declared.stdout), old.stdout

    # An external trace declaring nothing is read by the trace conventions' defaults: jt
    # against the sliding and rows that are the step's whole impulses. octocd's rows, one
    # relaxation pass of 8 with jt along the sliding, then fail momentum-balance: the
    # declarations are what makes its trace judged right.
    def external(f):
        undeclare(f)
        del f["/frames"]
    ext, _ = edited(trace, "external", external)
    assert ext.returncode == 3 and corpus.verdict(ext.stdout, "momentum-balance") == "FAIL", ext.stdout
    assert corpus.verdict(ext.stdout, "contact-geometry") == "pass", ext.stdout


# ---- sleeping bodies (/states/sleeping, deactivation) ---------------------------------

def sleeping_trace(path, flags=True, deactivation=None, move=None):
    """A floor (body 0, static), box 1 asleep on it 2 mm deep, box 2 asleep in the air, box 3
    falling freely until the engine puts it to sleep in step 5 (its velocity zeroed).
    No contact rows: engines do not collide sleeping bodies. `move`: (frame, body, dx)."""
    frames, dt, g = 10, np.float32(0.01), np.float32(-9.81)
    n = 4
    lo = np.float32([[-1, -0.05, -1]] + [[-0.05, -0.05, -0.05]] * 3)
    x = np.zeros((frames + 1, n, 3), np.float32)
    v = np.zeros((frames + 1, n, 3), np.float32)
    x[:, 0] = [0, -0.05, 0]
    x[:, 1] = [0, np.float32(0.05 - 0.002), 0]
    x[:, 2] = [0.5, 1.0, 0]
    x[0, 3] = [-0.5, 1.0, 0]
    asleep = np.zeros((frames + 1, n), np.uint8)
    asleep[:, 1] = asleep[:, 2] = 1
    for f in range(1, frames + 1):
        if f < 5:  # semi-implicit Euler in float32
            v[f, 3] = v[f - 1, 3] + np.float32([0, g * dt, 0])
            x[f, 3] = x[f - 1, 3] + dt * v[f, 3]
        else:
            x[f, 3] = x[4, 3] + dt * (v[4, 3] + np.float32([0, g * dt, 0])) if f == 5 else x[f - 1, 3]
            asleep[f, 3] = 1
    if move:
        frame, body, dx = move
        x[frame:, body] += np.float32(dx)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "octocd-trace"
        f.attrs["version"] = np.int32(2)
        f.attrs["engine"] = "sleepy"
        f.attrs["dt"] = float(dt)
        if deactivation:
            f.attrs["deactivation"] = deactivation
        f["bodies/local_aabb_min"] = lo
        f["bodies/local_aabb_max"] = -lo
        f["bodies/inverse_mass"] = np.float32([0, 1, 1, 1])
        f["states/position"] = x
        f["states/velocity"] = v
        f["states/orientation"] = np.tile(np.float32([1, 0, 0, 0]), (frames + 1, n, 1))
        f["states/angular_velocity"] = np.zeros((frames + 1, n, 3), np.float32)
        if flags:
            f["states/sleeping"] = asleep
        f["contacts/offsets"] = np.zeros(frames + 1, np.int64)
        f["contacts/pair"] = np.zeros((0, 2), np.uint32)
        f["contacts/normal"] = np.zeros((0, 3), np.float32)
        for k in ("depth", "jn", "jt"):
            f["contacts/" + k] = np.zeros(0, np.float32)
    return path


def test_sleeping_bodies_are_judged_not_to_move(workdir):
    # Undeclared: the frozen bodies are judged awake and fail (a box hanging in the air, a
    # box 2 mm in the floor without a contact row, a falling box stopped).
    r = corpus.judge(sleeping_trace(workdir / "awake.h5", flags=False))
    assert r.returncode == 3, r.stdout
    assert ("free-flight", "velocity") in failures(r.stdout) and \
        ("contact-completeness", "missing-contact") in failures(r.stdout), r.stdout

    # Flagged: asleep through a step, a body must not move; falling asleep is not judged.
    r = corpus.judge(sleeping_trace(workdir / "asleep.h5"))
    assert r.returncode == 0, r.stdout
    d = detail(r.stdout, "free-flight")
    assert "4 body-steps (integrator" in d and "25 body-steps asleep through the step judged not to move" in d \
        and "1 falling asleep not judged" in d, d
    assert "10 penetrating pair-frames of bodies asleep" in detail(r.stdout, "contact-completeness"), r.stdout
    plan = check_only(workdir / "asleep.h5")
    assert plan["free-flight"].startswith("judged"), plan

    # Planted: a sleeping body moved by 1 cm fails free-flight's `sleeping` cause.
    r = corpus.judge(sleeping_trace(workdir / "moved.h5", move=(7, 2, [0.01, 0, 0])))
    assert r.returncode == 3 and failures(r.stdout) == {("free-flight", "sleeping")}, r.stdout
    assert "frame 7: body 2 asleep before and after the step" in r.stdout, r.stdout

    # Bad declarations exit 2 naming what and the allowed values.
    for name, kw, what in (("off.h5", {"deactivation": "off"}, "/states/sleeping: given with the root attribute "
                                                                 "deactivation"),
                           ("on.h5", {"flags": False, "deactivation": "on"}, "/states/sleeping: missing"),
                           ("maybe.h5", {"deactivation": "maybe"}, "root attribute deactivation")):
        r = corpus.octocd("validate", "--trace-in", str(sleeping_trace(workdir / name, **kw)), "--check-only")
        assert r.returncode == 2 and what in r.stderr, r.stderr
    path = sleeping_trace(workdir / "two.h5")
    with h5py.File(path, "r+") as f:
        f["/states/sleeping"][3, 2] = 2
    r = corpus.octocd("validate", "--trace-in", str(path), "--check-only")
    assert r.returncode == 2 and "/states/sleeping: frame 3: body 2: 2" in r.stderr, r.stderr
