#!/usr/bin/env python3
"""octocd report: bench results (octocd-bench JSON) and traces (octocd-trace HDF5) into
OUT/index.html (self-contained: every plot inline as SVG, no network) and OUT/report.md
(plots as OUT/plots/*.svg). Run by `octocd report` (cli/report.cpp); usable directly:

    /usr/bin/python3 report/make_report.py -o OUT RESULT.json [TRACE.h5 ...]

Shards of one sweep (same sweep definition, machine and build) are merged. Performance
gate: `--baseline BASE.json [--threshold P] [--level A]` sets NEW beside BASE per point and
decides on the repetitions with a one-sided Mann-Whitney U test (docs/bench-format.md,
"Performance gate"). `--csv DIR` writes the data as CSV (per point and repetition, plus a
summary row). Exit codes: 0 ok, 2 bad input (a file of another format or version, duplicate
points, shards of different builds, a baseline of another sweep or machine, a forged
summary, too few repetitions to decide, a trace the hardened reader refuses, an output
folder that is a file, a device, a link or read-only: one line, never a traceback), 4 the
gate failed (a point slower, or a baseline point missing, failed or unmeasured in the new
run), 1 anything else (a full disk: the earlier report in OUT is left as it was).

Traces are untrusted input: their numbers come from `octocd trace-summary --json` (octocd's
hardened trace reader, `--octocd PATH` or the `octocd` on PATH), never from h5py here.
Every output file is written to a temporary file beside it and renamed into place once
all of them are written, so a failed run never truncates an earlier report.
Needs Debian's python3-matplotlib and python3-numpy.

This file is the entry point (`octocd report` runs it; installed under share/octocd/report
with the modules beside it): the command line, the sweep sections by name (SECTIONS) and the
exit codes. The parts are modules beside it: report_common.py (the one-line error, numbers,
load marks), report_data.py (results and trace summaries in), report_html.py (the document,
HTML and Markdown, written atomically), report_plots.py, report_tables.py (the sweep
sections), report_traces.py, report_gate.py (the performance gate), report_csv.py and
report_history.py (`--history DIR`: a history folder of nightly runs over commits on one
page, with change points and the verdicts over time; docs/regression.md).
"""
import argparse
import datetime
import errno
import html
import math
import os
import shutil
import sys
import types

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # the report_*.py modules beside this file

# The report's parts (tests reach them through this module too).
from report_common import CURRENT, NOISE_NOTE, OCTOCD, PAPER, fail, load_warning, np, plt  # noqa: E402,F401
from report_data import LOADED, check_points, load, merge, read_trace  # noqa: E402,F401
from report_html import Doc, output_dir  # noqa: E402
from report_plots import REGISTRY_SOURCE, read_registry_broadphases  # noqa: E402,F401
from report_csv import file_slug, sweep_csv  # noqa: E402
from report_gate import GATE_MIN_REPS, LEVEL_RANGE, gate_summary, reps_needed, section_gate  # noqa: E402
import report_speed_accuracy as RSA  # noqa: E402  (sweeps of kind speed-accuracy, design.md section 15)
import report_divergence as RDV  # noqa: E402  (sweeps of kind divergence, design.md section 20)
from report_common import Stopped, load_mark, num, on_sigterm, overlap, printable, spread_text  # noqa: E402
from report_plots import log_ticks, speedup_text, too_many_to_draw  # noqa: E402
from report_traces import penetration_comment, section_traces  # noqa: E402,F401
from report_tables import (engines_ran_text, machine_block, section_figA2, section_generic,  # noqa: E402,F401
                           section_max_instances, section_scaling, section_table5, section_table6,
                           section_tableA1, skipped_block)


def section_speed_accuracy(doc, g):
    """Per scene error against speed, the Pareto front and a reading (report/report_speed_accuracy.py)."""
    RSA.section(doc, g, types.SimpleNamespace(num=num, spread_text=spread_text, log_ticks=log_ticks, overlap=overlap,
                                              speedup_text=speedup_text, load_mark=load_mark,
                                              too_many_to_draw=too_many_to_draw))


