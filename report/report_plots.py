"""The report's plots (report/make_report.py): steps/s bars per scene and configuration
(log axis, the paper's figures on their own axis, speed-ups printed) and stage shares, with
the labels of points and engines."""

import re
import textwrap
import zlib

from report_common import STAGES, STAGE_COLORS, med, np, num, plt

MAX_BARS = 400  # bars a plot draws at most (10,000 took matplotlib 100 s); beyond, the tables hold the figures


# The one engine -> colour map of every plot and page of the report: the Okabe-Ito palette
# (colour-blind safe: Okabe & Ito, "Color Universal Design", 2008), one colour per built-in or
# shipped engine. Other engines (a user's process engine) take engine_colour's fallback.
ENGINE_COLORS = {"cpu": "#0072B2", "cuda": "#009E73", "bullet": "#D55E00", "mujoco": "#E69F00",
                 "ode": "#56B4E9", "dart": "#CC79A7", "rapier": "#F0E442", "jolt": "#000000"}
# Paul Tol's "muted" palette (colour-blind safe, none of them an ENGINE_COLORS colour) for
# engines the map above does not name.
FALLBACK_COLORS = ["#332288", "#88CCEE", "#44AA99", "#117733", "#999933", "#DDCC77", "#CC6677", "#882255",
                   "#AA4499", "#DDDDDD"]


# One marker per engine beside its colour (lines and points), so an engine is told apart
# without colour too; other engines take FALLBACK_MARKERS by the same CRC-32.
ENGINE_MARKERS = {"cpu": "o", "cuda": "s", "bullet": "^", "mujoco": "D", "ode": "v", "dart": "P", "rapier": "X",
                  "jolt": "*"}
FALLBACK_MARKERS = ["h", "p", "<", ">", "d", "8", "H"]  # filled, none of ENGINE_MARKERS

# What the `contacts` figure of a point counts on each engine (docs/engines.md, each
# engine's "contacts" row): counts of different things, never compared across engines.
CONTACTS_COUNTED = {
    "cpu": "octocd contacts: pairs the response resolves (one per body pair)",
    "cuda": "octocd contacts: pairs the response resolves (one per body pair)",
    "bullet": "Bullet manifold points (up to 4 per body pair)",
    "mujoco": "MuJoCo contacts (ncon; several per geom pair with multi-point collision)",
    "ode": "ODE contact joints (up to `contacts` per pair, default 8)",
    "dart": "DART's FCL contacts (up to 4 per box pair, one per touching triangle pair of a hull)",
    "rapier": "Rapier solver contacts of its manifolds",
    "jolt": "Jolt contact points of its manifolds",
}


def contacts_counted(engine, process=False):
    """What engine's `contacts` figure counts (CONTACTS_COUNTED), for a column's note."""
    name = str(engine)
    if name in CONTACTS_COUNTED:
        return CONTACTS_COUNTED[name]
    return "the engine's own contact count (a process engine)" if process else "the engine's own contact count"


def is_process_point(p):
    """Whether point p ran on an engine that times no stage of the pipeline (every has_stage
    false: a process engine, which reports its whole step only, and 0 AABB pairs)."""
    hs = p.get("has_stage")
    return isinstance(hs, dict) and bool(hs) and not any(hs.values())


def engine_marker(engine):
    """The marker of `engine` on every plot (ENGINE_MARKERS, else FALLBACK_MARKERS by CRC-32)."""
    name = str(engine)
    if name in ENGINE_MARKERS:
        return ENGINE_MARKERS[name]
    return FALLBACK_MARKERS[zlib.crc32(name.encode("utf-8")) % len(FALLBACK_MARKERS)]


