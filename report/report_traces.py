"""The report's section of traces (report/make_report.py): one row per trace, the traces
overlaid on shared axes, and a sentence on each one's penetration."""

import os

from report_common import CURRENT, np, num, plt
from report_data import read_trace
from report_plots import ENGINE_COLORS, FALLBACK_COLORS, engine_marker


def trace_engine(attrs):
    """The engine of a trace whose `engine` attribute names one of ENGINE_COLORS (its first
    word: "cpu", "rapier 0.21.0"), else None."""
    words = str(attrs.get("engine") or "").split()
    name = words[0].lower() if words else ""
    return name if name in ENGINE_COLORS else None


def trace_colours(traces):
    """One colour per trace file, kept through the traces section: the first file of an engine
    of ENGINE_COLORS takes that engine's colour (as on every other plot of the report); any
    other file (a second run of one engine, an engine the map does not name) the first of
    FALLBACK_COLORS (none an engine's) not yet taken, in file order; beyond them the colours
    repeat."""
    colours, taken = [None] * len(traces), set()
    for k, t in enumerate(traces):
        e = trace_engine(t["attrs"])
        if e and ENGINE_COLORS[e] not in taken:
            colours[k] = ENGINE_COLORS[e]
            taken.add(colours[k])
    free = [c for c in FALLBACK_COLORS if c not in taken]
    for k in range(len(traces)):
        if colours[k] is None:
            colours[k] = free.pop(0) if free else FALLBACK_COLORS[k % len(FALLBACK_COLORS)]
    return colours


