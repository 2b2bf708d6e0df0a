"""The report's plots of the scaling, Fig. A2, max-instances and speed-accuracy sections hold
at most MAX_BARS (400) items, as the gate's plots do (issue 57 item 5; report_plots.py,
too_many_to_draw): beyond, the plot is left out with a note and the tables keep every
figure. Before, each drew whatever a result held (10^4 items took matplotlib minutes).
Generated results, no octocd run; run by ctest (`report.readable`)."""
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import test_speed_accuracy as SA  # noqa: E402  (make_report loaded as a module, FakeDoc, sa_point)

MR = SA.MR
RP = sys.modules["report_plots"]
MAX = RP.MAX_BARS


def spread(v):
    return {"median": v, "min": v * 0.99, "max": v * 1.01, "mean": v, "stdev": 0.0, "n": 3,
            "values": [v * 0.99, v, v * 1.01]}


def group(points, settings=None, searches=None):
    return {"points_list": points, "first": {"settings": dict({"engines": ["cpu"]}, **(settings or {})),
                                             "sweep": {"name": "x"}},
            "engines": ["cpu"], "searches": searches or [], "files": ["r.json"]}


def figa2(betas, deltas):
    pts = []
    for b in range(betas):
        for d in range(deltas):
            pts.append({"status": "ok", "params": {"engine": "cpu", "scene": "s",
                                                    "axes": {"beta": str(0.1 + b), "delta": str(0.001 * (d + 1))}},
                        "windows": {"all": {"penetration_mean": spread(1e-3), "penetration_max": spread(2e-3),
                                            "penetration_share_above_slop": spread(0.1), "contacts": spread(10.0),
                                            "steps_per_s": spread(100.0)}}})
    return group(pts)


def scaling(series, sizes):
    pts = [{"status": "ok", "params": {"engine": "cpu", "broadphase": f"bp{k}"}, "bodies": 1000 * 2 ** s,
            "ms_per_frame": spread(1.0 + s + k), "pairs": 10, "frames": 5, "matches_recorded": True}
           for k in range(series) for s in range(sizes)]
    return group(pts)


def max_instances(count):
    pts = [{"status": "ok", "role": "probe", "params": {"scene": "s", "engine": "cpu", "axes": {"instances": i + 1}},
            "windows": {"w": {"steps_per_s": spread(1000.0 / (i + 1))}}} for i in range(count)]
    return group(pts, {"target_steps_per_s": 30, "window": {"first": 1, "last": 2}, "repeat": 3})


def run(section, g):
    MR.plt.close("all")
    doc = SA.FakeDoc()
    section(doc, g)
    return doc


def notes(doc):
    return [t for t in doc.texts if "not drawn" in t]


CASES = [  # (section, generator of g for n items, figure name prefix, what is counted, note title)
    (MR.section_figA2, lambda n: figa2(n, 1), "figA2-", "heat-map cells", "Fig. A2"),
    (MR.section_scaling, lambda n: scaling(n, 1), "scaling", "points", "Broadphase scaling"),
    (MR.section_max_instances, max_instances, "max-instances-probes", "points",
     "max-instances: the probes of the search"),
]


@pytest.mark.parametrize("section,make,figure,what,title", CASES, ids=["figA2", "scaling", "max-instances"])
def test_a_plot_of_more_than_400_items_is_left_out_with_a_note(section, make, figure, what, title):
    small = run(section, make(4))
    assert any(name.startswith(figure) for name, _, _ in small.figs), small.figs
    assert not notes(small)
    big = run(section, make(MAX + 1))
    assert not any(name.startswith(figure) for name, _, _ in big.figs), [n for n, _, _ in big.figs]
    assert notes(big) == [f"{title}: not drawn: {MAX + 1} {what} (a plot holds at most {MAX}); the tables and "
                          "the CSV (--csv) hold every figure."], big.texts
    # The tables keep every figure (a row a point, a row a series); the probes are in the CSV.
    if figure != "max-instances-probes":
        assert max(len(rows) for _, _, rows in big.tables) == MAX + 1


def test_figa2_counts_cells_over_every_engine_and_axis_value():
    doc = run(MR.section_figA2, figa2(21, 20))  # 420 cells, each axis below 400
    assert notes(doc) and "420 heat-map cells" in notes(doc)[0] and not doc.figs


def sa_points(count):
    return [SA.sa_point("box-stack", "cpu", "mesh", False, 960 - k, 1.0 + k, 1e-4 * (k + 1)) for k in range(count)]


def test_speed_accuracy_plots_hold_at_most_400_points():
    small = SA.section(sa_points(4))
    assert [n for n, _, _ in small.figs] == ["speed-accuracy-box-stack"] and not notes(small)
    big = SA.section(sa_points(MAX + 1))
    assert not big.figs
    assert notes(big) == [f"Speed against accuracy: not drawn: {MAX + 1} points (a plot holds at most {MAX}); the "
                          "tables and the CSV (--csv) hold every figure."], big.texts
    assert any(len(rows) == MAX + 1 for _, _, rows in big.tables)
