"""The performance gate and the report's merging on untrusted results (issue 57 item 4), run
by ctest (`report.gate.points`: the 10^5 points; `report.gate.untrusted`: the rest):

- the gate's statistics scale: U's exact null distribution where it is cheap (equal to
  scipy's exact result; beyond 30 a side to scipy's recursion run in numpy, which scipy's
  own takes seconds of Python for), the normal approximation with tie correction beyond
  (equal to scipy's asymptotic result, and within a few per cent of the exact result at sizes
  where both are cheap); 600 repetitions a side and 100,000 points are decided, not hung on;
- `--level` the repetitions cannot reach is exit 2 saying how many are needed (before: a
  10x slowdown passed at --level 0.001 with 5 a side);
- repetitions count once per file and run (before: one 1-repetition file given 5 times
  made 5 repetitions); a point id twice in one file is exit 2 naming the file and point;
- every hostile result generated here (numbers out of range, 400-digit integers, JSON
  2,000 deep, MB-long names, lone surrogates, wrong types, a 10^6-value list) ends in one
  line naming the file and field and exit 2: never a traceback, never a hang.
"""
import contextlib
import copy
import functools
import io
import json
import math
import os
import random
import shutil
import subprocess
import sys

import pytest

from test_gate import BASE, BIN, DATA, MAKE_REPORT, SRC, gate, report, scaled, set_values, sps

sys.path.insert(0, os.path.join(SRC, "report"))
import report_gate as G  # noqa: E402


# ---- statistics against scipy ------------------------------------------------------------------

def samples(rng, m, n, shift=1.0, ties=False):
    def draw():
        v = rng.lognormvariate(0, 0.1)
        return round(v, 2) if ties else v
    return [draw() * shift for _ in range(m)], [draw() for _ in range(n)]


@functools.lru_cache(maxsize=None)
def recursion_counts(m, n):
    """Counts of U = 0 .. m*n under H0 (no ties) by Mann and Whitney's recursion
    f(m, n, k) = f(m-1, n, k-n) + f(m, n-1, k) (the one scipy's exact method runs, one call
    per cell in Python), here one numpy row per (i, j): an algorithm of its own, not the
    gate's Gaussian binomial, and milliseconds where scipy's takes seconds (64 a side, 10
    against 400)."""
    import numpy as np
    size = m * n + 1
    unit = np.zeros(size)
    unit[0] = 1.0  # f(0, j, k) = f(i, 0, k) = [k == 0]
    prev = [unit] * (n + 1)
    for _ in range(1, m + 1):
        cur = [unit]
        for j in range(1, n + 1):
            row = cur[j - 1].copy()
            row[j:] += prev[j][:size - j]
            cur.append(row)
        prev = cur
    return tuple(prev[n])


def recursion_sf(u, m, n):
    """P(U >= u) under H0 from recursion_counts (scipy's exact one-sided 'greater' p)."""
    c = recursion_counts(m, n)
    return math.fsum(c[math.ceil(u):]) / math.fsum(c)


@pytest.mark.parametrize("m,n", [(5, 5), (6, 11), (12, 12), (20, 15), (30, 30)])
def test_the_recursion_oracle_is_scipys_exact_result(m, n):
    from scipy.stats import mannwhitneyu
    rng = random.Random(m * 100 + n)
    for shift in (0.95, 1.0, 1.04, 1.1):
        x, y = samples(rng, m, n, shift)
        u, _ = G.u_statistic(x, y)
        want = mannwhitneyu(x, y, alternative="greater", method="exact").pvalue
        assert recursion_sf(u, m, n) == pytest.approx(want, rel=1e-12, abs=0)


@pytest.mark.parametrize("m,n", [(5, 5), (5, 8), (6, 11), (12, 12), (20, 15), (30, 30), (5, 200), (40, 40),
                                 (64, 64)])
