"""Incompleteness where it is, and conservation near outside bodies (ctest label `corpus`;
docs/validation.md, "Incomplete contact reporting"; docs/trace-format.md, `/contacts/incomplete`).

A pile of 30 boxes written here as an engine would (translation only, 1 kg boxes, e = 0.5):
- 8 columns on a floor, each a box resting on it and a box dropped on that one from 5 to
  40 cm, bouncing until it rests;
- 7 columns falling side by side 3 cm apart far from the floor, each a box thrown down at
  4 m/s and one 3 mm above it at 4.6 m/s: they collide once in the air (dt 5 ms).
An engine like Havok drops the rows of each ended contact's last impulse (the step that ends
it). Declared in `/contacts/incomplete` (those (frame, body_a, body_b), or those frames), only
they are exempt: the clean run passes with momentum-balance and contact-completeness judged;
a velocity x1.5 on a body in contact on another step and an undeclared dropped step still fail
naming frame and body; a malformed declaration exits 2 naming the row and the allowed range.
Declared `contacts_complete` 0 (every step), the falling columns' collisions are judged on
conservation where the posed shapes show them apart from the other columns through the step
(their relative motion), so 5% energy injected into one collision fails.

Run by ctest with OCTOCD_BIN and OCTOCD_SOURCE_DIR set.
"""
import re
import shutil

import numpy as np
import pytest

h5py = pytest.importorskip("h5py", reason="python3-h5py is not installed")

import test_engine_corpus as corpus  # noqa: E402  (octocd, judge, verdict)

DT, G, E = 0.005, -9.81, 0.5
FRAMES = 200
RESTING, FALLING = 8, 7  # columns of two boxes each: 30 boxes and the floor


def pile(inject=None):
    """The run: states x, v ((F + 1) x n x 3, float32) and per frame 1..F its rows
    [(a, b, depth, point, jn)], normal (0, -1, 0) from B to A, A the lower body.
    `inject` = falling column k: 5% of the group's kinetic energy added to its collision's
    relative motion (momentum kept) in the step of its first impulse."""
    n = 1 + 2 * (RESTING + FALLING)
    x = np.zeros((n, 3))
    v = np.zeros((n, 3))
    x[0] = [0, -0.1, 0]
    for k in range(RESTING):
        x[1 + 2 * k] = [-1.05 + 0.3 * k, 0.0995, 0]
        x[2 + 2 * k] = [-1.05 + 0.3 * k, 0.2995 + 0.05 * (k + 1), 0]
    for k in range(FALLING):
        lo, hi = 1 + 2 * (RESTING + k), 2 + 2 * (RESTING + k)
        x[lo] = [20 + 0.23 * k, 100, 0]
        x[hi] = [20 + 0.23 * k, 100.203, 0]
        v[lo], v[hi] = [0, -4, 0], [0, -4.6, 0]
    x, v = np.float32(x).astype(float), np.float32(v).astype(float)
    xs, vs, rows = [np.float32(x)], [np.float32(v)], []
    injected = False
    for f in range(1, FRAMES + 1):
        t = v.copy()
        t[1:, 1] += DT * G
        step = []
        columns = [(0, 1 + 2 * k, 2 + 2 * k) for k in range(RESTING)] + \
                  [(None, 1 + 2 * (RESTING + k), 2 + 2 * (RESTING + k)) for k in range(FALLING)]
        for floor, b, top in columns:
            df = 0.1 - x[b][1] if floor is not None else -1.0
            dbt = 0.2 - (x[top][1] - x[b][1])
            vb0, vt0 = t[b][1], t[top][1]
            approach = vt0 - vb0
            target = -E * approach if approach < -0.05 else 0.0
            jf = jbt = 0.0
            vb, vt = vb0, vt0
            for _ in range(30):
                if df > 0:
                    nj = max(0.0, jf - vb)
                    vb += nj - jf
                    jf = nj
                if dbt > 0:
                    nj = max(0.0, jbt + (target - (vt - vb)) / 2.0)
                    vt += nj - jbt
                    vb -= nj - jbt
                    jbt = nj

            def corners(a, bb, depth, y, j):
                total = 0.0
                for c in range(4):
                    p = [x[b][0] + (0.1 if c & 1 else -0.1), y, x[b][2] + (0.1 if c & 2 else -0.1)]
                    jn = float(np.float32(j / 4))
                    total += jn
                    step.append((a, bb, float(depth), p, jn))
                return total
            sf = corners(0, b, df, -0.5 * df, jf) if df > 0 else 0.0
            sbt = corners(b, top, dbt, x[b][1] + 0.1 - 0.5 * dbt, jbt) if dbt > 0 else 0.0
            t[b][1] = vb0 + sf - sbt
            t[top][1] = vt0 + sbt
            if inject is not None and top == 2 + 2 * (RESTING + inject) and sbt > 0 and not injected:
                # Scale the relative velocity about the centre of mass: +5% kinetic energy.
                injected = True
                ke0 = 0.5 * (np.dot(v[b] + [0, DT * G, 0], v[b] + [0, DT * G, 0]) +
                             np.dot(v[top] + [0, DT * G, 0], v[top] + [0, DT * G, 0]))
                ke1 = 0.5 * (np.dot(t[b], t[b]) + np.dot(t[top], t[top]))
                vc = 0.5 * (t[b] + t[top])
                rel = 0.25 * np.dot(t[top] - t[b], t[top] - t[b])  # the relative motion's kinetic energy
                s = np.sqrt((rel + 1.05 * ke0 - ke1) / rel)
                t[b], t[top] = vc + s * (t[b] - vc), vc + s * (t[top] - vc)
        t = np.float32(t).astype(float)
        x = np.float32(x + DT * t).astype(float)
        x[0], t[0] = [0, -0.1, 0], 0
        v = t
        xs.append(np.float32(x))
        vs.append(np.float32(v))
        rows.append(sorted(step, key=lambda r: (r[0], r[1])))
    if inject is not None:
        assert injected
    return np.array(xs), np.array(vs), rows


