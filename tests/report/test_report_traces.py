"""The report's traces section (issue 80 item 1): each trace file in one colour through the
section, the engine's colour of report_plots.ENGINE_COLORS for the first file of an engine
(as on every other plot), another colour, none an engine's, for a second file of one engine
or an engine the map does not name; the colour said beside the file in the text and the
table. Four generated traces (no octocd run: report_traces.read_trace is replaced by their
columns). Run by ctest (`report.sections`)."""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import test_report_comparisons as FIX  # noqa: E402

RT = sys.modules["report_traces"]
RP = sys.modules["report_plots"]

# file -> the engine attribute its writer set
TRACES = {"a-cpu.h5": "cpu", "b-bullet.h5": "bullet", "c-cpu.h5": "cpu", "d-rapier.h5": "rapier 0.21.0",
          "e-mine.h5": "my-engine 1.0"}


def fake_trace(path):
    n = 30
    f = np.arange(1, n + 1, dtype=float)
    cols = {"frame": f, "step_ms": np.full(n, 2.0), "kinetic_energy": 1.0 / f, "contacts": np.full(n, 4.0),
            "aabb_pairs": np.full(n, 6.0), "penetration_max": np.full(n, 1e-4),
            "penetration_mean": np.full(n, 5e-5)}
    attrs = {"scene_name": "box-stack", "engine": TRACES[os.path.basename(path)], "broadphase": "octree",
             "midphase": "0,1,2", "body_count": 11, "device": "cpu", "build_id": "test", "start_time": "now"}
    return {"path": path, "n": n, "cols": cols, "attrs": attrs}


def test_each_trace_file_one_colour_from_the_engine_palette(monkeypatch):
    monkeypatch.setattr(RT, "read_trace", fake_trace)
    FIX.MR.plt.close("all")
    doc = FIX.FakeDoc()
    RT.section_traces(doc, [f"/x/{name}" for name in TRACES])
    (_, fig, _), = doc.figs
    by_file = {}
    for ax in fig.axes:
        for line in ax.get_lines():
            name = line.get_label().split()[0]  # "FILE", "FILE contacts", ...
            assert line.get_gid() == f"trace:{name}", (line.get_gid(), name)  # read in the SVG by tests
            by_file.setdefault(name, set()).add(line.get_color().lower())
    # Every file on the figure, five lines each (energy, contacts, pairs, max, mean), one colour.
    assert sorted(by_file) == sorted(TRACES)
    assert all(len(c) == 1 for c in by_file.values()), by_file
    colour = {name: next(iter(c)) for name, c in by_file.items()}
    engines = {e.lower() for e in RP.ENGINE_COLORS.values()}
    assert colour["a-cpu.h5"] == RP.ENGINE_COLORS["cpu"].lower()
    assert colour["b-bullet.h5"] == RP.ENGINE_COLORS["bullet"].lower()
    assert colour["d-rapier.h5"] == RP.ENGINE_COLORS["rapier"].lower()
    # The second cpu file and the unnamed engine: colours of their own, none an engine's.
    for name in ("c-cpu.h5", "e-mine.h5"):
        assert colour[name] not in engines, (name, colour)
    assert len(set(colour.values())) == len(TRACES), colour
    # A file with its engine's colour also has the engine's marker (told apart without colour).
    for ax in fig.axes:
        for line in ax.get_lines():
            name = line.get_label().split()[0]
            want = RP.ENGINE_MARKERS[name.split("-")[1].split(".")[0]] if name in ("a-cpu.h5", "b-bullet.h5",
                                                                                     "d-rapier.h5") else "None"
            assert line.get_marker() == want, (name, line.get_marker())
    # The colour is said beside each file: its paragraph and its table row.
    (header, rows), = doc.tables
    k = header.index("colour")
    for row in rows:
        assert row[k].lower() == colour[row[0]], (row, colour)
    for name in TRACES:
        text = next(t for t in doc.texts if t.startswith(name + ":"))
        assert f"drawn in {colour[name]}".lower() in text.lower(), text
    assert "engine cpu's colour" in next(t for t in doc.texts if t.startswith("a-cpu.h5:"))
    assert "engine cpu's colour" not in next(t for t in doc.texts if t.startswith("c-cpu.h5:"))
