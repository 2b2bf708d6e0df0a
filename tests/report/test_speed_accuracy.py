"""The report's speed-accuracy section (issue 34 item 3; report/report_speed_accuracy.py) on
small generated results of kind `speed-accuracy` (no octocd run): the Pareto front of a known
set, the reading's sentences (fastest engine and ratio) on known data, references, diverged
and skipped points, two shards merged, one plot per scene. Run by ctest
(`report.speed_accuracy`)."""
import importlib.util
import os
import re
import sys

import pytest

SRC = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_spec = importlib.util.spec_from_file_location("make_report_sa", os.path.join(SRC, "report", "make_report.py"))
MR = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(MR)
RSA = MR.RSA
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import test_report_comparisons as FIXES  # noqa: E402  (its run_main: make_report's main on generated inputs)

LABELS = {("cpu", "mesh", False): "cpu (octree, mesh)", ("cuda", "mesh", False): "cuda (lbvh, mesh)",
          ("bullet", "hull", True): "bullet (btDbvtBroadphase, hulls, rotation)",
          ("bullet", "box", False): "bullet (btDbvtBroadphase, boxes)"}


def spread(v, rel=0.01):
    vals = [v * (1 - rel), v, v * (1 + rel)]
    return {"median": v, "min": vals[0], "max": vals[2], "mean": v, "stdev": v * rel, "n": 3, "values": vals}


def sa_point(scene, engine, geometry, rotation, n, speed=None, err=None, iterations=None, status="ok",
             reason="", ref_n=960):
    """One point at dt = 1/n s; err None at ref_n (the line's reference: error 0)."""
    line = f"{scene} | {engine} | {geometry} | {'rotation' if rotation else 'translation'}" + \
        (f" | iterations={iterations}" if iterations is not None else "")
    axes = {"dt": f"{1.0 / n:.6f}"}
    if iterations is not None:
        axes["iterations"] = str(iterations)
    p = {"id": f"{line} | dt={axes['dt']}", "status": status,
         "params": {"scene": scene, "engine": engine, "axes": axes}, "geometry": geometry, "rotation": rotation,
         "line": line, "engine_label": LABELS[engine, geometry, rotation], "dt": 1.0 / n, "iterations": iterations,
         "steps": 240, "sim_seconds": 1.0}
    if status == "ok":
        p["speed"] = spread(speed)
        p["steps_per_s"] = spread(speed * n)
        p["error"] = {"consistency": 0.0 if n == ref_n else err, "reference_dt": 1.0 / ref_n,
                      "max_penetration_m": 0.002, "energy_drift": 0.01, "momentum_residual": None}
    else:
        p["reason"] = reason
    return p


def box_stack():
    """cpu (mesh), bullet (hulls, rotation) and cuda (mesh) on box-stack, dt 1/960 .. 1/60 s;
    bullet's 1/60 diverged. Pareto front (fastest first): bullet 1/120, cpu 1/60, bullet 1/240,
    cpu 1/120, cpu 1/240, cpu 1/480; bullet 1/480 and every cuda point are dominated."""
    sc = "box-stack"
    return [sa_point(sc, "cpu", "mesh", False, 960, 0.5),
            sa_point(sc, "cpu", "mesh", False, 480, 1.0, 1e-4),
            sa_point(sc, "cpu", "mesh", False, 240, 2.0, 5e-4),
            sa_point(sc, "cpu", "mesh", False, 120, 4.0, 6e-4),
            sa_point(sc, "cpu", "mesh", False, 60, 8.0, 2e-2),
            sa_point(sc, "bullet", "hull", True, 960, 1.5),
            sa_point(sc, "bullet", "hull", True, 480, 3.0, 8e-4),
            sa_point(sc, "bullet", "hull", True, 240, 6.0, 4e-3),
            sa_point(sc, "bullet", "hull", True, 120, 12.0, 5e-2),
            sa_point(sc, "bullet", "hull", True, 60, status="diverged",
                     reason="non-finite state at step 31 (body 4 position)"),
            sa_point(sc, "cuda", "mesh", False, 960, 0.4),
            sa_point(sc, "cuda", "mesh", False, 480, 0.8, 3e-4),
            sa_point(sc, "cuda", "mesh", False, 240, 1.5, 2e-3)]