def note_engine(fig, engine, why=None):
    """Records on `fig` that `engine` is on it (drawn in engine_colour) or, with `why`, why it
    is not; report_html.Doc.figure writes the record into the SVG's metadata (dc:description,
    "octocd-engines {json}"), which tests read to check that no engine is missing and no
    colour moves between plots."""
    rec = fig.__dict__.setdefault("octocd_engines", {})
    name = str(engine)
    if why is None:
        rec[name] = {"colour": engine_colour(name), "marker": engine_marker(name)}
    elif name not in rec:
        rec[name] = {"colour": engine_colour(name), "marker": engine_marker(name), "not_drawn": str(why)}


def unmeasured_engines(all_points, drawn):
    """{engine: why} for the engines of `all_points` (a sweep's points) with no point among
    `drawn`: the first skipped or failed point's reason, else "not measured"."""
    have = {p.get("params", {}).get("engine") for p in drawn}
    out = {}
    for p in all_points or []:
        e = p.get("params", {}).get("engine")
        if e is None or e in have:
            continue
        if e not in out or (out[e] == "not measured" and p.get("reason")):
            st = p.get("status", "?")
            out[e] = f"{st}: {str(p.get('reason', ''))[:120]}" if p.get("reason") else (
                "not measured" if st == "ok" else st)
    return out


def engine_colour(engine):
    """The colour of `engine` on every plot: ENGINE_COLORS's, else a FALLBACK_COLORS entry
    chosen by the CRC-32 of the name (the same name gets the same colour on every run, plot and
    page; two unknown engines can share one, 1 chance in 10)."""
    name = str(engine)
    if name in ENGINE_COLORS:
        return ENGINE_COLORS[name]
    return FALLBACK_COLORS[zlib.crc32(name.encode("utf-8")) % len(FALLBACK_COLORS)]


def wrap_label(text, width=16):
    """A category label wrapped onto lines of at most `width` characters, broken after '-',
    '_' or ' ' where it can ("bunny-stack-50" / "asian-dragon-random-60")."""
    text = str(text)
    if len(text) <= width:
        return text
    parts = re.split(r"(?<=[-_ ])", text)
    lines, cur = [], ""
    for part in parts:
        if cur and len(cur) + len(part) > width:
            lines.append(cur)
            cur = ""
        cur += part
    lines.append(cur)
    return "\n".join(textwrap.fill(line, width) if len(line) > width else line for line in lines)


def tick_label_overlaps(fig, ax, axis="x"):
    """Pairs (i, j) of the axis' drawn tick labels (visible, inside the view limits) whose boxes
    overlap (window extents from the figure's renderer)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    labels = ax.get_xticklabels() if axis == "x" else ax.get_yticklabels()
    lo, hi = sorted(ax.get_xlim() if axis == "x" else ax.get_ylim())
    boxes = [t.get_window_extent(renderer) for t in labels if t.get_visible() and t.get_text()
             and lo <= t.get_position()[0 if axis == "x" else 1] <= hi]  # ticks outside the view are not drawn
    return [(i, j) for i in range(len(boxes)) for j in range(i + 1, len(boxes)) if boxes[i].overlaps(boxes[j])]


def readable_xticks(fig, ax, labels, fontsize=8):
    """Category labels on ax's x axis that never overlap: wrapped (wrap_label) and level, else
    on one line turned 90 degrees, then drawn smaller, until tick_label_overlaps finds none.
    (Slanted labels are not tried: their boxes, axis-aligned, overlap where the text does not.)"""
    ax.set_xticks(np.arange(len(labels)))
    ax.set_xticklabels([wrap_label(x) for x in labels], rotation=0, ha="center", fontsize=fontsize)
    for size in (fontsize, 6, 4):
        if not tick_label_overlaps(fig, ax):
            return
        ax.set_xticklabels([str(x) for x in labels], rotation=90, ha="center", fontsize=size)


def legend_below_ticks(fig, ax, **kw):
    """ax's legend centred under its x tick labels (wherever their wrapping or turning left
    them), never over them."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    lo, hi = sorted(ax.get_xlim())
    boxes = [t.get_window_extent(renderer) for t in ax.get_xticklabels()
             if t.get_visible() and t.get_text() and lo <= t.get_position()[0] <= hi]
    low = min([b.y0 for b in boxes] + [ax.get_window_extent(renderer).y0])
    y = ax.transAxes.inverted().transform((0, low))[1]
    return ax.legend(loc="upper center", bbox_to_anchor=(0.5, y - 0.02), **kw)