def last_impulses(rows):
    """(frame, a, b) of each contact's last step with an impulse, for the contacts that end
    before the run does: Havok's 'collision finished' carries no data."""
    last, ended = {}, set()
    for f, step in enumerate(rows, start=1):
        here = {(a, b) for a, b, *_ in step}
        for a, b, _, _, jn in step:
            if jn > 0:
                last[(a, b)] = f
        for pair in [p for p in last if p not in here]:
            ended.add((last.pop(pair),) + pair)
    return sorted(ended)


def write(path, run, drop=(), declare=None, attrs=None):
    """The run as a version 2 trace; the rows of `drop` ((frame, a, b)) left out;
    `declare`: written as /contacts/incomplete (any array); `attrs`: more root attributes."""
    xs, vs, rows = run
    n = xs.shape[1]
    dropped = set(drop)
    kept = [[r for r in step if (f, r[0], r[1]) not in dropped] for f, step in enumerate(rows, start=1)]
    flat = [r for step in kept for r in step]
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "octocd-trace"
        f.attrs["version"] = np.int32(2)
        f.attrs["engine"] = "havok-like"
        f.attrs["dt"] = DT
        f.attrs["gravity"] = np.float64([0, G, 0])
        f.attrs["mu"] = 0.5
        f.attrs["restitution"] = E
        f.attrs["contact_margin"] = 0.005
        f.attrs["friction_directions"] = np.int32(1)
        for k, value in (attrs or {}).items():
            f.attrs[k] = value
        half = np.float32([[2, 0.1, 2]] + [[0.1, 0.1, 0.1]] * (n - 1))
        f["bodies/local_aabb_min"] = -half
        f["bodies/local_aabb_max"] = half
        f["bodies/inverse_mass"] = np.float32([0] + [1] * (n - 1))
        f["bodies/locked_dofs"] = np.uint8([0] + [0x38] * (n - 1))
        f["states/position"] = xs
        f["states/velocity"] = vs
        f["states/orientation"] = np.tile(np.float32([1, 0, 0, 0]), (FRAMES + 1, n, 1))
        f["states/angular_velocity"] = np.zeros((FRAMES + 1, n, 3), np.float32)
        f["contacts/offsets"] = np.int64(np.cumsum([0] + [len(s) for s in kept]))
        f["contacts/pair"] = np.uint32([[r[0], r[1]] for r in flat]).reshape(-1, 2)
        f["contacts/normal"] = np.tile(np.float32([0, -1, 0]), (len(flat), 1))
        f["contacts/point"] = np.float32([r[3] for r in flat]).reshape(-1, 3)
        f["contacts/depth"] = np.float32([r[2] for r in flat])
        f["contacts/jn"] = np.float32([r[4] for r in flat])
        f["contacts/jt"] = np.zeros(len(flat), np.float32)
        if declare is not None:
            f["contacts/incomplete"] = declare
    return path


def detail(out, row):
    m = re.search(r"^physics +" + re.escape(row) + r" .*\n +(.*)$", out, re.M)
    return m.group(1) if m else ""


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("incomplete")


@pytest.fixture(scope="module")
def run():
    return pile()