def mixed_pile():
    """One engine only (cpu); bullet skipped."""
    sc = "mixed-pile-1000"
    return [sa_point(sc, "cpu", "mesh", False, 960, 0.1),
            sa_point(sc, "cpu", "mesh", False, 480, 0.2, 3e-4),
            sa_point(sc, "cpu", "mesh", False, 240, 0.4, 2e-3),
            sa_point(sc, "bullet", "box", False, 960, status="skipped",
                     reason="engine bullet cannot run scene mixed-pile-1000: ...")]


def rot_drop():
    """Every point diverged or skipped."""
    sc = "rot-drop-220"
    return [sa_point(sc, "cpu", "mesh", False, 960, status="skipped",
                     reason="engine cpu cannot run rotating bodies"),
            sa_point(sc, "bullet", "hull", True, 960, status="diverged", reason="non-finite state at step 3")]


def result(points, shard=(0, 1)):
    for i, p in enumerate(points):
        p.setdefault("index", i)
    return {"format": "octocd-bench", "version": 1, "complete": True,
            "sweep": {"name": "speed-accuracy", "kind": "speed-accuracy", "description": "generated",
                      "definition": {"name": "speed-accuracy", "kind": "speed-accuracy"}},
            "settings": {"engines": ["cpu", "cuda", "bullet"], "repeat": 3, "shard": {"index": shard[0],
                                                                                       "count": shard[1]}},
            "machine": {"hostname": "h", "cpu": "c", "gpu": "g", "threads": 16, "omp_threads": 1,
                        "load_average": [1.0] * 3, "load_average_end": [1.0] * 3},
            "build": {"build_id": "0.1.0+t", "git_revision": "t"}, "points": points,
            "points_total": len(points), "started": "s", "updated": "u"}


def all_points():
    return box_stack() + mixed_pile() + rot_drop()


class FakeDoc:
    """Collects what a section writes; keeps the figures open for inspection."""

    def __init__(self):
        self.texts, self.tables, self.figs, self.heads = [], [], [], []
        self.csv_dir = None

    def p(self, text, cls=None):
        self.texts.append(text)

    def h(self, level, text, anchor=None):
        self.heads.append(text)

    def table(self, header, rows, note=None, name="table"):
        self.tables.append((name, header, rows))

    def figure(self, fig, name, caption):
        self.figs.append((name, fig, caption))


def section(points):
    MR.plt.close("all")
    doc = FakeDoc()
    MR.section_speed_accuracy(doc, MR.merge([("r.json", result(points))])[0])
    return doc


