"""The report's plots stay readable with six engines (issue 69 item 6): one colour per engine,
the same on every plot (report_plots.ENGINE_COLORS, engine_colour), category labels whose
drawn boxes never overlap (matplotlib's Agg renderer, each tick label's window extent), log
axes labelled. A generated small-scenes result of six engines, no octocd run; run by ctest
(`report.readable`)."""
import itertools
import os
import sys

import matplotlib.colors as mcolors

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import test_report_comparisons as FIX  # noqa: E402  (make_report as a module, point, result, FakeDoc)

MR = FIX.MR
RP = sys.modules["report_plots"]

SIX = ["cpu", "cuda", "bullet", "mujoco", "ode", "dart"]
SMALL_SCENES = ["bunny-stack-50", "asian-dragon-random-60", "armadillo-random-250", "dragon-random-250",
                "bunny-random-400", "mixed-pile-1000", "obstacle-mixed-50", "rods-150", "sizes-50x-214"]


def small_scenes(engines=SIX, scenes=SMALL_SCENES):
    """`bench small-scenes --engines ...` as a generated result: one point per scene and engine."""
    pts = [FIX.point(i, sc, eng, "midphase", "0,1,2", "C", 1000.0 * (1 + k) * (1 + 0.1 * s))
           for i, ((s, sc), (k, eng)) in enumerate(itertools.product(enumerate(scenes), enumerate(engines)))]
    j = FIX.result("small-scenes", pts)
    j["settings"]["engines"] = list(engines)
    j["sweep"]["definition"]["engines"] = list(engines)
    return j


def bar_colours(ax):
    """label -> the set of face colours (RGB) of the bars of that legend entry."""
    out = {}
    for cont in ax.containers:
        label = cont.get_label()
        patches = getattr(cont, "patches", None)
        if not patches:
            continue
        out.setdefault(label, set()).update(mcolors.to_hex(p.get_facecolor()[:3]) for p in patches)
    return out


def drawn(ax, t):
    """A tick label matplotlib draws: visible, with text, its tick inside the view limits."""
    if not (t.get_visible() and t.get_text()):
        return False
    x, y = t.get_position()
    lo, hi = sorted(ax.get_xlim() if t in ax.get_xticklabels() else ax.get_ylim())
    v = x if t in ax.get_xticklabels() else y
    return lo - 1e-9 * abs(hi - lo) <= v <= hi + 1e-9 * abs(hi - lo)