def too_many_to_draw(doc, title, count, what="bars"):
    """True, with a note in the report, when a plot would draw more than MAX_BARS items
    (bars, points, cells): it is left out and the section's tables hold every figure, as for
    the gate's plots (report_gate.py); matplotlib would spend minutes on 10^4 of them."""
    if count <= MAX_BARS:
        return False
    doc.p(f"{title}: not drawn: {count} {what} (a plot holds at most {MAX_BARS}); the tables and the CSV (--csv) "
          "hold every figure.", "note")
    return True


def steps_points(g):
    return [p for p in g["points_list"] if p.get("status") == "ok" and "windows" in p]


def axis_label(p, axis):
    lab = p.get("params", {}).get("labels", {}).get(axis)
    val = p.get("params", {}).get("axes", {}).get(axis)
    return lab if lab is not None else str(val)


# The engine registry's own broadphases (engines/src/engines.cpp: EngineInfo::own_broadphase
# -> own_broadphase_class; process engines' too, docs/bring-your-engine.md) as `octocd
# engines --json --no-checks` gives them (`octocd report` passes its own binary as --octocd),
# for results whose points record only `engine_broadphase`: read once, when a point first
# asks (a report of traces alone never runs octocd for it).
REGISTRY_BROADPHASE_CLASS = {}
REGISTRY_SOURCE = [None, False]  # [the octocd binary to ask, asked already]


def broadphase_class(eb, default):
    """The class name of the own broadphase `eb`: the registry's, else `default`."""
    if REGISTRY_SOURCE[0] and not REGISTRY_SOURCE[1]:
        REGISTRY_SOURCE[1] = True
        read_registry_broadphases(REGISTRY_SOURCE[0])
    return REGISTRY_BROADPHASE_CLASS.get(eb, default)


def read_registry_broadphases(octocd):
    """Fills REGISTRY_BROADPHASE_CLASS from `octocd engines --json --no-checks` (the registry's
    facts; no process engine's runtime is started); left empty (an engine's own broadphase is
    then named as its points record it, e.g. bullet-dbvt) when octocd cannot be run or answers
    otherwise."""
    import json
    import subprocess
    try:
        out = subprocess.run([octocd, "engines", "--json", "--no-checks"], capture_output=True, text=True,
                             timeout=300).stdout
        for e in json.loads(out).get("engines", []):
            if isinstance(e, dict) and e.get("own_broadphase") and e.get("own_broadphase_class"):
                REGISTRY_BROADPHASE_CLASS[str(e["own_broadphase"])] = str(e["own_broadphase_class"])
    except (OSError, ValueError, subprocess.SubprocessError):
        pass


def point_label(p, axis):
    """What point p ran on `axis`: the axis label, or for an axis its engine ignores what the
    engine ran instead (its own broadphase by the registry's class name, "no midphase")."""
    ignores = p.get("ignores")
    if axis and isinstance(ignores, dict) and axis in ignores:
        if axis == "broadphase":
            eb = p.get("engine_broadphase") or ""
            return broadphase_class(eb, eb or "own broadphase")
        if axis == "midphase":
            return "no midphase"
    return axis_label(p, axis) if axis else ""


def engines_of(g):
    """The engines of a group's runs (report_data.merge), in the sweep's order."""
    return g.get("engines") or g["first"]["settings"].get("engines", [])


def first_window(p):
    return next(iter(p["windows"].values()))


HATCHES = ["", "///", "...", "xxx", "\\\\\\", "ooo", "+++"]