def run_main(tmp_path, *inputs):
    """make_report's main on the inputs (test_report_comparisons.run_main): (exit code, report.md,
    index.html, output)."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    rc, md, out = FIXES.run_main(tmp_path, *inputs)
    FIXES.MR.plt.close("all")
    return rc, md, (tmp_path / "out" / "index.html").read_text() if rc == 0 else "", out


def key(p):
    return (p["params"]["engine"], round(1.0 / p["dt"]))


# ---- the Pareto front ---------------------------------------------------------------------------

def test_pareto_front_of_a_known_set():
    front = RSA.pareto_front(box_stack())
    assert [key(p) for p in front] == [("cpu", 480), ("cpu", 240), ("cpu", 120), ("bullet", 240), ("cpu", 60),
                                       ("bullet", 120)]
    # Along the front the error rises with the speed; references (error 0) and diverged points are out.
    assert all(RSA.speed(a) < RSA.speed(b) and RSA.error(a) < RSA.error(b) for a, b in zip(front, front[1:]))


def test_pareto_front_against_brute_force():
    pts = box_stack() + mixed_pile()
    cand = [p for p in pts if RSA.speed(p) is not None and RSA.error(p)]
    brute = [p for p in cand if not any(
        RSA.speed(q) >= RSA.speed(p) and RSA.error(q) <= RSA.error(p)
        and (RSA.speed(q) > RSA.speed(p) or RSA.error(q) < RSA.error(p)) for q in cand)]
    assert sorted(map(key, RSA.pareto_front(pts))) == sorted(map(key, brute))


def test_front_is_marked_in_the_table_and_on_the_plot():
    doc = section(box_stack())
    name, header, rows = next(t for t in doc.tables if t[0] == "speed-accuracy-points")
    col = header.index("Pareto")
    assert sum(r[col] == "front" for r in rows) == 6
    fig = doc.figs[0][1]
    ax = fig.axes[0]
    assert "Pareto front (all engines)" in ax.get_legend_handles_labels()[1]


# ---- the reading --------------------------------------------------------------------------------

def test_reading_names_the_fastest_engine_and_its_ratio_at_separating_thresholds():
    doc = section(box_stack())
    text = next(t for t in doc.texts if "At consistency error" in t)
    sentences = re.findall(r"At consistency error <= (\S+),", text)
    # 1, 2, 5 x 1e-4 .. 1e-1; a threshold answering as the stricter one before it is not repeated
    # (2e-4: cpu alone; 2e-3: cpu fastest, all three; 1e-2: bullet fastest, all three). Six differ:
    # 1e-4 (cpu alone), 5e-4 (cpu, cuda), 1e-3 (cpu, all three), 5e-3 (bullet), 2e-2 (cpu), 5e-2
    # (bullet); four are named: the strictest, the first all reach, then where the fastest changes.
    assert sentences == ["1e-4", "1e-3", "5e-3", "2e-2"], text
    assert ("At consistency error <= 1e-4, only cpu (octree, mesh) has a point: dt 1/480 s (1.00 simulated s per "
            "wall s, error 1e-4); bullet (btDbvtBroadphase, hulls, rotation) and cuda (lbvh, mesh) reach no point "
            "under it.") in text
    assert ("At consistency error <= 1e-3, the fastest is cpu (octree, mesh) at dt 1/120 s (4.00 simulated s per "
            "wall s, error 6e-4), 1.33x faster than bullet (btDbvtBroadphase, hulls, rotation) at its best point "
            "under that error, dt 1/480 s (3.00 simulated s per wall s, error 8e-4); then cuda (lbvh, mesh) 5.00x "
            "slower.") in text
    assert ("At consistency error <= 5e-3, the fastest is bullet (btDbvtBroadphase, hulls, rotation) at dt 1/240 s "
            "(6.00 simulated s per wall s, error 4e-3), 1.50x faster than cpu (octree, mesh)") in text
    assert "no clear winner" not in text  # the speeds' ranges are 1 % wide: apart
    assert ("The Pareto front holds 6 point(s): 4 of cpu (octree, mesh) and 2 of bullet (btDbvtBroadphase, hulls, "
            "rotation); none of cuda (lbvh, mesh).") in text
    assert "1 diverged" in text


def test_at_most_four_thresholds_the_strictest_and_the_loosest_kept():
    pts = []
    for k in range(6):  # engine k: error 5e-(7-k), speed 2^k: each decade has a new fastest engine (6 changes)
        p = sa_point("box-stack", "cpu", "mesh", False, 480, 2.0 ** k, 5 * 10.0 ** (k - 7))
        p["engine_label"] = f"engine {k}"
        pts.append(p)
    ts = RSA.thresholds(pts)
    assert [RSA.sci(x) for x, _, _ in ts] == ["5e-7", "5e-6", "5e-5", "5e-2"]
    assert [order[0] for _, _, order in ts] == ["engine 0", "engine 1", "engine 2", "engine 5"]


def test_reading_says_no_clear_winner_when_speed_ranges_overlap():
    pts = box_stack()
    for p in pts:  # bullet's 1/480 within 1 % of cpu's 1/120
        if key(p) == ("bullet", 480):
            p["speed"] = spread(3.98)
    text = " ".join(section(pts).texts)
    assert "1.01x faster than bullet" in text and "no clear winner" in text


def test_reading_with_one_engine_only():
    text = section(mixed_pile()).texts[-1]
    assert text.startswith("Only cpu (octree, mesh) has points with an error here: no engine to compare it with."), text
    assert "fastest point is dt 1/240 s (0.400 simulated s per wall s, error 2e-3)" in text
    assert "most consistent (references aside) dt 1/480 s (0.200" in text
    assert "No point with an error here for bullet (btDbvtBroadphase, boxes)" in text and "1 skipped" in text


def test_reading_when_every_point_diverged_or_was_skipped():
    doc = section(rot_drop())
    assert "Every point of this scene is unmeasured (1 diverged, 1 skipped)" in doc.texts[-1]
    assert not doc.figs  # nothing to draw
    name, header, rows = next(t for t in doc.tables if t[0] == "speed-accuracy-lost")
    assert sorted(r[0] for r in rows) == ["diverged", "skipped"]
    assert any("non-finite state at step 3" in r[-1] for r in rows)


def test_reading_when_only_references_ran():
    pts = [sa_point("box-stack", "cpu", "mesh", False, 960, 0.5),
           sa_point("box-stack", "cpu", "mesh", False, 480, status="diverged", reason="non-finite")]
    assert "No point of this scene has a consistency error above 0" in section(pts).texts[-1]


def test_reading_names_iterations_where_an_engine_varies_them():
    sc = "box-stack"
    pts = [sa_point(sc, "cpu", "mesh", False, 960, 0.5), sa_point(sc, "cpu", "mesh", False, 480, 1.0, 1e-3)]
    for it, sp in ((10, 2.0), (20, 1.0)):
        pts += [sa_point(sc, "bullet", "hull", True, 960, sp / 4, iterations=it),
                sa_point(sc, "bullet", "hull", True, 240, sp, 5e-4 * 10 / it, iterations=it)]
    doc = section(pts)
    text = doc.texts[-1]
    assert "bullet (btDbvtBroadphase, hulls, rotation) at dt 1/240 s, 10 iterations (2.00 simulated s" in text, text
    labels = doc.figs[0][1].axes[0].get_legend_handles_labels()[1]
    assert "bullet (btDbvtBroadphase, hulls, rotation), 10 iterations" in labels
    assert "bullet (btDbvtBroadphase, hulls, rotation), 20 iterations" in labels


# ---- references, diverged and skipped -----------------------------------------------------------

def test_references_are_drawn_apart_and_diverged_points_listed():
    doc = section(box_stack())
    name, fig, caption = doc.figs[0]
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    # No point is drawn at error 0 on the log axis; the references sit at the bottom edge in axes
    # coordinates (x data, y axes fraction), each labelled by its dt.
    data_lines = [ln for ln in ax.lines if ln.get_transform() == ax.transData]
    assert all(y > 0 for ln in data_lines for y in ln.get_ydata())
    refs = [ln for ln in ax.lines if ln.get_transform() == ax.get_xaxis_transform() and ln.get_marker() != "None"]
    assert sorted(float(ln.get_xdata()[0]) for ln in refs) == [0.4, 0.5, 1.5]
    assert [t.get_text() for t in ax.texts].count("1/960") == 3
    assert "references (error 0)" in caption
    # Speed spreads as error bars: one per measured point with an error > 0 (9).
    from matplotlib.collections import LineCollection
    bars = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert sum(len(c.get_segments()) for c in bars) == 9
    name, header, rows = next(t for t in doc.tables if t[0] == "speed-accuracy-points")
    assert len(rows) == 13
    err = header.index("consistency error")
    assert sum(r[err] == "0 (reference)" for r in rows) == 3
    name, header, rows = next(t for t in doc.tables if t[0] == "speed-accuracy-lost")
    assert rows == [["diverged", "bullet (btDbvtBroadphase, hulls, rotation)", "1/60\u00a0s", "-",
                     "non-finite state at step 31 (body 4 position)"]]


def test_a_malformed_point_is_refused_naming_file_and_key(tmp_path):
    pts = box_stack()
    del pts[2]["speed"]
    rc, md, page, out = run_main(tmp_path, result(pts))
    assert rc == 2 and "points[2].speed: None; allowed: a spread" in out, out
    pts = box_stack()
    pts[1]["status"] = "exploded"
    rc, md, page, out = run_main(tmp_path, result(pts))
    assert rc == 2 and "points[1].status: 'exploded'; allowed: ok, diverged, skipped, failed" in out, out


def test_odd_speed_ranges_draw_no_bar_instead_of_failing():
    pts = box_stack()
    pts[1]["speed"].update(min=2.0, max=float("inf"))  # min above the median, max not finite
    pts[2]["speed"].update(min=None, max=None)
    assert RSA.speed_bar(pts[1]) == (0.0, 0.0) and RSA.speed_bar(pts[2]) == (0.0, 0.0)
    assert RSA.speed_bar(pts[3]) == pytest.approx((0.04, 0.04))
    assert len(section(pts).figs) == 1


def test_values_a_log_axis_cannot_draw_leave_the_plot_not_the_report(tmp_path):
    pts = box_stack()
    pts[2]["error"]["energy_drift"] = float("nan")  # JSON NaN: Python's json reads it
    pts[3]["error"]["consistency"] = 1e308  # 4x above it overflows
    pts[4]["dt"] = 1e-305  # 1/dt overflows
    pts[6]["speed"].update(min=None)
    pts[7]["speed"].update(median=float("inf"))
    rc, md, page, out = run_main(tmp_path, result(pts))
    assert rc == 0, out
    assert page.count("<svg") == 1 and "| nan |" in md and "| 1e-305\u00a0s |" in md


# ---- the whole report: shards merged, one plot per scene ----------------------------------------

def test_report_has_one_plot_per_measured_scene_and_markdown(tmp_path):
    rc, md, page, out = run_main(tmp_path, result(all_points()))
    assert rc == 0, out
    figures = re.findall(r"<figcaption>([^<]*)</figcaption>", page)
    assert [c.split(":")[0] for c in figures] == ["box-stack", "mixed-pile-1000"]  # rot-drop-220: nothing measured
    assert page.count("<svg") == 2
    assert "Sweep speed-accuracy: speed against accuracy" in page
    for sc in ("box-stack", "mixed-pile-1000", "rot-drop-220"):
        assert f"### {sc}: speed against accuracy" in md
    assert md.count("![box-stack: consistency error against speed") == 1
    assert "| engine | geometry | dt | iterations | speed (sim. s / wall s) |" in md
    assert "At consistency error <= 1e-3, the fastest is cpu (octree, mesh)" in md
    assert "Every point of this scene is unmeasured" in md


def test_two_shards_merge_into_the_report_of_one_run(tmp_path):
    pts = all_points()
    one = result(all_points())
    parts = [result([p for i, p in enumerate(pts) if i % 2 == k], shard=(k, 2)) for k in (0, 1)]
    for part in parts:
        part["points_total"] = len(pts)
    rc, md_one, _, out = run_main(tmp_path / "one", one)
    assert rc == 0, out
    rc, md_two, page, out = run_main(tmp_path / "two", *parts)
    assert rc == 0, out
    strip = lambda md: [ln for ln in md.splitlines() if "Made by" not in ln and "files:" not in ln]
    assert strip(md_one) == strip(md_two)  # the same tables, readings and plots
    assert "files: in0.json, in1.json" in md_two and "Points: 19 of 19 in these files (15 measured)" in md_two
    # A point in both shards is refused, as for every other kind.
    parts[1]["points"].append(parts[0]["points"][0])
    rc, md, page, out = run_main(tmp_path / "dup", *parts)
    assert rc == 2 and "is also in" in out, out


def test_runs_of_other_engines_and_scenes_join_one_section_per_ladder(tmp_path):
    # cpu and cuda from a copy of the sweep without the rotating scene, Bullet from the shipped
    # sweep in shards of its own (other repetitions): one section, every engine's line in the
    # same scene's table and plot, as one run of all of them gives.
    pts = box_stack() + mixed_pile()
    mine = [p for p in pts if p["params"]["engine"] != "bullet"]
    theirs = [p for p in pts if p["params"]["engine"] == "bullet"]
    whole = result(pts)
    ours = result(mine)
    ours["sweep"]["definition"] = {"name": "speed-accuracy", "kind": "speed-accuracy", "engines": ["cpu", "cuda"],
                                   "scenes": ["box-stack", "mixed-pile-1000"]}
    ours["settings"]["engines"] = ["cpu", "cuda"]
    bullet = [result([p for i, p in enumerate(theirs) if i % 2 == k], shard=(k, 2)) for k in (0, 1)]
    for b in bullet:
        b["settings"].update(engines=["bullet"], repeat=2)
        b["sweep"]["definition"] = {"name": "speed-accuracy", "kind": "speed-accuracy",
                                    "engines": ["cpu", "cuda", "bullet"],
                                    "scenes": ["box-stack", "mixed-pile-1000", "rot-drop-220"]}
        b["points_total"] = len(theirs)
    rc, md_whole, _, out = run_main(tmp_path / "whole", whole)
    assert rc == 0, out
    rc, md, page, out = run_main(tmp_path / "runs", ours, *bullet)
    assert rc == 0, out
    assert md.count("Sweep speed-accuracy: speed against accuracy") == 1, md
    assert "engines cpu, cuda: 3 repetitions per point" in md, md  # each run's settings
    assert "engines bullet: 2 repetitions per point" in md, md
    tables = lambda text: [ln for ln in text.splitlines() if ln.startswith("|")]
    assert tables(md) == tables(md_whole)  # the same tables and readings' figures
    assert md.count("speed-accuracy-box-stack") == md_whole.count("speed-accuracy-box-stack")
    # Another ladder of time steps is another comparison: its own section.
    for b in bullet:
        b["settings"]["dts"] = [1 / 60, 1 / 120]
    rc, md, page, out = run_main(tmp_path / "ladders", ours, *bullet)
    assert rc == 0, out
    assert md.count("Sweep speed-accuracy: speed against accuracy") == 2, md