def test_exact_p_equals_scipys_exact_result(m, n):
    """scipy's exact p itself up to 30 a side; beyond (5 against 200, 40 and 64 a side, the
    bound of exact_is_cheap) the same recursion as scipy's (recursion_counts, checked against
    scipy above), which scipy runs in seconds of Python per size."""
    from scipy.stats import mannwhitneyu
    assert G.exact_is_cheap(m, n)
    rng = random.Random(m * 1000 + n)
    for shift in (0.95, 1.0, 1.04, 1.1):
        x, y = samples(rng, m, n, shift)
        u, tie = G.u_statistic(x, y)
        if m * n <= 900:
            want = mannwhitneyu(x, y, alternative="greater", method="exact").pvalue
        else:
            want = recursion_sf(u, m, n)
        assert G.u_sf(u, m, n, tie) == pytest.approx(want, rel=1e-12, abs=0)


@pytest.mark.parametrize("m,n", [(30, 30), (40, 40), (64, 64), (20, 100), (10, 400)])
def test_normal_approximation_is_scipys_asymptotic_result_and_near_the_exact_one(m, n):
    """Where both are cheap the normal approximation (used beyond exact_is_cheap) is within
    0.005 of scipy's exact p, and within 10 % of it for p >= 0.01 (the levels the gate uses);
    with ties it equals scipy's tie-corrected asymptotic p."""
    from scipy.stats import mannwhitneyu
    rng = random.Random(m + 7 * n)
    checked = 0
    for trial in range(60):
        x, y = samples(rng, m, n, rng.choice([1.0, 1.02, 1.05]), ties=trial % 3 == 0)
        u, tie = G.u_statistic(x, y)
        normal = G.u_sf_normal(u, m, n, tie)
        assert normal == pytest.approx(mannwhitneyu(x, y, alternative="greater", method="asymptotic").pvalue,
                                       rel=1e-9, abs=1e-300)
        if tie == 0:
            exact = recursion_sf(u, m, n)  # scipy's exact p (test_the_recursion_oracle_is_scipys_exact_result)
            assert abs(normal - exact) <= 0.005, (normal, exact)
            if exact >= 0.01:
                assert abs(normal - exact) <= 0.1 * exact, (normal, exact)
                checked += 1
    assert checked >= 10


def test_beyond_the_exact_bound_the_gate_uses_the_normal_approximation():
    assert not G.exact_is_cheap(65, 65) and not G.exact_is_cheap(600, 600) and G.exact_is_cheap(5, 10000)
    rng = random.Random(3)
    x, y = samples(rng, 600, 600, 1.02)
    u, tie = G.u_statistic(x, y)
    assert G.u_sf(u, 600, 600, tie) == G.u_sf_normal(u, 600, 600, tie)
    # The rank-sum U of numpy equals the pairwise count of plain Python (ties a half).
    xs, ys = samples(rng, 70, 80, 1.0, ties=True)
    u_ranks = G.u_statistic(xs, ys)
    u_pairs = sum(1.0 if a > b else 0.5 if a == b else 0.0 for a in xs for b in ys)
    assert u_ranks[0] == u_pairs and u_ranks[1] > 0


def test_critical_values_and_the_ratio_interval_agree_across_the_bound(monkeypatch):
    """The interval's order statistics: found by bisection beyond DIRECT_PAIRS, the same as
    sorting every pairwise difference (to 1e-12); the normal critical value within 1 % of
    the exact one at 64 a side."""
    rng = random.Random(5)
    a = [rng.gauss(0, 0.1) for _ in range(300)]
    b = [rng.gauss(0.01, 0.1) for _ in range(200)]
    ks = [1, 7, 30000, 30001, 59999, 60000]
    d = sorted(x - y for x in a for y in b)
    monkeypatch.setattr(G, "DIRECT_PAIRS", 100)
    got = G.pairwise_order_stats(a, b, ks)
    assert all(abs(g - d[k - 1]) <= 1e-12 for g, k in zip(got, ks)), (got, [d[k - 1] for k in ks])
    exact = G.u_critical(64, 64, 0.05)
    monkeypatch.setattr(G, "EXACT_COST", 0)
    assert abs(G.u_critical(64, 64, 0.05) - exact) <= 0.01 * exact