def test_incomplete_steps_and_pairs_are_exempt_and_the_rest_judged(workdir, run):
    xs, vs, rows = run
    ended = last_impulses(rows)
    assert len(ended) >= 20, ended  # the bounces' and the air collisions' last impulses
    assert all(len(e) == 3 for e in ended)
    pairs = np.int64(ended)

    # Every row reported: a clean run.
    r = corpus.judge(write(workdir / "complete.h5", run))
    assert r.returncode == 0, r.stdout

    # The rows of each ended contact's last impulse dropped: undeclared, a fault.
    r = corpus.judge(write(workdir / "dropped.h5", run, drop=ended))
    assert r.returncode == 3, r.stdout
    assert corpus.verdict(r.stdout, "momentum-balance") == "FAIL", r.stdout

    # Declared as pairs of those steps, or as those steps: passes, and momentum-balance and
    # contact-completeness stay judged (not n/a).
    for name, declared in (("pairs", pairs), ("frames", np.unique(pairs[:, 0]))):
        r = corpus.judge(write(workdir / f"declared-{name}.h5", run, drop=ended, declare=declared))
        assert r.returncode == 0, (name, r.stdout)
        for row in ("momentum-balance", "contact-completeness", "free-flight", "conservation"):
            assert corpus.verdict(r.stdout, row) == "pass", (name, row, r.stdout)
        assert "on the steps or pairs /contacts/incomplete declares" in detail(r.stdout, "momentum-balance"), r.stdout
    plan = corpus.octocd("validate", "--trace-in", str(workdir / "declared-pairs.h5"), "--check-only")
    assert re.search(r"^physics +momentum-balance +judged", plan.stdout, re.M), plan.stdout

    # One dropped step left undeclared still fails, naming its frame.
    frame, a, b = ended[len(ended) // 2]
    r = corpus.judge(write(workdir / "one-undeclared.h5", run, drop=ended,
                           declare=np.int64([e for e in ended if e != (frame, a, b)])))
    assert r.returncode == 3, r.stdout
    assert f"frame {frame}: body" in r.stdout, (frame, a, b, r.stdout)

    # A velocity x1.5 on a body in contact on a step not declared: momentum-balance fails
    # naming the frame and the body.
    declared_at = {(f, i) for f, p, q in ended for i in (p, q)}
    frame, body = next((f, rr[1]) for f, step in enumerate(rows, start=1) for rr in step
                       if (f, rr[1]) not in declared_at and (f, rr[0]) not in declared_at
                       and abs(vs[f, rr[1], 1]) > 0.5)
    path = write(workdir / "fast.h5", run, drop=ended, declare=pairs)
    with h5py.File(path, "r+") as f:
        f["states/velocity"][frame, body] = 1.5 * vs[frame, body]
    r = corpus.judge(path)
    assert r.returncode == 3 and corpus.verdict(r.stdout, "momentum-balance") == "FAIL", r.stdout
    assert f"frame {frame}: body {body}" in r.stdout, (frame, body, r.stdout)


def test_a_malformed_declaration_exits_2_naming_it(workdir, run):
    for name, declared, attrs, what in (
            ("zero", np.int64([3, 0]), None, f"/contacts/incomplete: row 1: frame 0; allowed: a frame in 1 .. {FRAMES}"),
            ("past", np.int64([[FRAMES + 1, 1, 2]]), None,
             f"/contacts/incomplete: row 0: frame {FRAMES + 1}; allowed: a frame in 1 .. {FRAMES}"),
            ("body", np.int64([[5, 1, 31]]), None, "/contacts/incomplete: row 0: body 31; allowed: a body index in 0 .. 30"),
            ("same", np.int64([[5, 2, 2]]), None, "/contacts/incomplete: row 0: pair (2, 2); allowed: two different"),
            ("shape", np.int64([[5, 1]]), None, "/contacts/incomplete: shape 1 x 2; allowed: K frames"),
            ("float", np.float32([5]), None, "/contacts/incomplete: wrong type; allowed: integers"),
            ("both", np.int64([5]), {"contacts_complete": np.int32(0)},
             "/contacts/incomplete: given with the root attribute contacts_complete = 0")):
        path = write(workdir / f"bad-{name}.h5", run, declare=declared, attrs=attrs)
        for args in (["--check-only"], []):
            r = corpus.octocd("validate", "--trace-in", str(path), *args)
            assert r.returncode == 2 and what in r.stderr, (name, args, r.stdout, r.stderr)


def test_check_only_never_advises_what_the_trace_contradicts(workdir, run):
    path = write(workdir / "incomplete.h5", run, attrs={"contacts_complete": np.int32(0)})
    r = corpus.octocd("validate", "--trace-in", str(path), "--check-only")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "contacts_complete = 1" not in r.stdout, r.stdout
    for row in ("momentum-balance", "contact-completeness"):
        assert re.search(r"^physics +" + row + r" +n/a +add /contacts/incomplete in place of the root attribute "
                         r"contacts_complete = 0", r.stdout, re.M), r.stdout


def test_conservation_judges_groups_apart_from_outside_bodies(workdir, run):
    # contacts_complete 0: the falling columns collide 3 cm beside each other, each body
    # moving 2.3 cm a step (with the margin, near by each body's own motion), but side by side: the posed shapes show each pair apart from the
    # other columns through the step, so their groups are judged.
    attrs = {"contacts_complete": np.int32(0)}
    r = corpus.judge(write(workdir / "air.h5", run, attrs=attrs))
    assert r.returncode == 0, r.stdout
    m = re.search(r"(\d+) isolated group-frames", detail(r.stdout, "conservation"))
    assert m and int(m.group(1)) >= FALLING, r.stdout
    # 5% kinetic energy injected into column 3's collision (momentum kept): caught.
    hot = pile(inject=3)
    r = corpus.judge(write(workdir / "air-hot.h5", hot, attrs=attrs))
    assert r.returncode == 3 and corpus.verdict(r.stdout, "conservation") == "FAIL", r.stdout
    body = 1 + 2 * (RESTING + 3)
    assert re.search(rf"frame \d+: isolated group of 2 bodies \(body {body} \.\.\.\): kinetic energy", r.stdout), \
        r.stdout
