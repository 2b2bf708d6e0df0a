"""Every engine on every plot in its one colour (issue 80 items 1, 2 and 8; issue 79 item 5):
a seven-engine small-scenes report (cuda skipped, dart timing two stages, rapier and jolt
process engines timing none) and a divergence report with a skipped engine, generated
(no octocd run) and reported by make_report.py. Read back from the SVG files the report
writes: each plot's record of its engines (dc:description "octocd-engines {json}",
report_plots.note_engine) names every engine of the sweep, drawn or with why not, and the
elements drawn for an engine (id "engine:NAME") are filled or stroked in
report_plots.ENGINE_COLORS's colour, the same on every plot. Names holding `$...$` (mathtext
syntax) give a page. Run by ctest (`report.engines`)."""
import json
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import test_report_comparisons as FIX  # noqa: E402
from test_report_readable import SIX, small_scenes  # noqa: E402

RP = sys.modules["report_plots"]
SEVEN = ["cpu", "cuda", "bullet", "mujoco", "ode", "dart", "rapier", "jolt"]  # cuda skipped: seven ran
REPORT = os.path.join(FIX.SRC, "report", "make_report.py")
SVG = "{http://www.w3.org/2000/svg}"


def seven_engines():
    """`bench small-scenes --engines cpu,cuda,bullet,mujoco,ode,dart,rapier,jolt` on a CPU-only
    build: cuda skipped; dart times response and metrics; rapier and jolt (process engines)
    time no stage."""
    j = small_scenes(engines=SEVEN)
    for p in j["points"]:
        e = p["params"]["engine"]
        p["has_stage"] = {s: e not in ("rapier", "jolt") and (e != "dart" or s in ("response", "metrics"))
                          for s in FIX.STAGE_MS}
        if e == "cuda":
            p["status"], p["reason"] = "skipped", "this octocd was built without CUDA (OCTOCD_CUDA=OFF)"
            del p["windows"]
    return j


def divergence(skipped="dart"):
    """A divergence sweep of two scenes, cpu, bullet and ode measured, `skipped` skipped."""
    pts = []
    for sc in ("box-stack", "mixed-pile-1000"):
        for e in ("cpu", "bullet", "ode", skipped):
            for eps in (1e-6, 1e-4):
                p = {"id": f"{sc} | eps={eps} | {e}", "index": len(pts), "status": "ok", "eps_m": eps,
                     "params": {"scene": sc, "engine": e, "axes": {}}}
                if e == skipped:
                    p.update(status="skipped", reason=f"engine {e} refuses the scene (testing)")
                else:
                    grow = 1.0 + 0.05 * (1 + SEVEN.index(e))
                    mean = [eps * grow ** f for f in range(41)]
                    p.update(dt=0.01, copies=4, mean_m=mean, max_m=[2 * x for x in mean], exponent_per_s=4.0)
                pts.append(p)
    j = FIX.result("divergence", pts)
    j["sweep"]["kind"] = "divergence"
    j["settings"]["engines"] = ["cpu", "bullet", "ode", skipped]
    return j