def test_600_repetitions_a_side_are_decided(tmp_path):
    """Before: scipy's exact U at 600 a side (and the pure-Python distribution) never ended."""
    rng = random.Random(11)
    base, same, slow = copy.deepcopy(BASE), scaled(BASE, 1.0), scaled(BASE, 1.3)
    for i in range(4):
        reps = [rng.lognormvariate(math.log(1000.0), 0.02) for _ in range(600)]
        set_values(sps(base, i), reps)
        set_values(sps(same, i), [rng.lognormvariate(math.log(1000.0), 0.02) for _ in range(600)])
        set_values(sps(slow, i), [v / 1.3 for v in reps])
    rc, out, err = gate(tmp_path, slow, base)
    assert rc == 4 and out.count("gate: SLOWER") == 4, out + err
    assert "time ratio 1.300" in out, out
    rc, out, err = gate(tmp_path, same, base)
    assert rc == 0 and "gate: passed: 4 figure(s)" in out, out + err


def test_100000_points_are_gated(tmp_path):
    """Before: each point looked its index up in a list (10^10 steps for 10^5 points)."""
    j = copy.deepcopy(BASE)
    pts = []
    for i in range(100000):
        v = [100.0 + (i * 7 + k) % 13 for k in range(5)]
        s = sorted(v)
        pts.append({"id": f"p{i}", "index": i, "status": "ok", "params": {"scene": f"s{i}", "engine": "cpu"},
                    "windows": {"all": {"steps_per_s": {"n": 5, "median": s[2], "min": s[0], "max": s[4],
                                                        "values": v}}}})
    j["points"], j["points_total"] = pts, len(pts)
    path = tmp_path / "big.json"
    path.write_text(json.dumps(j))
    rc, out, err = report(tmp_path, "--baseline", str(path), str(path))
    assert rc == 0 and "gate: passed: 100000 figure(s)" in out, err[-2000:]
    md = (tmp_path / "out" / "report.md").read_text()
    assert "not drawn: 100000 bars" in md and "| p99999 | all |" in md


# ---- --level and the repetitions ---------------------------------------------------------------

def test_a_level_five_repetitions_cannot_reach_says_how_many_are_needed(tmp_path):
    """With 5 a side the smallest one-sided p is 1/252 = 0.00397: at --level 0.001 a 10x
    slowdown passed; now exit 2 naming 7 repetitions (1/C(14,7) = 0.00029)."""
    rc, out, err = gate(tmp_path, scaled(BASE, 10.0), BASE, "--level", "0.001")
    assert rc == 2, out + err
    assert "too few repetitions for --level 0.001" in err and "0.00397" in err, err
    assert ">= 7 repetitions a side at this level (octocd bench --repeat 7)" in err, err
    assert err.count("\n") == 1 and "gate: passed" not in out
    # 7 a side reach it: the slowdown is found.
    b7, n7 = copy.deepcopy(BASE), copy.deepcopy(BASE)
    for i in range(4):
        vals = sps(BASE, i)["values"] + [sps(BASE, i)["values"][0] * 1.01, sps(BASE, i)["values"][1] * 0.99]
        set_values(sps(b7, i), vals)
        set_values(sps(n7, i), [v / 10 for v in vals])
    rc, out, err = gate(tmp_path, n7, b7, "--level", "0.001")
    assert rc == 4 and out.count("gate: SLOWER") == 4, out + err
    # The default level with 5 a side (and a 30 % slowdown) stays decidable.
    rc, out, err = gate(tmp_path, scaled(BASE, 1.3), BASE)
    assert rc == 4 and out.count("gate: SLOWER") == 4, out + err
    # Outside [1e-6, 0.25] is refused whatever the repetitions.
    rc, out, err = gate(tmp_path, BASE, BASE, "--level", "1e-12")
    assert rc == 2 and "--level: 1e-12; allowed: a significance level in [1e-06, 0.25]" in err, err