def penetration_comment(cols, name="the trace"):
    """One sentence on the penetration of a trace from its /frames columns (penetration_mean,
    penetration_max in m, per frame): the mean over frames, the largest and its frame; the
    last third's largest against the first third's (down by more than half: at most half of
    it; down by less than half: at most 0.9 times it; deeper: above 1.1 times it; else about
    as deep); and whether it settles: in the last third the per-frame largest d_p stays within
    10 % of its top (or 0.01 mm), else it jitters between its min and max there. Frames whose
    figures are not finite are left out; '' when none is left or nothing penetrates."""
    pm, pmax = np.asarray(cols.get("penetration_mean", []), float), np.asarray(cols.get("penetration_max", []), float)
    frame = np.asarray(cols.get("frame", np.arange(len(pmax))), float)
    if len(pm) != len(pmax) or len(frame) != len(pmax):
        return ""
    keep = np.isfinite(pm) & np.isfinite(pmax)  # frames with a figure (a reader gives NaN for a missing one)
    pm, pmax, frame = pm[keep], pmax[keep], frame[keep]
    n = len(pmax)
    if n == 0 or pmax.max() <= 0:
        return ""
    third = max(n // 3, 1)
    first, last = pmax[:third], pmax[n - third:]
    k = int(np.argmax(pmax))
    mm = lambda v: num(1e3 * float(v))
    if last.max() <= 0.5 * first.max():
        trend = "down by more than half"
    elif last.max() <= 0.9 * first.max():
        trend = "down by less than half"
    elif last.max() > 1.1 * first.max():
        trend = "deeper"
    else:
        trend = "about as deep"
    swing = float(last.max() - last.min())
    if swing <= max(0.1 * float(last.max()), 1e-5):
        settle = f"it settles (the per-frame largest d_p stays within {mm(swing)} mm of {mm(last.max())} mm)"
    else:
        settle = (f"it does not settle: the per-frame largest d_p jitters between {mm(last.min())} and "
                  f"{mm(last.max())} mm")
    return (f"{name}: AABB penetration d_p over {n} frames: mean {mm(np.mean(pm))} mm (mean of the per-frame "
            f"means), largest {mm(pmax[k])} mm at frame {int(frame[k])}. In the last third of the run the largest "
            f"is {mm(last.max())} mm against {mm(first.max())} mm in the first third ({trend}), and {settle}.")


def section_traces(doc, paths):
    """One table row per trace, and the traces overlaid on shared axes, each file in its one
    colour of trace_colours (said beside its name in the text and the table)."""
    traces = []
    for path in paths:
        CURRENT[0] = path
        traces.append(read_trace(path))
    doc.h(2, "Traces" if len(traces) > 1 else f"Trace {os.path.basename(paths[0])}")
    colours = trace_colours(traces)
    rows = []
    for t, colour in zip(traces, colours):
        a, n, c = t["attrs"], t["n"], t["cols"]
        e = trace_engine(a)
        drawn = f"drawn in {colour}" + (f" (engine {e}'s colour)" if colour == ENGINE_COLORS.get(e) else "")
        step = c["step_ms"]
        doc.p(f"{os.path.basename(t['path'])}: scene {a.get('scene_name')}, engine {a.get('engine')}, broadphase "
              f"{a.get('broadphase')}, midphase {a.get('midphase')}, {a.get('body_count')} bodies, {n} frames; device "
              f"{a.get('device')}; build {a.get('build_id')}; started {a.get('start_time')}; {drawn}.")
        comment = penetration_comment(c, os.path.basename(t["path"]))
        if comment:
            doc.p(comment)
        rows.append([os.path.basename(t["path"]), colour, n, num(1000.0 * n / step.sum()) if step.sum() > 0 else "-",
                     num(step.mean(), 4) if n else "-", num(c["contacts"].mean()) if n else "-",
                     int(c["contacts"].max()) if n else "-", num(1e3 * c["penetration_max"].max()) if n else "-",
                     num(c["kinetic_energy"][-1]) if n else "-"])
    doc.table(["trace", "colour", "frames", "steps/s", "mean step ms", "mean contacts", "max contacts", "max d_p (mm)",
               "final kinetic energy (J)"], rows, name="traces")
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), sharex=True)
    for t, col in zip(traces, colours):
        c, lab = t["cols"], os.path.basename(t["path"])
        e = trace_engine(t["attrs"])
        # The engine's marker where the file has its colour (a few per line), so it reads
        # without colour too; each line's gid names its file (the tests read it in the SVG).
        mk = dict(marker=engine_marker(e), markevery=max(len(c["frame"]) // 8, 1), markersize=4) \
            if col == ENGINE_COLORS.get(e) else {}
        style = dict(color=col, gid=f"trace:{lab}", **mk)
        axes[0].plot(c["frame"], c["kinetic_energy"], label=lab, **style)
        axes[1].plot(c["frame"], c["contacts"], label=f"{lab} contacts", **style)
        axes[1].plot(c["frame"], c["aabb_pairs"], linestyle=":", label=f"{lab} AABB pairs", **style)
        axes[2].plot(c["frame"], 1e3 * c["penetration_max"], label=f"{lab} max", **style)
        axes[2].plot(c["frame"], 1e3 * c["penetration_mean"], linestyle="--", alpha=0.7, label=f"{lab} mean",
                     **style)
    axes[0].set_title("kinetic energy (J)")
    axes[1].set_title("contacts (solid), AABB pairs (dotted)")
    axes[2].set_title("AABB penetration d_p (mm): max, mean (dashed)")
    for ax in axes:
        ax.set_xlabel("frame")
    handles, labels = axes[2].get_legend_handles_labels()
    h1, l1 = axes[1].get_legend_handles_labels()
    fig.legend(h1 + handles, l1 + labels, fontsize=9, ncol=min(4, 4 * len(traces)), loc="upper center",
               bbox_to_anchor=(0.5, -0.02))
    fig.tight_layout()
    names = "-".join(os.path.splitext(os.path.basename(t["path"]))[0] for t in traces)[:60]
    doc.figure(fig, "trace-" + names, ("Traces overlaid: " if len(traces) > 1 else "") +
               ", ".join(os.path.basename(t["path"]) for t in traces) + ": energy, contacts and penetration over frames")


# ---- performance gate ------------------------------------------------------------------------
#
# The statistic (docs/bench-format.md, "Performance gate"): per point and timing figure, the
# repetitions as times (1 / steps/s, or ms/frame) of both runs. The gate's test is the
# one-sided Mann-Whitney U test (scipy.stats.mannwhitneyu, exact null distribution) of
# H0 "new time <= (1 + P/100) x baseline time" against "new slower than that", at level
# alpha (--level, default 0.05): SLOWER when p < alpha. The ratio shown is the Hodges-Lehmann
# estimate (median of the m x n pairwise ratios new_i / base_j) with its distribution-free
# 1 - 2 alpha interval (the pairwise ratios' order statistics at U's critical value), the
# interval that goes with the test: SLOWER <=> its lower end lies above 1 + P/100 (up to ties).