def log_ticks(ax, axis="y"):
    """Readable log ticks: 1, 2, 5 per decade, written as plain numbers (200, 1,000, 0.05)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    a = ax.yaxis if axis == "y" else ax.xaxis
    a.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    def text(v, _):
        if v <= 0:
            return ""
        if v >= 1e6:
            return f"{v / 1e6:g}M"
        if v >= 1e4:
            return f"{v / 1e3:g}k"
        return f"{v:,.0f}" if v >= 1 else f"{v:g}"
    a.set_major_formatter(FuncFormatter(text))
    a.set_minor_formatter(NullFormatter())


def steps_bars(doc, pts, group_axis, title, name, xkey=lambda p: p["params"]["scene"], paper=None, all_points=None):
    """steps/s bars per scene (or xkey): one colour per engine, a hatch per group_axis value,
    the engine's name over each bar and, after an engine's first value of group_axis, its
    speed-up over that one ("bullet 1.8x"); `paper` {(scene, label): FPS} draws the paper's
    figures (FPS of a whole Unity application) in a panel of their own beside ours, never on
    our steps/s axis. An engine of `all_points` (the sweep's points) with no bar is named in
    the legend with why (skipped, failed)."""
    scenes = list(dict.fromkeys(xkey(p) for p in pts))
    vals = list(dict.fromkeys(point_label(p, group_axis) for p in pts))
    engines = list(dict.fromkeys(p["params"]["engine"] for p in pts))
    combos = [(v, e) for e in engines for v in vals
              if any(p["params"]["engine"] == e and point_label(p, group_axis) == v for p in pts)]
    if not scenes or not combos:
        return
    if len(scenes) * len(combos) > MAX_BARS:
        doc.p(f"{title}: not drawn: {len(scenes) * len(combos)} bars (a plot holds at most {MAX_BARS}); the table "
              "and the CSV (--csv) hold every figure.", "note")
        return
    fpts = {}  # (scene, engine) -> {value: steps/s spread}
    for p in pts:
        fpts.setdefault((xkey(p), p["params"]["engine"]), {})[point_label(p, group_axis)] = \
            first_window(p)["steps_per_s"]
    width_in = min(11, max(6, 1.4 * len(scenes) + 0.22 * len(combos) * len(scenes)))
    paper_vals = sorted({v for (sc, v) in paper if sc in scenes},
                        key=lambda v: vals.index(v) if v in vals else len(vals)) if paper else []
    if paper_vals:
        fig, (ax, pax) = plt.subplots(1, 2, figsize=(min(14, width_in + 4), 4.2),
                                      gridspec_kw={"width_ratios": [max(width_in, 1), 4]})
    else:
        fig, ax = plt.subplots(figsize=(width_in, 4.2))
    width = 0.8 / len(combos)
    for k, (val, eng) in enumerate(combos):
        ys, lo, hi = [], [], []
        for sc in scenes:
            s = fpts.get((sc, eng), {}).get(val)
            ys.append(s["median"] if s else np.nan)
            lo.append(s["median"] - s["min"] if s else 0)
            hi.append(s["max"] - s["median"] if s else 0)
        xs = np.arange(len(scenes)) + (k - (len(combos) - 1) / 2) * width
        colour = engine_colour(eng)
        shade = 1.0 - 0.35 * (vals.index(val) / max(len(vals) - 1, 1))  # lighter for later values
        ax.bar(xs, ys, width, yerr=[lo, hi], capsize=2, label=f"{eng} {val}".strip(), color=colour, alpha=shade,
               hatch=HATCHES[vals.index(val) % len(HATCHES)], edgecolor="#222", linewidth=0.6, gid=f"engine:{eng}")
        note_engine(fig, eng)
        # The engine's name over each bar, with its speed-up over its first value on this axis.
        for i, sc in enumerate(scenes):
            mine = fpts.get((sc, eng), {})
            if val not in mine:
                continue
            ref_val = next((v for v in vals if v in mine), None)
            text = str(eng) if len(str(eng)) <= 24 else str(eng)[:23] + "…"  # the legend has it whole
            if ref_val is not None and ref_val != val and med(mine[ref_val]) and med(mine[val]):
                text += " " + speedup_text(med(mine[val]) / med(mine[ref_val]))
            ax.annotate(text, (xs[i], mine[val]["max"]), xytext=(0, 2), textcoords="offset points", ha="center",
                        va="bottom", fontsize=7.5, rotation=90)
    ax.set_yscale("log")
    log_ticks(ax)
    lo_y, hi_y = ax.get_ylim()
    ax.set_ylim(lo_y, hi_y * 8)  # room for the names over the bars (log axis: about one decade)
    missing = unmeasured_engines(all_points, pts)
    for eng, why in missing.items():
        note_engine(fig, eng, why)
        ax.bar([np.nan], [np.nan], 0, color=engine_colour(eng), edgecolor="#222", linewidth=0.6,
               label=f"{eng}: no bar ({why[:60]})")
    ax.set_ylabel("steps/s of each engine's step (median, bars min–max; log scale)")
    ax.set_title("each bar: the named engine's steps/s" +
                 (f" (Nx: speed-up over the engine's first {group_axis})" if group_axis else ""), fontsize=9)
    fig.suptitle(title, fontsize=10)
    readable_xticks(fig, ax, scenes)
    if paper_vals:
        pw = 0.8 / len(paper_vals)
        for k, val in enumerate(paper_vals):
            ys = [paper.get((sc, val), np.nan) for sc in scenes]
            xs = np.arange(len(scenes)) + (k - (len(paper_vals) - 1) / 2) * pw
            pax.bar(xs, ys, pw, color="#bbb", edgecolor="#222", linewidth=0.6,
                    hatch=HATCHES[(vals.index(val) if val in vals else k) % len(HATCHES)], label=f"paper {val}")
            for x, y in zip(xs, ys):
                if not np.isnan(y):
                    pax.annotate(f"{y:g}", (x, y), xytext=(0, 2), textcoords="offset points", ha="center",
                                 va="bottom", fontsize=6, rotation=90)
        readable_xticks(fig, pax, scenes, fontsize=7)
        pax.margins(y=0.2)
        pax.set_ylabel("paper FPS (Unity, whole application)")
        pax.set_title("the paper's FPS (its own axis)", fontsize=9)
        legend_below_ticks(fig, pax, fontsize=8, ncol=len(paper_vals))
    legend_below_ticks(fig, ax, fontsize=9, ncol=min(len(combos) + len(missing), 4))
    doc.figure(fig, name, title + ("; the paper's FPS in the right-hand panel, on its own axis" if paper_vals else ""))


def speedup_text(r):
    """A speed-up as printed on plots and in tables: 1.84x, 0.52x."""
    return f"{num(r)}x"


def stage_shares(doc, pts, group_axis, title, name, all_points=None):
    """Per point the share of each stage in the step (bars, %) with the stage's time in ms printed
    in its segment and the step's total ms at the bar's end; the same as a table (ms and %).
    Every point is a row: a stage the engine does not time is "not timed", and an engine that
    times none (a process engine) has its row saying so with its whole step's ms."""
    rows = list(pts)
    if not rows:
        return
    labels, shares, times, notes = [], [], [], []
    drawn = len(rows) <= MAX_BARS
    for p in rows:
        w = first_window(p)
        hs = p.get("has_stage") if isinstance(p.get("has_stage"), dict) else {}
        # A stage the engine does not time counts 0 (whatever figure the point holds for it).
        st = [0.0 if hs.get(s) is False else med(w.get("stage_ms", {}).get(s, {})) or 0.0 for s in STAGES]
        tot = sum(st) or 1.0
        shares.append([100.0 * x / tot for x in st])
        times.append(st)
        notes.append("no stage times: the engine times its whole step only" if is_process_point(p) else
                     [s for s in STAGES if hs.get(s) is False])
        labels.append(f"{p['params']['scene']} {point_label(p, group_axis)} {p['params']['engine']}".strip())
    if not drawn:
        doc.p(f"{title}: not drawn: {len(rows)} bars (a plot holds at most {MAX_BARS}); the table below holds every "
              "figure.", "note")
    else:
        stage_bars(doc, rows, labels, shares, times, notes, title, name, all_points)
    table = []
    for p, lab, ts, shs, nt in zip(rows, labels, times, shares, notes):
        if isinstance(nt, str):
            step = med(first_window(p).get("step_ms", {}))
            table.append([lab] + [f"- ({nt})" if k == 0 else "-" for k in range(len(STAGES))]
                         + [num(step, 3) + " (whole step)" if step is not None else "-"])
            continue
        table.append([lab] + [("- (not timed)" if s in nt else f"{num(t, 3)} ({num(sh, 2)}%)")
                              for s, t, sh in zip(STAGES, ts, shs)] + [num(sum(ts), 3)])
    for eng, why in unmeasured_engines(all_points, rows).items():
        table.append([f"{eng}: not measured ({why[:100]})"] + ["-"] * (len(STAGES) + 1))
    doc.table(["point"] + [f"{s} ms (%)" for s in STAGES] + ["sum ms"], table,
              "Median ms per frame of each stage over the repetitions, its share of their sum in brackets; "
              "'- (not timed)': the engine does not time that stage apart (its time is in another stage's); a "
              "process engine times its whole step only.", name=name)


def stage_bars(doc, rows, labels, shares, times, notes, title, name, all_points=None):
    """stage_shares' plot: a bar per point, a segment per stage, the engine's marker in its
    colour before each bar; a point without stage times says so on its row."""
    fig, ax = plt.subplots(figsize=(9, 0.3 * len(rows) + 1.4))
    left = np.zeros(len(rows))
    arr = np.array(shares)
    for k, s in enumerate(STAGES):
        ax.barh(np.arange(len(rows)), arr[:, k], left=left, color=STAGE_COLORS[k], label=s)
        for i in range(len(rows)):
            if arr[i, k] >= 9.0:  # room for the figure inside the segment
                ax.text(left[i] + arr[i, k] / 2, i, num(times[i][k], 2), ha="center", va="center", fontsize=7.5,
                        color="black")
        left += arr[:, k]
    for i, p in enumerate(rows):
        eng = p["params"]["engine"]
        note_engine(fig, eng)
        ax.scatter([-2.5], [i], marker=engine_marker(eng), color=engine_colour(eng), edgecolors="#222",
                   linewidths=0.5, s=30, clip_on=False, zorder=5, gid=f"engine:{eng}")
        if isinstance(notes[i], str):
            step = med(first_window(p).get("step_ms", {}))
            ax.text(1, i, f"{eng}: {notes[i]}" + (f" ({num(step, 3)} ms)" if step is not None else ""),
                    ha="left", va="center", fontsize=7.5, color="#333")
        else:
            ax.text(101, i, f"{num(sum(times[i]), 3)} ms", ha="left", va="center", fontsize=7.5)
    for eng, why in unmeasured_engines(all_points, rows).items():
        note_engine(fig, eng, why)
    ax.set_yticks(np.arange(len(rows)))
    ax.set_yticklabels(labels, fontsize=8)
    ax.tick_params(axis="y", pad=12)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("share of the step (%); in the segments: the stage's median ms per frame; right: the step's ms")
    ax.set_title(title)
    ax.legend(fontsize=9, ncol=6, loc="upper center", bbox_to_anchor=(0.5, -0.12 - 1.0 / max(len(rows), 4)))
    doc.figure(fig, name, title + " (ms per frame printed in each segment and at the bar's end; the marker before "
               "each bar: its engine)")
