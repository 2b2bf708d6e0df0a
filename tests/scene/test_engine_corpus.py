"""The validation corpus on every reference engine (ctest label `corpus`; docs/engines.md,
"The engine matrix"): each engine available here (`octocd engines --available`: bullet,
mujoco, ode, ...) runs a drop of 24 rotated boxes and a few asymmetric bodies spinning in
free flight; its clean trace must pass every physics row, and each planted fault, edited
into a copy of the trace with h5py, must fail its row naming the frame.

Beside them the small engine of tests/scene/declared_faults.py, rewritten as each declaration
says (an engine reporting only poses, one without friction or impulses, one with per-step
incompleteness, one integrating the body origin, one with two points per row, ...): its clean
trace passes under each, and which of seven planted faults stay visible under each is
docs/validate-your-engine.md's table, checked here against the run.

Run by ctest with OCTOCD_BIN and OCTOCD_SOURCE_DIR set; pytest skips an engine this build
does not have, saying so.
"""
import json
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

h5py = pytest.importorskip("h5py", reason="python3-h5py is not installed")

SOURCE_DIR = os.environ.get("OCTOCD_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SOURCE_DIR, "build", "octocd"))

DROP = {
    "name": "corpus-drop", "rotation": True, "dt": 0.002, "frames": 200,
    "domain": {"min": [-0.6, 0, -0.6], "max": [0.6, 1.6, 0.6]}, "walls": "open-box",
    "groups": [
        {"name": "big", "shape": {"box": [0.06, 0.04, 0.05]}, "count": 8, "mass": 1,
         "orientation": {"axis": [0.6, 0, 0.8], "angle_deg": 30},
         "layout": {"type": "random", "min": [-0.4, 0.05, -0.4], "max": [0.4, 0.4, 0.4], "seed": 3}},
        {"name": "mid", "shape": {"box": [0.04, 0.04, 0.04]}, "count": 8, "mass": 0.5,
         "orientation": {"axis": [0, 1, 0], "angle_deg": 40},
         "layout": {"type": "random", "min": [-0.4, 0.45, -0.4], "max": [0.4, 0.8, 0.4], "seed": 4}},
        {"name": "small", "shape": {"box": [0.025, 0.025, 0.03]}, "count": 8, "mass": 0.2,
         "layout": {"type": "random", "min": [-0.4, 0.85, -0.4], "max": [0.4, 1.1, 0.4], "seed": 5}},
    ]}


def octocd(*args):
    return subprocess.run([BIN, *args], capture_output=True, text=True)


def available():
    r = octocd("engines", "--available")
    assert r.returncode == 0, r.stdout + r.stderr
    return set(r.stdout.split())


def reference_engines():
    """The registry's reference engines (`octocd engines --json --no-checks`: the built-in engines
    that run their own broadphase, bullet, mujoco, ode, dart, ...), built here or not, in its order."""
    r = octocd("engines", "--json", "--no-checks")
    assert r.returncode == 0, r.stdout + r.stderr
    return [e["name"] for e in json.loads(r.stdout)["engines"] if e.get("kind") == "builtin" and e.get("own_broadphase")]


ENGINES = available() if os.path.exists(BIN) else set()
REFERENCE_ENGINES = reference_engines() if os.path.exists(BIN) else []


def engine_param(e):
    return pytest.param(e, marks=pytest.mark.skipif(e not in ENGINES, reason=f"engine {e} is not available here "
                                                                               "(octocd engines says why)"))


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("corpus")


_traces = {}


def base_trace(workdir, engine, scene, frames):
    """The engine's clean trace of `scene` (a dict, or a shipped scene's name), once."""
    key = (engine, json.dumps(scene, sort_keys=True))
    if key not in _traces:
        if isinstance(scene, dict):
            path = workdir / f"{scene['name']}.json"
            path.write_text(json.dumps(scene))
        else:
            path = os.path.join(SOURCE_DIR, "datasets", "scenes", scene + ".json")
        name = scene["name"] if isinstance(scene, dict) else scene
        trace = workdir / f"{engine}--{name}.h5"
        r = octocd("run", str(path), "--engine", engine, "--rotation", "--frames", str(frames), "--state-every", "1",
                   "--contacts", "--trace", str(trace), "--no-xdmf", "--quiet")
        assert r.returncode == 0, r.stdout + r.stderr
        _traces[key] = trace
    return _traces[key]


def judge(trace):
    return octocd("validate", "--trace-in", str(trace))


def verdict(out, row):
    m = re.search(r"(^|\n)physics +" + re.escape(row) + r" +\S+ +\S+ +(pass|FAIL|n/a)", out)
    return m.group(2) if m else "missing"


def planted(trace, name, edit):
    copy = trace.parent / f"{trace.stem}--{name}.h5"
    shutil.copyfile(trace, copy)
    with h5py.File(copy, "r+") as f:
        frame = edit(f)
    return judge(copy), frame


def rows_of(f, frame):
    off = f["/contacts/offsets"][...]
    return range(int(off[frame - 1]), int(off[frame]))


def contact_bodies(f, frame):
    pair = f["/contacts/pair"]
    return {int(b) for r in rows_of(f, frame) for b in pair[r]}


def free_body(f, first=3):
    """(frame, body): a dynamic body moving without a contact row in that step and the next."""
    w = f["/bodies/inverse_mass"][...]
    vel = f["/states/velocity"]
    frames = f["/states/position"].shape[0] - 1
    for frame in range(first, frames - 1):
        touching = contact_bodies(f, frame) | contact_bodies(f, frame + 1)
        for i in np.nonzero(w > 0)[0]:
            if int(i) not in touching and np.linalg.norm(vel[frame, i]) > 0.05:
                return frame, int(i)
    pytest.skip("no body in free flight in this trace")


def pair_mu(f, a, b):
    mu = f["/bodies/friction"][...] if "/bodies/friction" in f else None
    if mu is None:
        return float(f.attrs["mu"])
    rule = f.attrs.get("friction_combine", "product")
    rule = rule.decode() if isinstance(rule, bytes) else rule
    fa, fb = float(mu[a]), float(mu[b])
    return {"product": fa * fb, "min": min(fa, fb), "max": max(fa, fb), "average": 0.5 * (fa + fb),
            "geometric": (fa * fb) ** 0.5}[rule]


def loaded_row(f, min_depth=0.0, dynamic_pair=False, rows_in_pair=1):
    """(frame, row): the row with the largest jn (depth >= min_depth) whose pair has at least
    `rows_in_pair` rows in its frame (both bodies dynamic when asked)."""
    w = f["/bodies/inverse_mass"][...]
    jn, depth, pair, off = f["/contacts/jn"][...], f["/contacts/depth"][...], f["/contacts/pair"][...], \
        f["/contacts/offsets"][...]
    best = None
    for frame in range(2, len(off)):
        lo, hi = int(off[frame - 1]), int(off[frame])
        for r in range(lo, hi):
            a, b = int(pair[r][0]), int(pair[r][1])
            if depth[r] < min_depth or (dynamic_pair and not (w[a] > 0 and w[b] > 0)):
                continue
            same = sum(1 for s in range(lo, hi) if tuple(pair[s]) == (a, b))
            if same >= rows_in_pair and (best is None or jn[r] > best[2]):
                best = (frame, r, jn[r])
    if best is None or best[2] <= 0:
        pytest.skip("no loaded contact row of that kind in this trace")
    return best[0], best[1]


# Faults of the engines themselves, each shown by a test with a witness from the engine's
# own API (docs/engines.md): (row, cause) an engine's clean run may fail, and only those.
ENGINE_FAULTS = {
    # MuJoCo's soft friction tracks a reference deceleration and pushes a contact point
    # along its sliding once the normal impulse has slowed it (MujocoFaults tests).
    "mujoco": {("friction", "dissipation"), ("friction", "cone")},
    # ODE's Dantzig LCP fixes each friction bound from the normal force before it solves
    # friction (OdeEngineFault.DantzigFrictionExceedsTheFinalNormalForce).
    "ode": {("friction", "cone")},
    # DART's default solver is ODE's Dantzig LCP with the same findex friction bounds
    # (DartEngineFault.DantzigFrictionExceedsTheFinalNormalForce).
    "dart": {("friction", "cone")},
}


@pytest.mark.parametrize("engine", [engine_param(e) for e in REFERENCE_ENGINES])
def test_clean_runs_pass_every_physics_row(workdir, engine):
    for scene, frames in ((DROP, 120), ("rot-spin-free", 200)):
        r = judge(base_trace(workdir, engine, scene, frames))
        name = scene if isinstance(scene, str) else scene["name"]
        failures = set(re.findall(r"^NEW FAILURE ([a-z-]+)/([a-z-]+):", r.stdout, re.M))
        assert r.returncode in (0, 3), r.stdout + r.stderr
        assert failures <= ENGINE_FAULTS.get(engine, set()), f"{engine} on {name}: {failures}\n{r.stdout}"
        assert (r.returncode == 0) == (not failures), r.stdout


FAULTS = ["velocity x1.5", "teleport 1 cm", "w x1.5", "flipped normal", "flipped speculative normal", "row dropped",
          "friction 1.2x cone", "impulse on the wrong body"]


@pytest.mark.parametrize("fault", FAULTS)
@pytest.mark.parametrize("engine", [engine_param(e) for e in REFERENCE_ENGINES])
def test_planted_faults_fail_naming_the_frame(workdir, engine, fault):
    spin = fault == "w x1.5"
    trace = base_trace(workdir, engine, "rot-spin-free", 200) if spin else base_trace(workdir, engine, DROP, 120)

    def edit(f):
        if fault in ("velocity x1.5", "teleport 1 cm", "w x1.5"):
            frame, i = free_body(f)
            if fault == "velocity x1.5":
                f["/states/velocity"][frame, i] = f["/states/velocity"][frame, i] * 1.5
            elif fault == "teleport 1 cm":
                f["/states/position"][frame, i] = f["/states/position"][frame, i] + np.array([0.01, 0, 0])
            else:
                f["/states/angular_velocity"][frame, i] = f["/states/angular_velocity"][frame, i] * 1.5
            return frame
        if fault == "flipped normal":
            frame, r = loaded_row(f, min_depth=1e-3)
            f["/contacts/normal"][r] = -f["/contacts/normal"][r]
            return frame
        if fault == "flipped speculative normal":
            # a row of depth 0 and no impulse (within the engine's contact margin) on a pair
            # whose shapes are apart: the one with the largest gap between body origins.
            depth, jn, off = f["/contacts/depth"][...], f["/contacts/jn"][...], f["/contacts/offsets"][...]
            rows = [(frame, r) for frame in range(2, len(off)) for r in range(int(off[frame - 1]), int(off[frame]))
                    if depth[r] == 0 and jn[r] == 0]
            if not rows:
                pytest.skip("this engine reports no row of depth 0 without an impulse (no speculative rows)")
            frame, r = rows[len(rows) // 2]
            f["/contacts/normal"][r] = -f["/contacts/normal"][r]
            return frame
        if fault == "row dropped":
            frame, r = loaded_row(f, dynamic_pair=True, rows_in_pair=2)
            f["/contacts/jn"][r] = 0.0
            f["/contacts/jt"][r] = 0.0
            f["/contacts/jt3"][r] = np.zeros(3)
            return frame
        if fault == "friction 1.2x cone":
            frame, r = loaded_row(f)
            a, b = (int(x) for x in f["/contacts/pair"][r])
            n = np.array(f["/contacts/normal"][r], dtype=float)
            t = np.cross(n, [1.0, 0, 0]) if abs(n[0]) < 0.9 else np.cross(n, [0, 1.0, 0])
            t /= np.linalg.norm(t)
            total = sum(float(f["/contacts/jn"][s]) for s in rows_of(f, frame)
                        if tuple(f["/contacts/pair"][s]) == (a, b))
            for s in rows_of(f, frame):
                if tuple(f["/contacts/pair"][s]) == (a, b):
                    f["/contacts/jt3"][s] = np.zeros(3)
            f["/contacts/jt3"][r] = 1.2 * pair_mu(f, a, b) * total * t
            f["/contacts/jt"][r] = 1.2 * pair_mu(f, a, b) * total
            return frame
        # impulse on the wrong body: the last row of a frame, between two dynamic bodies and
        # loaded, names a third body c > b instead of b (the rows stay sorted by pair).
        w = f["/bodies/inverse_mass"][...]
        off, pair, jn = f["/contacts/offsets"][...], f["/contacts/pair"][...], f["/contacts/jn"][...]
        best = None
        for frame in range(2, len(off)):
            r = int(off[frame]) - 1
            if r < int(off[frame - 1]):
                continue
            a, b = int(pair[r][0]), int(pair[r][1])
            later = [int(i) for i in np.nonzero(w > 0)[0] if int(i) > b]
            if w[a] > 0 and w[b] > 0 and later and jn[r] > 0 and (best is None or jn[r] > best[2]):
                best = (frame, r, jn[r], a, later[0])
        if best is None:
            pytest.skip("no loaded last row between dynamic bodies in this trace")
        frame, r, _, a, c = best
        f["/contacts/pair"][r] = [a, c]
        return frame

    r, frame = planted(trace, fault.replace(" ", "-"), edit)
    rows = {"velocity x1.5": "free-flight", "teleport 1 cm": "free-flight", "w x1.5": "free-flight",
            "flipped normal": "contact-geometry", "flipped speculative normal": "contact-geometry",
            "row dropped": "momentum-balance",
            "friction 1.2x cone": "friction", "impulse on the wrong body": "momentum-balance"}
    assert r.returncode == 3, f"{engine}, {fault} at frame {frame} not caught:\n{r.stdout}"
    assert verdict(r.stdout, rows[fault]) == "FAIL", f"{engine}, {fault}: row {rows[fault]}\n{r.stdout}"
    assert f"frame {frame}" in r.stdout, f"{engine}, {fault}: frame {frame} not named\n{r.stdout}"


def redeclared(trace, impulses):
    """A copy of `trace` as an engine that reports less (docs/validation.md, "What the impulses
    hold"): `impulses` "normal-only" (the friction impulses unknown: jt written as zeros, no
    jt3) or "none" (jn zeroed too)."""
    copy = trace.parent / f"{trace.stem}--impulses-{impulses}.h5"
    shutil.copyfile(trace, copy)
    with h5py.File(copy, "r+") as f:
        f["/contacts/jt"][...] = 0.0
        if "/contacts/jt3" in f:
            del f["/contacts/jt3"]
        if impulses == "none":
            f["/contacts/jn"][...] = 0.0
        f.attrs["impulses"] = impulses
    return copy


@pytest.mark.parametrize("impulses", ["normal-only", "none"])
@pytest.mark.parametrize("engine", [engine_param(e) for e in REFERENCE_ENGINES])
def test_partial_impulses_pass_clean_and_catch_planted_faults(workdir, engine, impulses):
    """Each reference engine's clean drop, declared as reporting only normal impulses (Rapier)
    or none (Jolt): no new failure; normal-only, a loaded row dropped or a body in contact
    with its velocity x1.5 fails momentum-balance naming the frame; none, momentum-balance
    and friction are n/a."""
    trace = redeclared(base_trace(workdir, engine, DROP, 120), impulses)
    r = judge(trace)
    failures = set(re.findall(r"^NEW FAILURE ([a-z-]+)/([a-z-]+):", r.stdout, re.M))
    assert r.returncode in (0, 3), r.stdout + r.stderr
    assert failures <= ENGINE_FAULTS.get(engine, set()), f"{engine}, impulses {impulses}: {failures}\n{r.stdout}"
    assert verdict(r.stdout, "friction") == "n/a", r.stdout
    if impulses == "none":
        assert verdict(r.stdout, "momentum-balance") == "n/a", r.stdout
        assert 'impulses = "none"' in r.stdout, r.stdout
        return
    assert verdict(r.stdout, "momentum-balance") == "pass", r.stdout

    def dropped(f):
        frame, row = loaded_row(f, dynamic_pair=True, rows_in_pair=2)
        f["/contacts/jn"][row] = 0.0
        return frame

    def fast(f):
        # the body in contact whose momentum m |v'| most exceeds its rows' cones (mu jn)
        w, vel = f["/bodies/inverse_mass"][...], f["/states/velocity"]
        jn, pair, off = f["/contacts/jn"][...], f["/contacts/pair"][...], f["/contacts/offsets"][...]
        best = None
        for frame in range(2, len(off)):
            cone = {}
            for s in range(int(off[frame - 1]), int(off[frame])):
                a, b = int(pair[s][0]), int(pair[s][1])
                for i in (a, b):
                    cone[i] = cone.get(i, 0.0) + pair_mu(f, a, b) * float(jn[s])
            for i, c in cone.items():
                if w[i] > 0:
                    ratio = np.linalg.norm(vel[frame, i]) / w[i] / (c + 1e-9)
                    if best is None or ratio > best[0]:
                        best = (ratio, frame, i)
        if best is None or best[0] < 4:
            pytest.skip("no body in contact whose momentum exceeds its rows' cones 4 times")
        _, frame, i = best
        f["/states/velocity"][frame, i] = f["/states/velocity"][frame, i] * 1.5
        return frame

    for name, edit in (("dropped", dropped), ("fast", fast)):
        out, frame = planted(trace, name, edit)
        assert out.returncode == 3, f"{engine}, {name} at frame {frame} not caught:\n{out.stdout}"
        assert verdict(out.stdout, "momentum-balance") == "FAIL", f"{engine}, {name}\n{out.stdout}"
        assert f"frame {frame}" in out.stdout, f"{engine}, {name}: frame {frame} not named\n{out.stdout}"


def test_the_declarations_table_is_measured(tmp_path):
    """docs/validate-your-engine.md, "What each declaration turns off": the table of planted
    faults per declaration is this run's (tests/scene/declared_faults.py), and under each the
    steps before the faults' and the bodies not planted pass every row."""
    import declared_faults
    measured = declared_faults.measure(BIN, str(tmp_path))
    for name, (stray, _) in measured.items():
        assert not stray, f"declared {name}, failures that are no planted fault's: {stray}"
    table = declared_faults.table(measured)
    page = open(os.path.join(SOURCE_DIR, "docs", "validate-your-engine.md"), encoding="utf-8").read()
    start = page.find(declared_faults.HEADER)
    assert start >= 0, "docs/validate-your-engine.md has no table headed " + declared_faults.HEADER
    assert page[start:].split("\n\n", 1)[0] == table, "the page's table differs from the run's:\n" + table


def test_the_origin_integrator_needs_its_declaration(tmp_path):
    """The small engine of tests/scene/declared_faults.py with its lone box's origin integrated
    (MuJoCo's free joint; its centre of mass 2 cm off the origin, spinning at 22 rad/s): the
    centre of mass drifts 1.1e-4 m/s a step, so without `integrated_point` "origin" free-flight
    fails naming the box; the table's line declaring it passes (above)."""
    import declared_faults as d
    path = str(tmp_path / "origin-undeclared.h5")
    d.write(path, d.run(origin=d.COM), com=d.COM, velocity_at="origin", attrs={"velocity_at": "origin"})
    code, rows = d.judge(BIN, path)
    row = next(r for r in rows if r["name"] == "free-flight")
    assert code == 3 and row["verdict"] == "fail", row["detail"]
    assert any(f"body {d.FREE}" in item for c in row["causes"] for item in c["items"]), row["causes"]
