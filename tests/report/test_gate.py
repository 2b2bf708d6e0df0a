"""The performance gate (`octocd report --baseline`, design.md section 14b) on the committed small results
(tests/data/gate-*.json) and copies of them with planted faults: every refusal and exit code.
Run by ctest (`report.gate`): OCTOCD_BIN is the octocd binary."""
import contextlib
import copy
import csv
import io
import json
import math
import os
import subprocess
import sys

import pytest

SRC = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DATA = os.path.join(SRC, "tests", "data")
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SRC, "build", "octocd"))


def load(name):
    with open(os.path.join(DATA, name)) as f:
        return json.load(f)


BASE = load("gate-base.json")


def set_values(spread, vals):
    """A spread whose summary matches its repetitions (as octocd bench writes it)."""
    fin = [v for v in vals if isinstance(v, (int, float)) and math.isfinite(v)]
    spread["values"] = vals
    spread["n"] = len(vals)
    if len(fin) == len(vals) and vals:
        s = sorted(vals)
        spread["median"] = s[len(s) // 2] if len(s) % 2 else 0.5 * (s[len(s) // 2 - 1] + s[len(s) // 2])
        spread["min"], spread["max"] = s[0], s[-1]
    else:
        spread["median"] = spread["min"] = spread["max"] = None


def sps(j, i):
    return j["points"][i]["windows"]["all"]["steps_per_s"]


def scaled(j, factor, points=None):
    """A copy with the steps/s repetitions of `points` (default all) divided by `factor`."""
    j = copy.deepcopy(j)
    j["build"]["build_id"] = "0.1.0+scaled"
    for i, _ in enumerate(j["points"]):
        if points is None or i in points:
            set_values(sps(j, i), [v / factor for v in sps(j, i)["values"]])
    return j


def _spec():
    import importlib.util
    spec = importlib.util.spec_from_file_location("make_report", os.path.join(SRC, "report", "make_report.py"))
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    return m


MAKE_REPORT = _spec()  # imported once: the tests run the gate in-process, a few through the binary


def gate(tmp_path, new, base=BASE, *extra, binary=False):
    """(exit code, stdout, stderr) of `octocd report --baseline BASE NEW` (in-process by default)."""
    paths = []
    for name, j in (("base.json", base), ("new.json", new)):
        p = tmp_path / name
        if isinstance(j, str):
            p = os.path.join(DATA, j)
        else:
            p.write_text(json.dumps(j))
        paths.append(str(p))
    args = ["--baseline", paths[0], "-o", str(tmp_path / "out"), *extra, paths[1]]
    if binary:
        r = subprocess.run([BIN, "report", *args], capture_output=True, text=True, timeout=120)
        return r.returncode, r.stdout, r.stderr
    out, err = io.StringIO(), io.StringIO()
    argv, sys.argv = sys.argv, ["make_report.py", *args]
    rc = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            MAKE_REPORT.main()
    except SystemExit as e:
        rc = e.code if isinstance(e.code, int) else 1
    finally:
        sys.argv = argv
    return rc, out.getvalue(), err.getvalue()


def test_planted_slowdown_is_named_with_ratio_and_interval(tmp_path):
    rc, out, err = gate(tmp_path, "gate-new.json", "gate-base.json", "--csv", str(tmp_path / "csv"), binary=True)
    assert rc == 4, out + err
    slower = [l for l in out.splitlines() if "gate: SLOWER" in l]
    assert len(slower) == 1, out
    assert "pile | midphase=aabb-only | cpu: steps/s (all): time ratio 1.200 (90 % interval 1.175-1.225" in slower[0]
    assert "1 of 4 figure(s) SLOWER" in out
    # The gate as data: 5 + 5 repetitions and one summary row per point, numbers only.
    rows = list(csv.DictReader(open(tmp_path / "csv" / "gate.csv")))
    assert [r["kind"] for r in rows].count("rep") == 40 and [r["kind"] for r in rows].count("summary") == 4
    summ = {r["point"]: r for r in rows if r["kind"] == "summary"}
    assert int(summ["pile | midphase=aabb-only | cpu"]["slower"]) == 1
    assert abs(float(summ["pile | midphase=aabb-only | cpu"]["ratio_time"]) - 1.2) < 1e-9
    assert float(summ["pile | midphase=1,2 | cpu"]["p_slower"]) > 0.05  # one repetition as fast as before
    for r in rows:
        for k in ("value", "base_median", "new_median", "ratio_time", "ratio_lo", "ratio_hi", "p_slower"):
            if r[k]:
                float(r[k])


def test_same_run_and_faster_run_pass(tmp_path):
    rc, out, err = gate(tmp_path, "gate-base.json", "gate-base.json")
    assert rc == 0, out + err
    assert "gate: passed: 4 figure(s)" in out
    rc, out, err = gate(tmp_path, "gate-base.json", "gate-new.json")  # reversed: faster
    assert rc == 0, out + err


def test_thirty_percent_slower_everywhere_flags_every_point(tmp_path):
    rc, out, err = gate(tmp_path, scaled(BASE, 1.3))
    assert rc == 4, out + err
    assert out.count("gate: SLOWER") == 4, out
    assert "4 of 4 figure(s) SLOWER" in out
    # Above the threshold the slowdown is not one.
    rc, out, err = gate(tmp_path, scaled(BASE, 1.3), BASE, "--threshold", "40")
    assert rc == 0, out + err


@pytest.mark.parametrize("status", ["failed", "skipped"])
def test_every_point_failed_or_skipped_fails_naming_each(tmp_path, status):
    j = copy.deepcopy(BASE)
    for p in j["points"]:
        for k in ("windows", "wall_s"):
            p.pop(k, None)
        p["status"], p["reason"] = status, "non-finite state at frame 3"
    rc, out, err = gate(tmp_path, j)
    assert rc == 4, out + err
    for p in BASE["points"]:
        assert f"gate: FAILED: {p['id']}: {status} in the new run" in out, out


def test_one_failed_point_is_not_dropped(tmp_path):
    j = copy.deepcopy(BASE)
    j["points"][2] = {"id": BASE["points"][2]["id"], "index": 2, "status": "failed", "reason": "boom"}
    rc, out, err = gate(tmp_path, j)
    assert rc == 4, out + err
    assert f"gate: FAILED: {BASE['points'][2]['id']}: failed in the new run" in out and "boom" in out


def test_interrupted_run_with_one_of_four_points_fails(tmp_path):
    j = copy.deepcopy(BASE)
    j["points"] = j["points"][:1]
    j["complete"], j["stopped"] = False, "SIGINT"
    rc, out, err = gate(tmp_path, j)
    assert rc == 4, out + err
    assert "stopped by SIGINT" in out
    for p in BASE["points"][1:]:
        assert f"gate: FAILED: {p['id']}: missing in the new run" in out


def test_a_stopped_run_is_refused_even_with_every_point(tmp_path):
    j = copy.deepcopy(BASE)
    j["complete"], j["stopped"] = False, "SIGINT"
    rc, out, err = gate(tmp_path, j, BASE, "--threshold", "50")
    assert rc == 4, out + err
    assert "not a finished run" in out and "stopped by SIGINT" in out


@pytest.mark.parametrize("bad", [0.0, None, -5.0, float("inf"), float("nan")])
def test_non_finite_or_non_positive_figures_fail(tmp_path, bad):
    j = copy.deepcopy(BASE)
    set_values(sps(j, 1), [bad] * 5)
    rc, out, err = gate(tmp_path, j)
    assert rc == 4, out + err
    assert f"gate: FAILED: {BASE['points'][1]['id']}: steps/s (all) in the new run" in out, out
    # In the baseline, bad input.
    rc, out, err = gate(tmp_path, BASE, j)
    assert rc == 2, out + err
    assert "allowed: finite figures > 0 in the baseline" in err


def test_median_zero_with_finite_repetitions_fails(tmp_path):
    j = copy.deepcopy(BASE)
    set_values(sps(j, 0), [0.0, 0.0, 0.0, 1.0, 2.0])
    rc, out, err = gate(tmp_path, j)
    assert rc == 4, out + err
    assert BASE["points"][0]["id"] in out


@pytest.mark.parametrize("factor", [1.0, 17.0, 33.0])
def test_one_repetition_is_too_few_to_decide(tmp_path, factor):
    j = copy.deepcopy(BASE)
    j["settings"]["repeat"] = 1
    for i in range(4):
        set_values(sps(j, i), [sps(j, i)["values"][0] / factor])
    rc, out, err = gate(tmp_path, j, binary=factor == 17.0)
    assert rc == 2, out + err
    assert "too few repetitions to decide: 'pile | midphase=aabb-only | cpu' steps/s (all) has 5 in the baseline " \
           "and 1 in the new run" in err
    assert err.count("\n") == 1, err


def test_forged_baseline_range_is_refused(tmp_path):
    # The stored range says the baseline was slow; its repetitions say otherwise.
    j = copy.deepcopy(BASE)
    s = sps(j, 0)
    s["min"], s["max"], s["median"] = 1.0, 1e9, 2.0
    rc, out, err = gate(tmp_path, scaled(BASE, 1.3), j)
    assert rc == 2, out + err
    assert "allowed: a summary that matches its values" in err and "base.json" in err
    # A summary without its repetitions: nothing to decide on.
    del s["values"]
    rc, out, err = gate(tmp_path, scaled(BASE, 1.3), j)
    assert rc == 2, out + err
    assert "values: missing" in err


def test_another_machine_needs_across_machines(tmp_path):
    j = scaled(BASE, 1.0)
    j["machine"]["hostname"] = "other-host"
    rc, out, err = gate(tmp_path, j)
    assert rc == 2, out + err
    assert "--across-machines" in err and "other-host" in err
    rc, out, err = gate(tmp_path, j, BASE, "--across-machines", binary=True)
    assert rc == 0, out + err


def test_another_sweep_is_refused(tmp_path):
    j = copy.deepcopy(BASE)
    j["sweep"]["definition"]["frames"] = 100
    rc, out, err = gate(tmp_path, j)
    assert rc == 2, out + err
    assert "baseline of another sweep" in err


def with_cpu(j, wall_factor=1.0, cpu_factor=1.0):
    """A copy with cpu_steps_per_s (the wall repetitions x 0.8), both figures slowed apart."""
    j = copy.deepcopy(j)
    for i, p in enumerate(j["points"]):
        w = p["windows"]["all"]
        w["cpu_steps_per_s"] = {}
        set_values(w["cpu_steps_per_s"], [0.8 * v / cpu_factor for v in w["steps_per_s"]["values"]])
        set_values(w["steps_per_s"], [v / wall_factor for v in w["steps_per_s"]["values"]])
    return j


def test_cpu_time_decides_where_both_runs_have_it(tmp_path):
    # Wall-clock 30 % slower (another process's load), CPU time unchanged: passes by default.
    base = with_cpu(BASE)
    rc, out, err = gate(tmp_path, with_cpu(BASE, wall_factor=1.3), base)
    assert rc == 0, out + err
    rc, out, err = gate(tmp_path, with_cpu(BASE, wall_factor=1.3), base, "--timing", "wall")
    assert rc == 4 and out.count("gate: SLOWER") == 4, out + err
    # CPU time 30 % slower: the code is.
    rc, out, err = gate(tmp_path, with_cpu(BASE, cpu_factor=1.3), base)
    assert rc == 4 and out.count("gate: SLOWER: ") == 4 and "CPU steps/s (all)" in out, out + err
    # Forced CPU time on results without it: bad input.
    rc, out, err = gate(tmp_path, BASE, BASE, "--timing", "cpu")
    assert rc == 2 and "no cpu_steps_per_s" in err, out + err


def test_bad_level_is_refused(tmp_path):
    rc, out, err = gate(tmp_path, "gate-base.json", "gate-base.json", "--level", "0.9")
    assert rc == 2, out + err


def report(tmp_path, *args):
    """(exit code, stdout, stderr) of make_report.py in-process."""
    out, err = io.StringIO(), io.StringIO()
    argv, sys.argv = sys.argv, ["make_report.py", "-o", str(tmp_path / "out"), *args]
    rc = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            MAKE_REPORT.main()
    except SystemExit as e:
        rc = e.code if isinstance(e.code, int) else 1
    finally:
        sys.argv = argv
    return rc, out.getvalue(), err.getvalue()


@pytest.mark.parametrize("name", ["bench-small-table6.json", "bench-small-scaling.json", "gate-base.json"])
def test_csv_is_data(tmp_path, name):
    """--csv: per point and window one row per repetition and a summary row (the median);
    numbers only, units in the header; the values are the result's repetitions."""
    j = load(name)
    rc, out, err = report(tmp_path, "--csv", str(tmp_path / "csv"), os.path.join(DATA, name))
    assert rc == 0, out + err
    rows = list(csv.DictReader(open(tmp_path / "csv" / (j["sweep"]["name"] + ".csv"))))
    head = list(rows[0].keys())
    figs = [h for h in head if h.endswith("]")]
    assert figs and all(" [" in h for h in figs), head
    for r in rows:
        assert r["kind"] in ("rep", "summary")
        for h in figs:
            if r[h] != "":
                float(r[h])  # a number, never "20,196 (3,396-27,014, n=5)" or "+42.9%"
    for p in j["points"]:
        mine = [r for r in rows if r["point"] == p["id"]]
        if p["status"] != "ok":
            assert [r["kind"] for r in mine] == ["summary"], mine
            continue
        if "windows" in p:
            for wn, w in p["windows"].items():
                sp = w["steps_per_s"]
                reps = [r for r in mine if r["window"] == wn and r["kind"] == "rep"]
                summ = [r for r in mine if r["window"] == wn and r["kind"] == "summary"]
                assert [float(r["steps_per_s [1/s]"]) for r in reps] == sp["values"]
                assert [int(r["repetition"]) for r in reps] == list(range(sp["n"]))
                assert len(summ) == 1 and float(summ[0]["steps_per_s [1/s]"]) == sp["median"]
        else:
            reps = [r for r in mine if r["kind"] == "rep"]
            assert [float(r["ms_per_frame [ms]"]) for r in reps] == p["ms_per_frame"]["values"]


def test_several_runs_a_side_are_pooled(tmp_path):
    """--baseline R1 --baseline R2 NEW1 NEW2: runs of one build, the same points: their
    repetitions pooled (10 a side here); a point failed in one new run fails the gate."""
    paths = {}
    for k, (name, j) in enumerate((("b1", BASE), ("b2", scaled(BASE, 1.0)), ("n1", scaled(BASE, 1.3)),
                                   ("n2", scaled(BASE, 1.3)))):
        j = copy.deepcopy(j)
        j["build"]["build_id"] = "base" if name[0] == "b" else "new"
        j["started"] = f"2026-11-22T0{k}:00:00Z"  # four runs (a copy of one run is refused: counted once)
        paths[name] = tmp_path / f"{name}.json"
        paths[name].write_text(json.dumps(j))
    args = ["--baseline", str(paths["b1"]), "--baseline", str(paths["b2"]), "--csv", str(tmp_path / "csv"),
            str(paths["n1"]), str(paths["n2"])]
    rc, out, err = report(tmp_path, *args)
    assert rc == 4 and out.count("gate: SLOWER: ") == 4, out + err
    rows = list(csv.DictReader(open(tmp_path / "csv" / "gate.csv")))
    assert sum(1 for r in rows if r["kind"] == "rep" and r["side"] == "new") == 4 * 10
    bad = json.loads(paths["n2"].read_text())
    bad["points"][3] = {"id": BASE["points"][3]["id"], "index": 3, "status": "failed", "reason": "boom"}
    paths["n2"].write_text(json.dumps(bad))
    rc, out, err = report(tmp_path, *args)
    assert rc == 4 and f"gate: FAILED: {BASE['points'][3]['id']}: failed in the new run" in out, out + err