def test_repetitions_count_once_per_file_and_run(tmp_path):
    """One 1-repetition result given 5 times (or 5 copies of it) counted as 5 repetitions."""
    one = copy.deepcopy(BASE)
    one["settings"]["repeat"] = 1
    for i in range(4):
        set_values(sps(one, i), [sps(one, i)["values"][0] / 10])
    p = tmp_path / "one.json"
    p.write_text(json.dumps(one))
    copies = []
    for k in range(5):
        shutil.copy(p, tmp_path / f"copy{k}.json")
        copies.append(str(tmp_path / f"copy{k}.json"))
    base = os.path.join(DATA, "gate-base.json")
    rc, out, err = report(tmp_path, "--baseline", base, *([str(p)] * 5))
    assert rc == 2 and f"{p}: the same file as {p}; allowed: each result file once" in err, out + err
    rc, out, err = report(tmp_path, "--baseline", base, *copies)
    assert rc == 2 and f"{copies[1]}: the same run as {copies[0]}" in err, out + err
    assert "a copy counts its repetitions twice" in err
    # The same on the baseline's side.
    rc, out, err = report(tmp_path, "--baseline", base, "--baseline", base, copies[0])
    assert rc == 2 and "the same file as" in err, out + err
    # Runs that are distinct (another start) still pool: 5 runs of 1 repetition decide.
    for k, c in enumerate(copies):
        j = json.loads(open(c).read())
        j["started"] = f"2026-11-23T0{k}:00:00Z"
        open(c, "w").write(json.dumps(j))
    rc, out, err = report(tmp_path, "--baseline", base, *copies)
    assert rc == 4 and out.count("gate: SLOWER") == 4, out + err


def test_a_point_twice_in_one_file_is_refused_naming_file_and_point(tmp_path):
    j = copy.deepcopy(BASE)
    j["points"].append(copy.deepcopy(j["points"][2]))
    rc, out, err = gate(tmp_path, j, BASE)
    assert rc == 2, out + err
    assert f"new.json: points[4].id: '{BASE['points'][2]['id']}' is also points[2]; allowed: each point once" in err
    rc, out, err = gate(tmp_path, BASE, j)
    assert rc == 2 and "base.json: points[4].id" in err, out + err


# ---- hostile results: one line naming file and field, never a traceback ------------------------

def hostile_results():
    """(name, text of the new result, text expected in the error) for every kind of hostile
    result of this round; the baseline is gate-base.json."""
    def doc(edit):
        j = copy.deepcopy(BASE)
        edit(j)
        return json.dumps(j)

    def values(vals, i=0):
        return lambda j: set_values(sps(j, i), vals)

    def put(path, value):
        def edit(j):
            node = j
            for k in path[:-1]:
                node = node[k]
            node[path[-1]] = value
        return edit

    spread = "points[0].windows.all.steps_per_s"
    text = json.dumps(BASE)
    cases = [
        ("1e308-steps-per-s", doc(values([1e308] * 5)), f"{spread}.median: 1e+308 is out of range"),
        ("denormal-steps-per-s", doc(values([5e-324] * 5)), f"{spread}.median: 5e-324 is out of range"),
        ("1e308-pairs", doc(lambda j: set_values(j["points"][0]["windows"]["all"]["pairs"], [1e308] * 5)),
         "points[0].windows.all.pairs.median: 1e+308 is out of range"),
        ("400-digit-integer", text.replace('"repeat": 5', '"repeat": ' + "9" * 400, 1),
         "settings.repeat: the integer 999"),
        ("400-digit-n", text.replace('"n": 5', '"n": 1' + "0" * 400, 1), "points[0].wall_s.n: the integer 1000"),
        ("2e64-index", text.replace('"index": 0', '"index": 36893488147419103232', 1),
         "points[0].index: the integer 36893488147419103232"),
        ("json-2000-deep", '{"format": "octocd-bench", "version": 1, "x": ' + "[" * 2000 + "]" * 2000 + "}",
         "nested deeper than the reader can follow"),
        ("json-100-deep", text[:-1] + ', "x": ' + "[" * 100 + "]" * 100 + "}", "nested deeper than 64 levels"),
        ("lone-surrogate", text.replace('"pile | midphase=aabb-only | cpu"', '"pile \\ud800"', 1),
         "points[0].id: 'pile \\ud800' is not valid Unicode"),
        ("mb-long-name", doc(put(["sweep", "name"], "n" * (1 << 20))), "sweep.name: a string of 1048576 characters"),
        ("mb-long-id", doc(put(["points", 0, "id"], "i" * (1 << 20))), "points[0].id: a string of 1048576"),
        ("5000-char-engine", doc(put(["points", 0, "params", "engine"], "e" * 5000)), "points[0].params"),
        ("million-values", doc(values([100.0 + k % 7 for k in range(10 ** 6)])), f"{spread}.n: 1000000; allowed"),
        ("values-longer-than-n", doc(lambda j: sps(j, 0).update(values=[1.0] * 2000)),
         f"{spread}.values: 2000 values; allowed: at most 1000"),
        ("key-twice", text.replace('"complete": true', '"complete": true, "complete": false', 1),
         "key 'complete' twice in one object"),
        ("nul-byte", text.encode().replace(b'"vm"', b'"v\x00m"', 1), "a NUL byte at character"),
        ("not-utf8", text.encode().replace(b'"vm"', b'"v\xffm"', 1), "not UTF-8 at byte"),
        ("machine-a-list", doc(put(["machine"], [])), "machine: []; allowed: an object"),
        ("threads-a-string", doc(put(["machine", "threads"], "2")), 'machine.threads: "2"; allowed: an integer'),
        ("load-1e308", doc(put(["machine", "load_average"], [1e308])), "machine.load_average: [1e+308]; allowed"),
        ("point-load-nan", doc(put(["points", 0, "load_average"], [float("nan")])),
         "points[0].load_average: [NaN]; allowed"),
        ("definition-an-int", doc(put(["sweep", "definition"], 5)), "sweep.definition: 5; allowed: an object"),
        ("engines-an-int", doc(put(["settings", "engines"], 5)), "settings.engines: 5; allowed"),
        ("repeat-true", doc(put(["settings", "repeat"], True)), "settings.repeat: true; allowed"),
        ("shard-index-out-of-range", doc(put(["settings", "shard"], {"index": 3, "count": 2})),
         "settings.shard.index: 3; allowed: an integer in [0, 1]"),
        ("index-a-string", doc(put(["points", 0, "index"], "0")), 'points[0].index: "0"; allowed'),
        ("status-a-list", doc(put(["points", 0, "status"], ["ok"])), "points[0].status"),
        ("values-a-string", doc(lambda j: sps(j, 0).update(values="12")), f"{spread}.values"),
        ("value-a-string", doc(lambda j: sps(j, 0)["values"].__setitem__(0, "12")), f"{spread}"),
        ("too-many-points", doc(lambda j: j.update(points=[{"id": f"p{i}", "status": "skipped"}
                                                             for i in range(100001)])),
         "points: \"an array of 100001 points\"; allowed: an array of at most 100000"),
        ("complete-a-string", doc(put(["complete"], "yes")), 'complete: "yes"; allowed: true or false'),
        ("complete-missing-format", doc(put(["version"], "1")), "version 1; allowed: octocd-bench version 1"),
    ]
    return [(n, t if isinstance(t, bytes) else t.encode(), e) for n, t, e in cases]