SECTIONS = {"table5": ("Table 5: midphase configurations A, B, C", section_table5),
            "table6": ("Table 6: Level 0 (AABB only) vs hierarchical C", section_table6),
            "tableA1": ("Table A1: spatial hash vs octree, early and late phases", section_tableA1),
            "figA2": ("Fig. A2: penetration for beta x delta", section_figA2),
            "broadphase-scaling": ("Broadphase scaling", section_scaling),
            "max-instances": ("Most instances at 30 steps/s (paper section 5.3)", section_max_instances)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--title", default=None)
    ap.add_argument("--baseline", action="append", default=[], help="baseline result file(s) (shards merged)")
    ap.add_argument("--threshold", type=float, default=10.0, help="slowdown in %% that fails the gate")
    ap.add_argument("--level", type=float, default=0.05, help="the gate's significance level")
    ap.add_argument("--across-machines", action="store_true", help="gate runs of two machines")
    ap.add_argument("--timing", choices=["auto", "cpu", "wall"], default="auto",
                    help="the gate's figure: steps per process CPU second (cpu), wall-clock steps/s (wall), or cpu "
                         "where both runs have it (auto)")
    ap.add_argument("--csv", help="write the data as CSV into this folder")
    ap.add_argument("--octocd", default=shutil.which("octocd"),
                    help="the octocd binary whose `trace-summary` reads traces (default: octocd on PATH)")
    ap.add_argument("--history", help="draw this history folder (report/report_history.py, docs/regression.md)")
    ap.add_argument("--change-level", type=float, default=0.05,
                    help="--history: the change-point test's family-wise level per machine")
    ap.add_argument("inputs", nargs="*")
    a = ap.parse_args()
    OCTOCD[0] = a.octocd
    if a.history:
        if a.inputs or a.baseline:
            fail(f"--history {a.history}: with inputs or --baseline; allowed: --history DIR alone")
        if not (1e-9 <= a.change_level <= 0.5):
            fail(f"--change-level: {a.change_level}; allowed: a level in [1e-9, 0.5]")
        if not os.path.isdir(a.history):
            fail(f"--history {a.history}: not a folder; allowed: a history folder (docs/regression.md)")
        output_dir(a.output, "-o")
        if a.csv:
            output_dir(a.csv, "--csv")
        import report_history
        report_history.run(a.history, a.output, a.change_level, a.title, csv_dir=a.csv, timing=a.timing)
        return
    if not a.inputs:
        fail("no inputs; allowed: result files of octocd bench (.json) and traces (.h5), or --history DIR")
    a.title = a.title or "octocd benchmark report"
    OCTOCD[0] = a.octocd
    REGISTRY_SOURCE[:] = [a.octocd, False]  # the registry's own broadphases, read when a point asks
    LOADED.clear()  # each file read and checked once per report
    output_dir(a.output, "-o")
    if a.csv:
        output_dir(a.csv, "--csv")
    if not (0 <= a.threshold < 1000) or math.isnan(a.threshold):
        fail(f"--threshold: {a.threshold}; allowed: a percentage in [0, 1000)")
    if not (LEVEL_RANGE[0] <= a.level <= LEVEL_RANGE[1]):
        fail(f"--level: {a.level}; allowed: a significance level in [{LEVEL_RANGE[0]:g}, {LEVEL_RANGE[1]:g}] (and "
             "one the repetitions can reach: 0.00397 or above with 5 a side)")
    loaded = []
    for p in a.inputs:
        CURRENT[0] = p
        loaded.append(load(p))
    results = [(x[1], x[2]) for x in loaded if x[0] == "result"]
    traces = [x[1] for x in loaded if x[0] == "trace"]
    for p in a.baseline + [x[0] for x in results]:
        CURRENT[0] = p
        check_points(p, dict(results).get(p) or load(p)[2])
    # What a malformed result found later is blamed on (run()): the one input, or all of them.
    CURRENT[0] = a.inputs[0] if len(a.inputs) == 1 else "one of " + ", ".join(a.inputs)
    gate = None
    doc = None
    if a.baseline:
        base_loaded = []
        for p in a.baseline:
            x = load(p)
            if x[0] != "result":
                fail(f"{p}: --baseline: an HDF5 trace; allowed: a result of octocd bench (.json)")
            base_loaded.append((x[1], x[2]))
        bg, ng = merge(base_loaded, pool=True), merge(results, pool=True)
        if len(bg) != 1 or len(ng) != 1:
            fail(f"--baseline: {len(bg)} sweep(s) or machine(s) in the baseline, {len(ng)} in the new results; "
                 "allowed: one sweep (its shards) of one machine on each side")
        doc = Doc(a.output, a.csv)
        gate = section_gate(doc, bg[0], ng[0], a.threshold, a.level, a.across_machines, a.timing)
        if gate["few"] and not gate["broken"]:
            pid, label, nb, nn, least = gate["few"][0]
            more = f" (and {len(gate['few']) - 1} more figure(s))" if len(gate["few"]) > 1 else ""
            if least is None:
                fail(f"too few repetitions to decide: '{pid}' {label} has {nb} in the baseline and {nn} in the new run"
                     + more + f"; allowed: >= {GATE_MIN_REPS} repetitions a side (octocd bench --repeat "
                     f"{GATE_MIN_REPS})")
            k = reps_needed(a.level)
            fail(f"too few repetitions for --level {a.level:g}: '{pid}' {label} has {nb} in the baseline and {nn} in "
                 f"the new run, whose smallest one-sided Mann-Whitney U p is {least:.3g} (every new time above every "
                 f"baseline time), not below the level: no slowdown could be shown{more}; allowed: >= {k} repetitions "
                 f"a side at this level (octocd bench --repeat {k}), or --level above {least:.3g}")
        if gate["frames"] and not gate["broken"]:
            pid, spans = gate["frames"][0]
            more = f" (and {len(gate['frames']) - 1} more point(s))" if len(gate["frames"]) > 1 else ""
            fail(f"no verdict: '{pid}' was timed over other frames in its runs ({spans}){more}: the time budget cut "
                 "them differently, and steps/s over other frames do not compare; allowed: runs that timed the same "
                 "frames (octocd bench --protocol paper, or a --max-time that cuts neither)")
        if gate["broken"]:
            # A failed new run: its sections are not drawn (their figures are what failed).
            results = []
            traces = []
    groups = merge(results, pool=bool(a.baseline))  # the gate pools runs; the sections show the first
    order = list(SECTIONS)
    groups.sort(key=lambda g: (order.index(g["first"]["sweep"]["name"]) if g["first"]["sweep"]["name"] in order
                               else len(order), g["first"]["sweep"]["name"]))
    doc = doc or Doc(a.output, a.csv)
    doc.p(f"Made by octocd report on {datetime.datetime.utcnow().strftime('%Y-%m-%d %H:%M UTC')} from "
          f"{len(results)} result file(s) and {len(traces)} trace(s). {NOISE_NOTE}", "note")
    nav = []
    for i, g in enumerate(groups):
        name = g["first"]["sweep"]["name"]
        title, fn = SECTIONS.get(name, (f"Sweep {name}", section_generic))
        if g["first"]["sweep"].get("kind") == "broadphase" and name not in SECTIONS:
            title, fn = (f"Sweep {name}: broadphase replay", section_scaling)
        if g["first"]["sweep"].get("kind") == "max-instances" and name not in SECTIONS:
            title, fn = (f"Sweep {name}: most instances at the target steps/s", section_max_instances)
        if g["first"]["sweep"].get("kind") == RSA.KIND:  # its own table of unmeasured points per scene
            title, fn = (f"Sweep {name}: speed against accuracy", section_speed_accuracy)
        if g["first"]["sweep"].get("kind") == RDV.KIND:  # its own table of unmeasured points
            title, fn = (f"Sweep {name}: divergence of perturbed copies", lambda d, gg: RDV.section(d, gg, None))
        nav.append((f"s{i}", title))
        doc.section = name
        CURRENT[0] = ", ".join(g["files"])
        doc.h(2, title, f"s{i}")
        machine_block(doc, g)
        fn(doc, g)
        if g["first"]["sweep"].get("kind") not in (RSA.KIND, RDV.KIND):
            skipped_block(doc, g)
        if doc.csv_dir and g["first"]["sweep"].get("kind") == RDV.KIND:
            doc.files.put(os.path.join(doc.csv_dir, file_slug(name) + ".csv"), RDV.write_csv(None, g))
            doc.ncsv += 1
        elif doc.csv_dir:
            sweep_csv(doc, os.path.join(doc.csv_dir, file_slug(name) + ".csv"), g)
            doc.ncsv += 1
    if traces:
        doc.section = "trace"
        section_traces(doc, traces)
    if a.baseline:
        nav.insert(0, ("gate", "Performance gate"))
    if nav:
        doc.html.insert(0 if a.baseline else 1, "<nav>" + "".join(f'<a href="#{k}">{html.escape(t)}</a>' for k, t in nav) + "</nav>")
    doc.write(a.title)
    print(f"octocd report: wrote {os.path.join(a.output, 'index.html')} and {os.path.join(a.output, 'report.md')} "
          f"({doc.nplot} plots" + (f", {doc.ncsv} CSV file(s) in {a.csv}" if a.csv else "") + ")")
    if gate is not None:
        gate_summary(gate, a.threshold, a.level)
        if gate["broken"] or gate["slower"]:
            sys.exit(4)

def run():
    """main() as `octocd report` runs it: every failure one line and an exit code (0, 1, 2, 4,
    130 for SIGINT, 143 for SIGTERM), never a traceback (scripts/fuzz_report_json.py fuzzes
    it so)."""
    import signal
    signal.signal(signal.SIGTERM, on_sigterm)
    try:
        main()
    except SystemExit:
        raise
    except (KeyboardInterrupt, Stopped) as e:  # SIGINT or SIGTERM: nothing was committed
        sig = "SIGTERM" if isinstance(e, Stopped) else "SIGINT"
        print(f"octocd report: stopped by {sig}; the earlier report (if any) is left as it was", file=sys.stderr)
        sys.exit(143 if isinstance(e, Stopped) else 130)
    except OSError as e:
        # Writing the report: a full disk or a size limit is a runtime failure (exit 1), a
        # path it may not write bad input (exit 2); the earlier report is left as it was.
        where = e.filename or "the output"
        code = errno.errorcode.get(e.errno, str(e.errno))
        if e.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO):
            print(f"octocd report: runtime failure: {where}: {code}: {e.strerror}; the earlier report (if any) is "
                  "left as it was", file=sys.stderr)
            sys.exit(1)
        fail(f"{where}: {code}: {e.strerror}; allowed: an output folder octocd may write in")
    except MemoryError:
        print("octocd report: runtime failure: out of memory; the earlier report (if any) is left as it was",
              file=sys.stderr)
        sys.exit(1)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, ZeroDivisionError, OverflowError,
            RecursionError) as e:
        # A result that passed the checks of report_data.py but holds something else where a
        # figure should be (the checks name the field; this names the file).
        fail(f"{CURRENT[0]}: malformed result ({type(e).__name__}: {e}); allowed: a result of octocd bench as "
             "docs/bench-format.md describes it")
    except Exception as e:  # noqa: BLE001  (never a traceback: one line, exit 1)
        print(f"octocd report: runtime failure: {type(e).__name__}: {printable(e)}; the earlier report (if any) is "
              "left as it was", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    run()