def overlapping_ticks(fig):
    """(axes index, label a, label b) for every pair of drawn tick labels whose boxes overlap,
    (axes index, label, "legend") for a label under a legend."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    bad = []
    legends = [(ax.get_legend(), ax.get_legend().get_window_extent(renderer)) for ax in fig.axes if ax.get_legend()]
    for n, ax in enumerate(fig.axes):
        for labels in (ax.get_xticklabels(), ax.get_yticklabels()):
            shown = [t for t in labels if drawn(ax, t)]
            boxes = [t.get_window_extent(renderer) for t in shown]
            for i, j in itertools.combinations(range(len(boxes)), 2):
                if boxes[i].overlaps(boxes[j]):
                    bad.append((n, shown[i].get_text(), shown[j].get_text()))
            for t, b in zip(shown, boxes):  # a legend drawn over a label hides it as well
                bad += [(n, t.get_text(), "legend") for _, lb in legends if lb.overlaps(b)]
    return bad


def steps_figure(j):
    doc = FIX.section(MR.section_generic, j)
    figs = [f for name, f, _ in doc.figs if name == "sweep-steps"]
    assert len(figs) == 1
    return figs[0]


def test_six_engines_six_distinct_colours():
    fig = steps_figure(small_scenes())
    ax = fig.axes[0]
    cols = bar_colours(ax)
    per_engine = {label.split()[0]: c for label, c in cols.items()}
    assert sorted(per_engine) == sorted(SIX)
    for eng, c in per_engine.items():
        assert len(c) == 1, (eng, c)  # one colour per engine over all scenes
    colours = [next(iter(c)) for c in per_engine.values()]
    assert len(set(colours)) == 6, per_engine
    # The map's colours, the same ones a plot of any other section takes.
    for eng, c in per_engine.items():
        assert next(iter(c)) == mcolors.to_hex(RP.ENGINE_COLORS[eng]).lower()


def test_engine_map_covers_the_shipped_engines_and_is_distinct():
    named = ["cpu", "cuda", "bullet", "mujoco", "ode", "dart", "rapier", "jolt"]
    assert all(e in RP.ENGINE_COLORS for e in named)
    cols = [mcolors.to_hex(RP.engine_colour(e)) for e in named]
    assert len(set(cols)) == len(named)
    # An unknown engine (a user's process engine): the same colour on every call, none of the map's.
    a = RP.engine_colour("my-process-engine")
    assert a == RP.engine_colour("my-process-engine")
    assert a not in RP.ENGINE_COLORS.values()
    assert mcolors.is_color_like(a)


def test_unknown_engine_bars_take_the_fallback_colour():
    fig = steps_figure(small_scenes(engines=["cpu", "my-process-engine"]))
    cols = {label.split()[0]: c for label, c in bar_colours(fig.axes[0]).items()}
    assert cols["my-process-engine"] == {mcolors.to_hex(RP.engine_colour("my-process-engine"))}
    assert cols["cpu"] != cols["my-process-engine"]


def test_scene_labels_never_overlap_with_six_engines():
    fig = steps_figure(small_scenes())
    assert overlapping_ticks(fig) == []
    shown = [t.get_text().replace("\n", "") for t in fig.axes[0].get_xticklabels()]
    assert shown == SMALL_SCENES  # every scene named, in order (wrapped lines joined)


def test_many_long_labels_never_overlap():
    scenes = [f"a-rather-long-scene-name-number-{k}" for k in range(30)]
    fig = steps_figure(small_scenes(engines=["cpu", "bullet"], scenes=scenes))
    assert overlapping_ticks(fig) == []


def test_the_checker_sees_overlap():
    """The overlap check itself fails on labels drawn on top of each other (as before)."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.set_xticks(range(len(SMALL_SCENES)))
    ax.set_xticklabels(SMALL_SCENES, rotation=0)
    assert overlapping_ticks(fig)
    assert RP.tick_label_overlaps(fig, ax)
    plt.close(fig)


def test_paper_panel_labels_never_overlap():
    """Table 5's plot with the paper's FPS in a panel of its own: neither panel's labels overlap."""
    doc = FIX.section(MR.section_table5, FIX.table5())
    figs = [f for name, f, _ in doc.figs if len(f.axes) == 2]
    assert figs
    for fig in figs:
        assert overlapping_ticks(fig) == []


def test_log_axes_are_labelled():
    fig = steps_figure(small_scenes())
    for ax in fig.axes:
        if ax.get_yscale() == "log":
            assert "log" in ax.get_ylabel() and "steps/s" in ax.get_ylabel()
        if ax.get_xscale() == "log":
            assert "log" in ax.get_xlabel()


def test_wrap_label_breaks_at_dashes():
    assert RP.wrap_label("asian-dragon-random-60") == "asian-dragon-\nrandom-60"
    assert RP.wrap_label("rods-150") == "rods-150"
    assert all(len(x) <= 16 for x in RP.wrap_label("x" * 40).split("\n"))


def test_log_axes_of_the_other_sections_are_labelled():
    """Broadphase scaling, max-instances and Table 5's plots: every log axis says so."""
    import test_report_plot_caps as CAPS
    docs = [CAPS.run(MR.section_scaling, CAPS.scaling(2, 3)), CAPS.run(MR.section_max_instances, CAPS.max_instances(6)),
            FIX.section(MR.section_table5, FIX.table5())]
    seen = 0
    for doc in docs:
        for _, fig, _ in doc.figs:
            for ax in fig.axes:
                for scale, label in ((ax.get_xscale(), ax.get_xlabel()), (ax.get_yscale(), ax.get_ylabel())):
                    if scale == "log":
                        seen += 1
                        assert "log" in label, label
    assert seen >= 5