@pytest.mark.parametrize("case", hostile_results(), ids=lambda c: c[0])
def test_a_hostile_result_is_one_line_naming_file_and_field(tmp_path, case):
    name, text, expect = case
    path = tmp_path / f"{name}.json"
    path.write_bytes(text)
    base = os.path.join(DATA, "gate-base.json")
    for args in (["--baseline", base, str(path)], [str(path)], ["--baseline", str(path), base]):
        out_dir = tmp_path / "out"
        argv, sys.argv = sys.argv, ["make_report.py", "-o", str(out_dir), *args]
        err, out = io.StringIO(), io.StringIO()
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                MAKE_REPORT.run()  # as `octocd report` runs it: any exception left is a traceback
            rc = 0
        except SystemExit as e:
            rc = e.code
        finally:
            sys.argv = argv
        e = err.getvalue()
        assert rc == 2, (name, args, rc, out.getvalue()[-500:], e)
        assert e.count("\n") == 1 and e.startswith("octocd report: error: "), e
        assert str(path) in e, e
        if expect:
            assert expect in e, e
        assert len(e) < 2200, len(e)


def test_a_hostile_result_through_the_binary_is_one_line(tmp_path):
    """The same through `octocd report` (the script's own process): exit 2, one line."""
    if not os.access(BIN, os.X_OK):
        pytest.skip(f"the octocd CLI is not built at {BIN}")
    for name, text, expect in hostile_results()[:8]:
        path = tmp_path / f"{name}.json"
        path.write_bytes(text)
        r = subprocess.run([BIN, "report", "--baseline", os.path.join(DATA, "gate-base.json"), str(path), "-o",
                            str(tmp_path / "out")], capture_output=True, text=True, timeout=300)
        assert r.returncode == 2 and "Traceback" not in r.stderr, (name, r.stderr)
        assert expect in r.stderr, (name, r.stderr)
