"""The report's comparisons (issue 34 item 4) on small generated bench results: the paper's
FPS on its own axis, engine labels from the registry, stage ms beside the shares, speed-ups
on the plots, the load mark only where the load exceeded the free cores, the penetration
of a stack commented from its frames. Run by ctest (`report.sections`)."""
import contextlib
import copy
import importlib.util
import io
import json
import os
import re
import sys

import numpy as np

SRC = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_spec = importlib.util.spec_from_file_location("make_report_fixes", os.path.join(SRC, "report", "make_report.py"))
MR = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(MR)
# The engines' own broadphase classes from the registry, as `octocd report` reads them.
OCTOCD_BIN = os.environ.get("OCTOCD_BIN", os.path.join(SRC, "build", "octocd"))
MR.read_registry_broadphases(OCTOCD_BIN)

STAGE_MS = {"integrate": 0.1, "aabbs": 0.05, "broadphase": 0.6, "midphase": 0.2, "response": 0.3, "metrics": 0.05}


def spread(v, n=3, rel=0.01):
    vals = [v * (1 - rel), v, v * (1 + rel)][:n]
    s = sorted(vals)
    return {"median": s[len(s) // 2], "min": s[0], "max": s[-1], "n": n, "values": vals}


def window(sps, scale=1.0):
    w = {"first": 31, "last": 330, "frames": 300, "steps_per_s": spread(sps), "step_ms": spread(1000.0 / sps),
         "stage_ms": {k: spread(v * scale) for k, v in STAGE_MS.items()}}
    for k in ("pairs", "box_pairs", "vertex_tests", "contacts", "cell_candidates", "memory_bytes",
              "penetration_mean", "penetration_max"):
        w[k] = spread(1.0)
    return w


def point(idx, scene, engine, axis, value, label, sps, load=None, ignores=False, windows=("all",),
          engine_broadphase="octree"):
    p = {"id": f"{scene} | {axis}={value} | {engine}", "index": idx, "status": "ok", "bodies": 400,
         "params": {"scene": scene, "engine": engine, "axes": {axis: value}, "labels": {axis: label}},
         "engine_broadphase": engine_broadphase,
         "has_stage": {s: engine != "bullet" for s in STAGE_MS},
         "windows": {w: window(sps) for w in windows}}
    if load is not None:
        p["load_average"] = [load, load, load]
    if ignores:
        p["ignores"] = {axis: f"engine {engine} has no {axis}"}
    return p


def result(name, points, threads=16, omp=16, load_start=1.1, load_end=1.1):
    return {"format": "octocd-bench", "version": 1, "complete": True,
            "sweep": {"name": name, "kind": "steps", "description": "generated", "definition": {"name": name}},
            "settings": {"engines": ["cpu", "cuda", "bullet"], "repeat": 3, "frames": 330, "warmup": 30},
            "machine": {"hostname": "h", "cpu": "c", "gpu": "g", "threads": threads, "omp_threads": omp,
                        "load_average": [load_start] * 3, "load_average_end": [load_end] * 3},
            "build": {"build_id": "0.1.0+t", "git_revision": "t"}, "points": points,
            "points_total": len(points), "started": "s", "updated": "u"}


def table5(cpu_load=17.0, cuda_load=1.1):
    """table5 on 16 cores, the CPU engine on 16 OpenMP threads: cpu and cuda (A, B, C) and
    bullet (no midphase: A only, labelled A by the sweep)."""
    pts, i = [], 0
    for sc in ("bunny-random-400", "dragon-random-250"):
        for cfg, val in (("A", "2"), ("B", "1,2"), ("C", "0,1,2")):
            for eng, base, load in (("cpu", 2000.0, cpu_load), ("cuda", 20000.0, cuda_load)):
                sps = base * {"A": 1.0, "B": 1.5, "C": 2.0}[cfg]
                pts.append(point(i, sc, eng, "midphase", val, cfg, sps, load))
                i += 1
        pts.append(point(i, sc, "bullet", "midphase", "2", "A", 21336.0, 1.1, ignores=True,
                         engine_broadphase="bullet-dbvt"))
        i += 1
    return result("table5", pts)


class FakeDoc:
    """Collects what a section writes; keeps the figures open for inspection."""

    def __init__(self):
        self.texts, self.tables, self.figs = [], [], []
        self.csv_dir = None

    def p(self, text, cls=None):
        self.texts.append(text)

    def h(self, *a, **k):
        pass

    def table(self, header, rows, note=None, name="table"):
        self.tables.append((header, rows))

    def figure(self, fig, name, caption):
        self.figs.append((name, fig, caption))

    def cells(self):
        return [str(c) for _, rows in self.tables for r in rows for c in r]


def section(fn, j):
    MR.plt.close("all")  # the previous test's figures
    doc = FakeDoc()
    g = MR.merge([("r.json", j)])[0]
    fn(doc, g)
    return doc


def fig_texts(fig):
    return [t.get_text() for ax in fig.axes for t in ax.texts]


def run_main(tmp_path, *inputs):
    paths = []
    for k, x in enumerate(inputs):
        p = tmp_path / f"in{k}.json"
        p.write_text(json.dumps(x))
        paths.append(str(p))
    out, err = io.StringIO(), io.StringIO()
    argv, sys.argv = sys.argv, ["make_report.py", "-o", str(tmp_path / "out"), *paths]
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            MR.main()
        rc = 0
    except SystemExit as e:
        rc = e.code if isinstance(e.code, int) else 1
    finally:
        sys.argv = argv
    md = (tmp_path / "out" / "report.md").read_text() if rc == 0 else ""
    return rc, md, out.getvalue() + err.getvalue()


# ---- the paper's FPS never on our steps/s axis ------------------------------------------------

def test_paper_fps_has_its_own_axis_not_ours():
    doc = section(MR.section_table5, table5())
    name, fig, caption = next(f for f in doc.figs if f[0] == "table5-steps")
    ours, paper = fig.axes[0], fig.axes[1]
    fps = {MR.PAPER["table5"]["rows"][sc][c][0] for sc in ("bunny-random-400", "dragon-random-250") for c in "ABC"}
    our_heights = {round(b.get_height(), 6) for b in ours.patches}
    our_lines = {round(float(y), 6) for ln in ours.lines for y in ln.get_ydata()}
    assert not {round(f, 6) for f in fps} & (our_heights | our_lines), "a paper FPS is drawn on our steps/s axis"
    assert "steps/s" in ours.get_ylabel() and ours.get_yscale() == "log"
    assert "paper FPS" in paper.get_ylabel() and "steps/s" not in paper.get_ylabel()
    assert {round(b.get_height(), 6) for b in paper.patches} == {round(f, 6) for f in fps}
    assert "own axis" in caption


# ---- speed-ups printed on the plots -----------------------------------------------------------

def test_speedups_are_printed_on_the_steps_plot():
    doc = section(MR.section_table5, table5())
    fig = next(f for n, f, _ in doc.figs if n == "table5-steps")
    texts = fig_texts(fig)
    # B = 1.5 x A and C = 2 x A for cpu and cuda on both scenes: 8 speed-ups; bullet (one value) none.
    assert sorted(t.split()[-1] for t in texts if t.endswith("x")) == ["1.50x"] * 4 + ["2.00x"] * 4, texts
    # Each bar names its engine (issue 80 item 1): 2 scenes x (3 cpu + 3 cuda + 1 bullet) bars.
    names = sorted(t.get_text().split()[0] for t in fig.axes[0].texts)
    assert names == ["bullet"] * 2 + ["cpu"] * 6 + ["cuda"] * 6, texts


# ---- absolute stage times beside the shares ---------------------------------------------------

def test_stage_ms_printed_beside_shares():
    doc = section(MR.section_table5, table5())
    fig = next(f for n, f, _ in doc.figs if n == "table5-stages")
    texts = fig_texts(fig)
    assert texts.count("1.30 ms") == 12, texts  # each bar's step total (sum of the stage medians)
    assert "0.60" in texts  # broadphase, 46 % of the step: its ms inside the segment
    header, rows = next(t for t in doc.tables if t[0][0] == "point")
    assert header[3] == "broadphase ms (%)"
    assert rows[0][3] == "0.600 (46%)" and rows[0][-1] == "1.30"


# ---- labels from the engine registry; Bullet in the fastest table -----------------------------

def test_bullet_named_by_what_it_ran():
    bullet_col = [r[-1] for r in verdicts(table5())]
    assert len(bullet_col) == 2
    doc = section(MR.section_table5, table5())
    assert all("no midphase, one configuration: 21,336 (" in c for c in bullet_col), bullet_col
    fig = next(f for n, f, _ in doc.figs if n == "table5-steps")
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert "bullet no midphase" in labels and "bullet A" not in labels


def tablea1():
    pts, i = [], 0
    for mesh in ("bunny", "dragon"):
        for eng, bp, lab, sps, ign, eb in (("cpu", "hash:0.25", "SH", 900.0, False, "hash"),
                                           ("cpu", "octree", "O-A", 1000.0, False, "octree"),
                                           ("bullet", "hash:0.25", "SH", 5000.0, True, "bullet-dbvt")):
            p = point(i, "bunny-stack-50", eng, "broadphase", bp, lab, sps, 1.0, ignores=ign,
                      windows=("early", "late"), engine_broadphase=eb)
            p["params"]["axes"]["mesh"] = mesh
            p["id"] += f" | mesh={mesh}"
            p["params"]["labels"]["mesh"] = mesh
            pts.append(p)
            i += 1
    return result("tableA1", pts)


def test_bullet_broadphase_named_btdbvt_never_sh(tmp_path):
    doc = section(MR.section_tableA1, tablea1())
    cells = doc.cells()
    assert "(one broadphase: btDbvtBroadphase)" in cells
    fig = next(f for n, f, _ in doc.figs if n == "tableA1-late")
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert "bullet btDbvtBroadphase" in labels and not any(l.startswith("bullet SH") for l in labels), labels
    texts = fig_texts(fig)
    assert [t.split()[-1] for t in texts].count("1.11x") == 2, texts  # O-A over SH, cpu, both meshes
    rc, md, log = run_main(tmp_path, tablea1())
    assert rc == 0, log
    assert "bullet SH" not in md and "btDbvtBroadphase" in md


def test_what_each_engine_ran_is_named():
    j = tablea1()
    for p in j["points"]:
        if p["params"]["engine"] == "bullet":
            p["geometry"] = "convex hulls of the meshes"
    g = MR.merge([("r.json", j)])[0]
    assert MR.engines_ran_text(g) == ("Engines ran: cpu: 4 of 4 point(s) measured, 900.0–1,000 steps/s (medians), "
                                      "broadphase hash, octree; bullet: 2 of 2 point(s) measured, 5,000 steps/s, "
                                      "broadphase btDbvtBroadphase, geometry convex hulls of the meshes")
    # A skipped engine is named with its count and reason, never an empty "cuda: ".
    j["points"].append({"id": "x | cuda", "index": 99, "status": "skipped", "reason": "built without CUDA",
                        "params": {"scene": "bunny-stack-50", "engine": "cuda", "axes": {}}})
    g = MR.merge([("r.json", j)])[0]
    assert MR.engines_ran_text(g).endswith("; cuda: 0 of 1 point(s) measured, 1 skipped (built without CUDA)")


def test_own_broadphase_classes_are_the_registrys():
    """The report names every built-in engine's own broadphase by the class the registry
    gives (`octocd engines --json --no-checks`), and a broadphase the registry does not know by its name."""
    import subprocess
    out = subprocess.run([OCTOCD_BIN, "engines", "--json", "--no-checks"], capture_output=True, text=True,
                         check=True).stdout
    pairs = {e["own_broadphase"]: e["own_broadphase_class"] for e in json.loads(out)["engines"]
             if e.get("kind") == "builtin" and e.get("own_broadphase")}
    assert "bullet-dbvt" in pairs, pairs
    report_plots = sys.modules["report_plots"]  # imported by make_report.py
    for eb, cls in pairs.items():
        assert report_plots.broadphase_class(eb, eb) == cls
    assert report_plots.broadphase_class("no-such-broadphase", "no-such-broadphase") == "no-such-broadphase"


# ---- the load mark only where the load exceeded the free cores ---------------------------------

SCENES = ("bunny-random-400", "dragon-random-250")


def verdicts(j):
    """The fastest table's rows of the scenes the generated result has."""
    doc = section(MR.section_table5, j)
    return [r for r in next(rows for h, rows in doc.tables if h[1] == "paper: fastest") if r[0] in SCENES]


def test_no_load_mark_at_low_load():
    # Load 1.1 on 16 cores at the start and end, cuda and bullet points at 1.1 (their own thread
    # included), cpu points at 16.5 (its 16 OpenMP threads and 0.5 of others on 16 cores, within
    # the cores): nothing is marked.
    rows = verdicts(table5(cpu_load=16.0))
    assert not any("⚠" in str(c) for r in rows for c in r), rows
    g = MR.merge([("r.json", table5(cpu_load=16.0))])[0]
    assert MR.load_warning(g["first"]["machine"])  # the run-level rule still flags 1.1 + 16 threads ...
    doc = FakeDoc()
    doc.html, doc.md = [], []
    MR.machine_block(doc, g)
    assert "⚠" not in "".join(doc.md)  # ... but no point ran short of cores, so nothing is marked


def test_load_mark_where_load_exceeds_free_cores():
    # cpu points measured at load 18 (2 runnable threads of others beside its 16 on 16 cores):
    # the cpu verdicts are marked, the cuda and bullet ones (load 1.1) are not.
    rows = verdicts(table5(cpu_load=18.0))
    cpu = [r[2] for r in rows]
    cuda = [r[3] for r in rows]
    bullet = [r[4] for r in rows]
    assert all(c.startswith("⚠ ") for c in cpu), cpu
    assert not any("⚠" in c for c in cuda + bullet), cuda + bullet
    # A cuda point where others held 15.5 of 16 cores: its one host thread still had a core ...
    j = table5(cpu_load=16.0, cuda_load=16.0)
    assert not any("⚠" in r[3] for r in verdicts(j))
    # ... at 17.5 (16.5 of others) it had none.
    j = table5(cpu_load=16.0, cuda_load=17.5)
    assert all(r[3].startswith("⚠ ") for r in verdicts(j))
    g = MR.merge([("r.json", j)])[0]
    doc = FakeDoc()
    doc.html, doc.md = [], []
    MR.machine_block(doc, g)
    assert "⚠ 6 of 14 measured points ran under load" in "".join(doc.md)


def test_load_mark_without_point_loads_uses_the_run_start_and_end():
    j = table5()
    for p in j["points"]:
        p.pop("load_average", None)
    j["machine"]["load_average"] = [1.1] * 3
    j["machine"]["load_average_end"] = [1.2] * 3
    rows = verdicts(j)
    # Others' 1.1 at the start leaves 14.9 cores for the cpu engine's 16 threads: cpu marked; cuda not.
    assert all(r[2].startswith("⚠ ") for r in rows) and not any("⚠" in r[3] for r in rows)
    # Others' 0.5 leaves 15.5 cores for 16 threads: less than one core short, no mark (a
    # 1-minute load average that also counts the bench's own waiting threads says no more).
    j["machine"]["load_average"] = [0.5] * 3
    j["machine"]["load_average_end"] = [16.6] * 3
    assert not any("⚠" in str(c) for r in verdicts(j) for c in r)
    j["machine"]["load_average"] = [1.1] * 3
    j["machine"]["omp_threads"] = 4
    assert not any("⚠" in str(c) for r in verdicts(j) for c in r)


# ---- the penetration of a stack commented from the data -----------------------------------------

def test_penetration_comment_settling_and_jittering():
    n = 300
    frame = np.arange(1, n + 1, dtype=float)
    # Settles: 8 mm at the impact, 1 mm at rest.
    settle = {"frame": frame, "penetration_max": np.where(frame < 50, 0.008, 0.001),
              "penetration_mean": np.where(frame < 50, 0.004, 0.0005)}
    t = MR.penetration_comment(settle, "stack.h5")
    assert "largest 8.00 mm at frame 1." in t and "(down by more than half)" in t, t
    assert "it settles (the per-frame largest d_p stays within 0 mm of 1.00 mm)" in t, t
    # Rests at the slop from the start (box-stack): as deep as at first, and settled.
    rest = 0.00102 + 1e-6 * np.sin(frame)
    t = MR.penetration_comment({"frame": frame, "penetration_max": rest, "penetration_mean": rest}, "s")
    assert "(about as deep)" in t and "it settles" in t, t
    # Jitters between 6 and 10 mm for the whole run (the CPU stack of issue 34).
    jit = 0.008 + 0.002 * np.sin(frame * 1.3)
    t = MR.penetration_comment({"frame": frame, "penetration_max": jit, "penetration_mean": jit / 2}, "stack.h5")
    assert "(about as deep)" in t and "mean 4.00 mm" in t, t
    assert re.search(r"it does not settle: the per-frame largest d_p jitters between 6\.0+ and 10\.0+ mm", t), t
    # Grows: the last third deeper than the first, and not settled.
    t = MR.penetration_comment({"frame": frame, "penetration_max": 0.001 + frame * 1e-5,
                                "penetration_mean": frame * 1e-6}, "x")
    assert "(deeper)" in t and "does not settle" in t, t
    # Frames without a figure (NaN from the reader) are left out.
    holes = settle["penetration_max"].copy()
    holes[100:110] = np.nan
    t2 = MR.penetration_comment(dict(settle, penetration_max=holes), "stack.h5")
    assert "over 290 frames" in t2 and "it settles" in t2, t2
    for bad in (np.zeros(n), np.full(n, np.nan), np.zeros(0)):
        assert MR.penetration_comment({"frame": np.arange(len(bad)), "penetration_max": bad,
                                       "penetration_mean": bad}) == ""


def test_report_end_to_end_table5(tmp_path):
    rc, md, log = run_main(tmp_path, table5(cpu_load=18.0))
    assert rc == 0, log
    assert "⚠ 6 of 14 measured points ran under load" in md
    assert "broadphase ms (%)" in md and "no midphase, one configuration" in md


def test_gate_marks_only_points_measured_under_load(tmp_path):
    """The gate's verdicts: ⚠ on a point whose run (either side) ran short of cores."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import test_gate as tg
    new = tg.scaled(tg.BASE, 1.3)  # every point 30 % slower: SLOWER verdicts to mark or not
    base = copy.deepcopy(tg.BASE)
    for j in (base, new):
        j["machine"]["load_average"] = j["machine"]["load_average_end"] = [0.3] * 3
        for p in j["points"]:
            p["load_average"] = [1.2] * 3  # its own thread and 0.2 of others on 2 cores
    new["points"][0]["load_average"] = [3.5] * 3  # 2.5 of others on 2 cores: no core left for it
    rc, out, err = tg.gate(tmp_path, new, base)
    assert rc == 4, out + err
    rows = [l for l in (tmp_path / "out" / "report.md").read_text().splitlines() if l.endswith("SLOWER |")]
    assert len(rows) == 4, rows
    assert [("⚠ SLOWER" in r) for r in rows] == [True, False, False, False], rows


# ---- one sweep run per engine set (Bullet in a run of its own) ---------------------------------

def test_runs_of_one_sweep_by_engine_set_give_every_engine_its_column(tmp_path):
    full = table5()
    ours = copy.deepcopy(full)
    ours["points"] = [p for p in full["points"] if p["params"]["engine"] != "bullet"]
    ours["settings"]["engines"], ours["points_total"] = ["cpu", "cuda"], len(ours["points"])
    bullet = copy.deepcopy(full)
    bullet["points"] = [p for p in full["points"] if p["params"]["engine"] == "bullet"]
    bullet["settings"]["engines"], bullet["settings"]["repeat"] = ["bullet"], 5
    bullet["points_total"] = len(bullet["points"])
    for j in (ours, bullet):
        j["sweep"]["definition"]["engines"] = ["cpu", "cuda", "bullet"]
    g = MR.merge([("bullet.json", bullet), ("ours.json", ours)])[0]
    assert g["engines"] == ["cpu", "cuda", "bullet"]  # the sweep's order, not the files'
    assert g["points_total"] == len(full["points"])
    rc, md, log = run_main(tmp_path, bullet, ours)
    assert rc == 0, log
    head = next(line for line in md.splitlines() if line.startswith("| scene (bodies) | config"))
    assert head.endswith("| cpu steps/s | cuda steps/s | bullet steps/s |"), head
    assert "engines bullet: 5 repetitions per point" in md and "engines cpu, cuda: 3 repetitions per point" in md
    assert f"Points: {len(full['points'])} of {len(full['points'])} in these files" in md
    # Without the Bullet run the table has no Bullet column and says the run is complete.
    rc, md, log = run_main(tmp_path, ours)
    assert rc == 0 and "bullet steps/s" not in md, log