def report(tmp_path, j, name="in.json"):
    path = tmp_path / name
    path.write_text(json.dumps(j))
    out = tmp_path / "rep"
    r = subprocess.run([sys.executable, REPORT, "-o", str(out), str(path)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    return out


def plot_engines(svg_path):
    """(record, drawn): the plot's record of its engines (dc:description) and, per engine, the
    set of fill and stroke colours of the elements drawn for it (id engine:NAME)."""
    root = ET.parse(svg_path).getroot()
    desc = [d.text for d in root.iter("{http://purl.org/dc/elements/1.1/}description")]
    record = json.loads(desc[0].split(" ", 1)[1]) if desc and desc[0].startswith("octocd-engines ") else {}
    drawn = {}
    for g in root.iter(SVG + "g"):
        gid = g.get("id", "")
        if not gid.startswith("engine:"):
            continue
        for el in g.iter():
            style = el.get("style", "")
            for key in ("fill", "stroke"):
                m = re.search(rf"(?:^|;)\s*{key}:\s*(#[0-9a-fA-F]{{6}})", style)
                if m:
                    drawn.setdefault(gid[len("engine:"):], set()).add((key, m.group(1).lower()))
                elif key == "fill" and el.tag == SVG + "path" and not re.search(r"(?:^|;)\s*fill:", style):
                    drawn.setdefault(gid[len("engine:"):], set()).add((key, "#000000"))  # SVG's default fill
    return record, drawn


def check_plots(out, engines, skipped=()):
    """Every plot of the report names every engine, in ENGINE_COLORS's colour; `skipped` ones
    with why not; the elements drawn for an engine are in its colour. Returns the plots."""
    plots = sorted(os.listdir(out / "plots"))
    assert plots
    for name in plots:
        # Every text is plain: no mathtext source shown raw (a log axis's own labels are mathtext).
        assert "mathdefault" not in (out / "plots" / name).read_text(), name
        record, drawn = plot_engines(out / "plots" / name)
        assert sorted(record) == sorted(engines), (name, record)
        for e, rec in record.items():
            assert rec["colour"].lower() == RP.ENGINE_COLORS[e].lower(), (name, e, rec)
            assert rec["marker"] == RP.ENGINE_MARKERS[e], (name, e, rec)
            if e in skipped:
                assert rec.get("not_drawn"), (name, e, rec)
                assert e not in drawn, (name, e)
            else:
                assert "not_drawn" not in rec, (name, e, rec)
                colours = {c for _, c in drawn.get(e, set())}
                assert RP.ENGINE_COLORS[e].lower() in colours, (name, e, drawn.get(e))
                # No other engine's colour on its elements (the bars' dark edges are no engine's).
                others = {RP.ENGINE_COLORS[o].lower() for o in RP.ENGINE_COLORS if o != e} - {"#000000"}
                assert not colours & others, (name, e, colours)
    return plots


def test_seven_engines_every_plot_every_engine_one_colour(tmp_path):
    out = report(tmp_path, seven_engines())
    plots = check_plots(out, SEVEN, skipped=("cuda",))
    assert [p.split("-", 1)[1] for p in plots] == ["sweep-steps.svg", "sweep-stages.svg"]
    md = (out / "report.md").read_text()
    # The header says what each engine ran, with figures; the skipped one with its reason.
    ran = next(line for line in md.splitlines() if "Engines ran:" in line)
    for e in SEVEN:
        assert re.search(rf"\b{e}: \d+ of 9 point\(s\) measured", ran), (e, ran)
    assert "cuda: 0 of 9 point(s) measured, 9 skipped (this octocd was built without CUDA" in ran
    assert re.search(r"jolt: 9 of 9 point\(s\) measured, [\d,]+–[\d,]+ steps/s", ran), ran
    # The stage table has a row for every engine that ran: the process engines say why no shares.
    stage_rows = [line for line in md.splitlines() if line.startswith("| bunny-stack-50 C ")]
    assert sorted(r.split("|")[1].split()[-1] for r in stage_rows) == sorted(e for e in SEVEN if e != "cuda")
    assert any("rapier" in r and "no stage times" in r for r in stage_rows), stage_rows
    assert any("dart" in r and "not timed" in r for r in stage_rows), stage_rows
    assert "cuda: not measured (skipped" in md
    # The contacts column says what each engine counts; a process engine's pairs are not reported.
    assert "contacts (each engine's own count)" in md and "Bullet manifold points" in md
    assert "rapier: Rapier solver contacts" in md
    assert "| bunny-stack-50 \\| midphase=0,1,2 \\| jolt | all |" in md
    jolt_row = next(line for line in md.splitlines() if line.startswith("| bunny-stack-50 \\| midphase=0,1,2 \\| jolt"))
    assert "- (not reported)" in jolt_row
    # The y axis is each engine's steps/s, not "octocd steps/s".
    steps_svg = (out / "plots" / plots[0]).read_text()
    assert "octocd steps/s" not in steps_svg and "steps/s of each engine" in steps_svg


def test_a_skipped_engine_moves_no_colour(tmp_path):
    """cpu skipped: bullet keeps its own colour (it took cpu's blue when colours went by order)."""
    j = seven_engines()
    for p in j["points"]:
        if p["params"]["engine"] == "cpu":
            p["status"], p["reason"] = "skipped", "testing"
            p.pop("windows", None)
    check_plots(report(tmp_path, j), SEVEN, skipped=("cpu", "cuda"))


def test_divergence_with_a_skipped_engine(tmp_path):
    out = report(tmp_path, divergence("dart"))
    plots = check_plots(out, ["cpu", "bullet", "ode", "dart"], skipped=("dart",))
    assert len(plots) == 2
    for name in plots:  # the engine's name at the end of its line, the skipped one in the legend with why
        text = (out / "plots" / name).read_text()
        assert ">bullet<" in text.replace(" ", "") or "bullet" in text
        assert "dart: no line (skipped: engine dart refuses the scene" in text
    md = (out / "report.md").read_text()
    # No timing notes on a sweep of distances.
    assert "repetition per point" not in md and "under load" not in md


def test_notes_only_where_they_apply(tmp_path):
    """'1 repetition' only when a point had one; its verdict clause only where the section takes
    verdicts; the load note only when a point ran under load."""
    j = small_scenes(engines=["cpu", "bullet"])
    j["machine"].update(load_average=[0.1] * 3, load_average_end=[0.1] * 3)  # an idle machine
    md = (report(tmp_path, j) / "report.md").read_text()
    assert "repetition per point" not in md and "under load" not in md and "Load at the run" not in md
    j["settings"]["repeat"] = 1
    md = (report(tmp_path, j, "one.json") / "report.md").read_text()
    assert "1 repetition per point: the figures have no spread." in md and "no verdict" not in md
    j["machine"].update(load_average=[3.0] * 3, load_average_end=[3.0] * 3)  # 3 busy cores of 16, 16 threads
    md = (report(tmp_path, j, "loaded.json") / "report.md").read_text()
    assert "measured points ran under load" in md


def test_mathtext_in_names_is_plain_text(tmp_path):
    """A `$...$` in a scene, engine or sweep name (malformed mathtext: matplotlib used to raise
    and no page was written) is drawn as it is written."""
    j = small_scenes(engines=["cpu", "$x^$"], scenes=["$\\frac{1}{$", "a$b$c"])
    j["sweep"]["name"] = "$\\sqrt{$"
    out = report(tmp_path, j)
    svg = "".join((out / "plots" / n).read_text() for n in os.listdir(out / "plots"))
    assert "$\\frac{1}{$" in svg and "a$b$c" in svg and "$x^$" in svg


def test_the_svg_check_sees_a_moved_colour(tmp_path):
    """The check itself fails on a plot whose engine is drawn in another engine's colour."""
    out = report(tmp_path, small_scenes(engines=["cpu", "bullet"]))
    name = sorted(os.listdir(out / "plots"))[0]
    path = out / "plots" / name
    text = path.read_text()
    path.write_text(text.replace(RP.ENGINE_COLORS["bullet"].lower(), RP.ENGINE_COLORS["cpu"].lower()))
    try:
        check_plots(out, ["cpu", "bullet"])
    except AssertionError:
        return
    raise AssertionError("a moved colour passed the check")


def test_an_engine_without_a_figure_has_a_cell_saying_why():
    """Table 5 with cuda skipped on every point: its cells say why, never a bare '-'."""
    j = FIX.table5()
    for p in j["points"]:
        if p["params"]["engine"] == "cuda":
            p["status"], p["reason"] = "skipped", "this octocd was built without CUDA"
            p.pop("windows", None)
    doc = FIX.section(FIX.MR.section_table5, j)
    header, rows = doc.tables[0]
    col = header.index("cuda steps/s")
    start = next(i for i, r in enumerate(rows) if r[0].startswith("bunny-random-400"))
    mine = rows[start:start + 3]  # configurations A, B, C of a scene the result has
    assert all(r[col] == "- (skipped: this octocd was built without CUDA)" for r in mine), mine
    assert any(r[col] == "- (not in these files)" for r in rows)  # a scene of the paper's table it lacks
    header, rows = doc.tables[1]
    col = header.index("cuda: fastest (speed vs A)")
    assert next(r for r in rows if r[0] == "bunny-random-400")[col].startswith("- (skipped: "), rows


def test_speed_accuracy_lines_take_their_engines_colour(tmp_path):
    """The speed-accuracy plots draw each engine's lines in its colour (they went by line order)."""
    import test_speed_accuracy as SA
    out = report(tmp_path, SA.result(SA.all_points()))
    plots = sorted(os.listdir(out / "plots"))
    assert plots
    seen = set()
    for name in plots:
        record, drawn = plot_engines(out / "plots" / name)
        assert record, name
        for e, rec in record.items():
            assert rec["colour"].lower() == RP.engine_colour(e).lower(), (name, e, rec)
        for e, cols in drawn.items():
            strokes = {c for k, c in cols if k == "stroke"}
            assert strokes == {RP.engine_colour(e).lower()}, (name, e, cols)
            seen.add(e)
    assert seen == {"cpu", "cuda", "bullet"}, seen
