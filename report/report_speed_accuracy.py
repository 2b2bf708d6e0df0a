"""The report's speed-accuracy section (design.md section 15; after Erez, Tassa and Todorov, "Simulation
tools for model-based robotics", ICRA 2015): results of `octocd bench` sweeps of kind
`speed-accuracy` (docs/bench-format.md), per scene

- a log-log plot of consistency error (y) against speed (x, simulated seconds per wall
  second), one line per `line` (scene, engine, geometry, rotation, iterations), its points
  labelled by dt, the speed's min-max over the repetitions as error bars, the Pareto front
  over all engines (the lowest error reached at each speed) as a staircase, the points of
  error 0 (each line's reference, its smallest dt) at the bottom edge apart from the log axis;
- a reading generated from the data (which engine is fastest under an error threshold, and by
  how much, at the thresholds that separate the engines);
- a table of every point and one of the points not measured (diverged, skipped, failed) with
  their reasons.

Called by make_report.py (`section(doc, g, h)`, `check_point(where, p, fail)`): `doc` is the
report's Doc (p, h, table, figure: HTML and Markdown at once), `g` a merged sweep (shards of
one sweep merged by make_report.merge), `h` the report's shared helpers (num, spread_text,
log_ticks, speedup_text, overlap, load_mark, too_many_to_draw) as attributes.
"""
import math

from report_common import is_number, np, plt
from report_plots import engine_colour, note_engine

KIND = "speed-accuracy"
STATUSES = ("ok", "diverged", "skipped", "failed")
GEOMETRY_MARKERS = {"mesh": "o", "hull": "s", "box": "^"}
MAX_THRESHOLDS = 4  # sentences of the reading per scene, at most

INTRO = ("Every engine runs each scene over a ladder of time steps (and Bullet's solver iterations), the same "
         "simulated time each. Speed: simulated seconds per wall second (median over the repetitions, bars "
         "min–max). Consistency error: the RMS position difference against the same line's smallest dt at matched "
         "times, over a body's size; it says how much a coarser step changes an engine's own answer, not how far "
         "that answer is from the truth, so read it beside the physics figures (largest penetration, energy "
         "drift, momentum-balance residual). Each line's smallest dt is its reference (error 0 by construction): "
         "a log axis cannot draw 0, so references are drawn apart at the bottom edge and left out of the Pareto "
         "front. The front (black staircase, ringed points) is, over all engines, the lowest error reached at each "
         "speed or faster. The reading names, at thresholds X on the error, the fastest engine with a point under "
         "X and its speed-up over the next engine's best point under X; X runs over 1, 2 and 5 times the powers of "
         "ten between the scene's smallest and largest nonzero errors, and a threshold is named where the fastest engine, or the "
         "set of engines reaching it, changes from the next stricter one (at most four: the strictest reached, the "
         "first that every engine reaches, then those where the fastest engine changes).")


# ---- input -------------------------------------------------------------------------------------

def check_point(where, p, fail):
    """The fields this section reads, checked on one point of a speed-accuracy result once
    report_data.check_points checked its status (one of STATUSES) and params: one line naming
    the file, point and key through `fail` (exit 2)."""
    for key in ("line", "engine_label", "geometry", "reason"):
        if key in p and not isinstance(p[key], str):
            fail(f"{where}.{key}: {p[key]!r}; allowed: a string")
    if "dt" in p and not (is_number(p["dt"]) and math.isfinite(p["dt"]) and p["dt"] > 0):
        fail(f"{where}.dt: {p['dt']!r}; allowed: a time step in seconds > 0")
    if p.get("iterations") is not None and not (isinstance(p["iterations"], int) and not isinstance(
            p["iterations"], bool)):
        fail(f"{where}.iterations: {p['iterations']!r}; allowed: an integer or null")
    if p["status"] != "ok":
        return
    for key in ("line", "engine_label", "dt"):
        if key not in p:
            fail(f"{where}.{key}: missing; allowed: a measured speed-accuracy point (docs/bench-format.md)")
    s = p.get("speed")
    if not isinstance(s, dict) or not isinstance(s.get("n"), int) or not all(
            s.get(k) is None or is_number(s.get(k)) for k in ("median", "min", "max")):
        fail(f"{where}.speed: {str(s)[:60]}; allowed: a spread {{median, min, max, n, ...}} of simulated s per wall s")
    e = p.get("error")
    if not isinstance(e, dict):
        fail(f"{where}.error: {str(e)[:60]}; allowed: an object {{consistency, reference_dt, max_penetration_m, "
             "energy_drift, momentum_residual}}")
    for key in ("consistency", "reference_dt", "max_penetration_m", "energy_drift", "momentum_residual"):
        if e.get(key) is not None and not is_number(e[key]):
            fail(f"{where}.error.{key}: {e[key]!r}; allowed: a number or null")
    if e.get("consistency") is not None and e["consistency"] < 0:
        fail(f"{where}.error.consistency: {e['consistency']!r}; allowed: an error >= 0")


# ---- the figures of a point --------------------------------------------------------------------

def drawable(v):
    """Whether v can sit on a log axis (and 4x it, a tenth of it): finite in [1e-300, 1e300]."""
    return is_number(v) and 1e-300 <= v <= 1e300


def speed(p):
    """Median simulated seconds per wall second, or None where not measured or not drawable."""
    s = p.get("speed") if p.get("status") == "ok" else None
    v = s.get("median") if isinstance(s, dict) else None
    return float(v) if drawable(v) else None


def error(p):
    """The consistency error (0 or drawable), or None where not measured or out of range."""
    e = p.get("error") if p.get("status") == "ok" else None
    v = e.get("consistency") if isinstance(e, dict) else None
    return float(v) if is_number(v) and (v == 0 or drawable(v)) else None


def dt_of(p):
    dt = p.get("dt")
    if not is_number(dt):
        try:
            dt = float(p.get("params", {}).get("axes", {}).get("dt"))
        except (TypeError, ValueError):
            return None
    return float(dt)


def dt_text(dt, unit=True):
    """A time step as the ladder names it: '1/240 s' where 1/dt is within 0.2 % of an integer
    (a stored 0.004166 is 1/240), else '0.003 s'."""
    if dt is None or not drawable(dt):
        return "-" if dt is None else f"{dt:g}" + (" s" if unit else "")
    n = round(1.0 / dt)
    text = f"1/{n}" if n >= 1 and abs(1.0 / dt - n) <= 2e-3 * n else f"{dt:g}"
    return text + (" s" if unit else "")


def sci(v):
    """An error as 4.2e-4 (0 as 0)."""
    if v is None:
        return "-"
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    m, e = f"{v:.1e}".split("e")
    return f"{float(m):g}e{int(e)}"


def label(p):
    """What ran: the bench's engine label (engine, broadphase, geometry, rotation)."""
    return p.get("engine_label") or p.get("params", {}).get("engine", "?")


def varies_iterations(pts):
    """{engine label: whether its points run more than one number of solver iterations}."""
    seen = {}
    for p in pts:
        seen.setdefault(label(p), set()).add(p.get("iterations"))
    return {k: len(v) > 1 for k, v in seen.items()}


def speed_bar(p):
    """(median - min, max - median) of p's speed, each >= 0; 0 (no bar) where min or max is
    not drawable."""
    s, m = p["speed"], speed(p)
    lo, hi = s.get("min"), s.get("max")
    return (max(m - lo, 0.0) if drawable(lo) else 0.0, max(hi - m, 0.0) if drawable(hi) else 0.0)


def speed_range(p):
    """p's speed as a spread for make_report's overlap(): n, and min and max from speed_bar."""
    lo, hi = speed_bar(p)
    n = p["speed"].get("n")
    return {"n": n if isinstance(n, int) else 1, "min": speed(p) - lo, "max": speed(p) + hi}


def is_reference(p):
    """Whether p is its line's reference: its dt is the reference dt, or its error is 0."""
    e, dt = p.get("error") or {}, dt_of(p)
    ref = e.get("reference_dt") if isinstance(e, dict) else None
    if is_number(ref) and dt is not None and abs(ref - dt) <= 1e-9 * max(ref, dt):
        return True
    return error(p) == 0.0


def pareto_front(pts):
    """The points no other point beats: none is at least as fast with an error at most as
    large (one of them strictly). Only points with a speed and an error > 0 count (error 0
    is a reference's by construction). Sorted by speed, slowest first: along the front the
    error rises with the speed."""
    cand = [p for p in pts if speed(p) is not None and error(p) is not None and error(p) > 0]
    cand.sort(key=lambda p: (-speed(p), error(p)))
    front, best = [], math.inf
    for p in cand:  # fastest first: a point is on the front when it beats every faster point's error
        if error(p) < best:
            front.append(p)
            best = error(p)
    return front[::-1]


# ---- the reading ---------------------------------------------------------------------------------

def best_under(pts, x):
    """{engine label: its fastest point with an error > 0 and <= x}."""
    best = {}
    for p in pts:
        e, s = error(p), speed(p)
        if e is None or s is None or e == 0 or e > x:
            continue
        k = label(p)
        if k not in best or s > speed(best[k]):
            best[k] = p
    return best


def thresholds(pts):
    """[(X, {label: best point}, labels fastest first)] at the thresholds that separate the
    engines: X over 1, 2 and 5 times the powers of ten from the one at or below the smallest
    error > 0 to the one above the largest; an X is kept where the fastest engine under it, or the set of
    engines with a point under it, differs from the previous kept one. At most MAX_THRESHOLDS,
    by priority: the strictest, the first that every engine reaches, those where the fastest
    engine changes, the loosest."""
    errs = [error(p) for p in pts if error(p) and speed(p) is not None]
    if not errs:
        return []
    lo, hi = math.floor(math.log10(min(errs)) + 1e-9), math.ceil(math.log10(max(errs)) - 1e-9)
    out, prev = [], None
    for x in [float(f"{m}e{k}") for k in range(lo, hi + 1) for m in (1, 2, 5)]:
        best = best_under(pts, x)
        if not best:
            continue
        order = sorted(best, key=lambda n: -speed(best[n]))
        sig = (order[0], frozenset(best))
        if sig != prev:
            out.append((x, best, order))
            prev = sig
    if len(out) > MAX_THRESHOLDS:  # by priority: strictest, first reached by all, fastest changes, loosest
        every = frozenset(label(p) for p in pts if error(p) and speed(p) is not None)
        changes = [t for a, t in zip(out, out[1:]) if t[2][0] != a[2][0]]
        keep = []
        for t in [out[0]] + [t for t in out if frozenset(t[1]) == every][:1] + changes + [out[-1]]:
            if t not in keep:
                keep.append(t)
        out = sorted(keep[:MAX_THRESHOLDS], key=lambda t: t[0])
    return out


def point_text(p, vary, h):
    it = p.get("iterations")
    return (f"dt {dt_text(dt_of(p))}" + (f", {it} iterations" if vary.get(label(p)) and it is not None else "")
            + f" ({h.num(speed(p))} simulated s per wall s, error {sci(error(p))})")


def names(xs):
    xs = list(xs)
    return xs[0] if len(xs) == 1 else ", ".join(xs[:-1]) + " and " + xs[-1]


def front_text(pts):
    """Which engines the Pareto front holds, in a sentence."""
    front = pareto_front(pts)
    held = {}
    for p in front:
        held[label(p)] = held.get(label(p), 0) + 1
    parts = [f"{n} of {e}" for e, n in sorted(held.items(), key=lambda x: -x[1])]
    none = [e for e in dict.fromkeys(label(p) for p in pts) if e not in held]
    return (f" The Pareto front holds {len(front)} point(s): {names(parts)}"
            + (f"; none of {names(none)}." if none else "."))


def reading(pts, h, machine):
    """One paragraph on a scene's points, generated from the data."""
    if not pts:
        return "No point of this scene is in the results."
    ok = [p for p in pts if p.get("status") == "ok"]
    lost = [p for p in pts if p.get("status") != "ok"]
    counts = {}
    for p in lost:
        counts[p.get("status")] = counts.get(p.get("status"), 0) + 1
    lost_text = ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))
    if not ok:
        return (f"Every point of this scene is unmeasured ({lost_text}): there is no speed or error to compare; the "
                "reasons are in the table below.")
    measured = [p for p in ok if speed(p) is not None and error(p) is not None and error(p) > 0]
    vary = varies_iterations(pts)
    tail = f" Not measured: {lost_text} (table below)." if lost else ""
    if not measured:
        return (f"No point of this scene has a consistency error above 0 ({len(ok)} measured point(s), all "
                "references or without an error: a line needs a second dt that runs to compare with its "
                "reference), so no speed can be set against accuracy." + tail)
    dead = [e for e in dict.fromkeys(label(p) for p in pts) if not any(label(q) == e for q in measured)]
    dead_text = (f" No point with an error here for {names(dead)} (diverged, skipped, failed or references only)."
                 if dead else "")
    with_err = list(dict.fromkeys(label(p) for p in measured))
    if len(with_err) == 1:
        mine = sorted(measured, key=lambda p: -speed(p))
        acc = min(measured, key=error)
        return (f"Only {with_err[0]} has points with an error here: no engine to compare it with. Its fastest point "
                f"is {point_text(mine[0], vary, h)}; its most consistent (references aside) "
                f"{point_text(acc, vary, h)}." + dead_text + tail)
    sentences = []
    for x, best, order in thresholds(measured):
        win = best[order[0]]
        missing = [e for e in with_err if e not in best]
        mark = h.load_mark(machine, *best.values())
        if len(order) == 1:
            s = f"{mark}At consistency error <= {sci(x)}, only {order[0]} has a point: {point_text(win, vary, h)}"
        else:
            run = best[order[1]]
            s = (f"{mark}At consistency error <= {sci(x)}, the fastest is {order[0]} at "
                 f"{point_text(win, vary, h)}, {h.speedup_text(speed(win) / speed(run))} faster than {order[1]} at "
                 f"its best point under that error, {point_text(run, vary, h)}")
            if h.overlap(speed_range(win), speed_range(run)):
                s += " (the two speeds' min–max ranges overlap, or one repetition: no clear winner)"
            if len(order) > 2:
                s += "; then " + ", ".join(f"{e} {h.speedup_text(speed(win) / speed(best[e]))} slower"
                                          for e in order[2:])
        if missing:
            s += f"; {names(missing)} {'reaches' if len(missing) == 1 else 'reach'} no point under it"
        sentences.append(s + ".")
    return " ".join(sentences) + front_text(measured) + dead_text + tail


# ---- the section ---------------------------------------------------------------------------------

def slug(name):
    return "".join(c if c.isalnum() or c in "-_." else "-" for c in name).strip("-") or "scene"


def plot(doc, scene, pts, front, h):
    """The scene's log-log plot of consistency error against speed (see the module doc)."""
    ok = [p for p in pts if speed(p) is not None and error(p) is not None]
    if not ok:
        return False
    lines = list(dict.fromkeys(p.get("line") or p.get("id") for p in ok))
    vary = varies_iterations(pts)
    pos = [error(p) for p in ok if error(p) > 0]
    fig, ax = plt.subplots(figsize=(8.5, 5.2))
    ax.set_xscale("log")
    ax.set_yscale("log")
    if pos:
        top, bottom = 4.0 * max(pos), 10 ** (math.floor(math.log10(min(pos))) - 1)
    else:
        top, bottom = 1.0, 1e-6
    ax.set_ylim(bottom, top)
    ref_band = 0.035  # axes fraction: the row of the error-0 points, below the lowest decade
    for k, ln in enumerate(lines):
        mine = sorted((p for p in ok if (p.get("line") or p.get("id")) == ln), key=lambda p: speed(p))
        first = mine[0]
        # The engine's colour of every plot of the report (report_plots.engine_colour); its lines
        # are told apart by marker (geometry), style (rotation) and their labels.
        engine = first.get("params", {}).get("engine", "?")
        colour = engine_colour(engine)
        note_engine(fig, engine)
        marker = GEOMETRY_MARKERS.get(first.get("geometry"), "D")
        style = "-" if first.get("rotation") else "--"
        name = label(first) + (f", {first.get('iterations')} iterations"
                               if vary.get(label(first)) and first.get("iterations") is not None else "")
        line_varies = len({p.get("iterations") for p in mine}) > 1
        pos_pts = [p for p in mine if error(p) > 0]
        xs = [speed(p) for p in pos_pts]
        ys = [error(p) for p in pos_pts]
        xerr = np.array([speed_bar(p) for p in pos_pts]).T.reshape(2, len(pos_pts))
        ax.errorbar(xs, ys, xerr=xerr, color=colour, marker=marker, linestyle=style, ms=5, capsize=2, lw=1.2,
                    label=name, gid=f"engine:{engine}")
        for p in mine:
            text = dt_text(dt_of(p), unit=False) + (f", {p.get('iterations')} it." if line_varies else "")
            if error(p) > 0:
                ax.annotate(text, (speed(p), error(p)), xytext=(4, 3), textcoords="offset points", fontsize=6.5,
                            color=colour)
            else:  # error 0: drawn apart at the bottom edge (x in data, y in axes coordinates)
                ax.plot([speed(p)], [ref_band], transform=ax.get_xaxis_transform(), marker=marker, ms=6,
                        markerfacecolor="white", markeredgecolor=colour, linestyle="none", clip_on=False)
                ax.annotate(text, (speed(p), ref_band), xycoords=ax.get_xaxis_transform(), xytext=(4, 3),
                            textcoords="offset points", fontsize=6.5, color=colour)
    if front:
        fx, fy = [speed(p) for p in front], [error(p) for p in front]
        ax.step(fx, fy, where="pre", color="black", lw=1.0, alpha=0.8, label="Pareto front (all engines)")
        ax.plot(fx, fy, linestyle="none", marker="o", ms=11, markerfacecolor="none", markeredgecolor="black", lw=0.8)
    ax.axhline(bottom * 10 ** 0.5, color="#999", lw=0.6, linestyle=":")
    ax.text(0.99, ref_band + 0.04, "below the dotted line: error 0, the references (each line's smallest dt), "
            "hollow markers", transform=ax.transAxes, ha="right", va="bottom", fontsize=6.5, color="#555")
    lo, hi = ax.get_xlim()
    if lo < 1.0 < hi:
        ax.axvline(1.0, color="#bbb", lw=0.8)
        ax.text(1.0, 0.98, " real time", transform=ax.get_xaxis_transform(), fontsize=7, color="#777", va="top")
    h.log_ticks(ax, "x")
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    ax.yaxis.set_major_locator(LogLocator(base=10))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: sci(v) if v > bottom * 1.5 else ""))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("speed: simulated seconds per wall second (median; bars min–max over the repetitions; log scale)")
    ax.set_ylabel("consistency error (against the line's smallest dt; log scale)")
    ax.set_title(f"{scene}: consistency error against speed (points labelled by dt in s)", fontsize=9)
    ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2)
    doc.figure(fig, f"speed-accuracy-{slug(scene)}",
               f"{scene}: consistency error against speed, log-log; one line per engine setting (solid: rotation, "
               "dashed: translation only; marker: geometry), points labelled by dt; black staircase and rings: the "
               "Pareto front over all engines; hollow markers at the bottom edge: references (error 0)")
    return True


def mm(v):
    return 1e3 * v if is_number(v) else None


def points_table(doc, pts, front, h):
    vary = varies_iterations(pts)
    rows = []
    on_front = {id(p) for p in front}
    order = list(dict.fromkeys(p.get("line") or p.get("id") for p in pts))
    for p in sorted(pts, key=lambda p: (order.index(p.get("line") or p.get("id")), dt_of(p) or 0.0)):
        e = p.get("error") if isinstance(p.get("error"), dict) else {}
        ok = p.get("status") == "ok"
        err = error(p)
        err_text = sci(err) + (" (reference)" if ok and is_reference(p) else "")
        rows.append([label(p) + (f", {p.get('iterations')} iterations"
                                 if vary.get(label(p)) and p.get("iterations") is not None else ""),
                     p.get("geometry", "-"), dt_text(dt_of(p)).replace(" ", "\u00a0"),
                     p.get("iterations") if p.get("iterations") is not None else "-",
                     h.spread_text(p.get("speed")) if ok else "-", err_text if ok else "-",
                     h.num(mm(e.get("max_penetration_m"))) if ok else "-",
                     sci(e.get("energy_drift")) if ok and is_number(e.get("energy_drift")) else "-",
                     sci(e.get("momentum_residual")) if ok and is_number(e.get("momentum_residual")) else "-",
                     "front" if id(p) in on_front else "", p.get("status")])
    doc.table(["engine", "geometry", "dt", "iterations", "speed (sim. s / wall s)", "consistency error",
               "max penetration (mm)", "energy drift", "momentum residual", "Pareto", "status"], rows,
              "Speed: median (min–max, n repetitions). Consistency error against the line's smallest dt "
              "(its reference). Energy drift and momentum residual as the bench's physics tier gives them; '-': "
              "not available for that engine or point.", name="speed-accuracy-points")


def lost_table(doc, pts):
    lost = [p for p in pts if p.get("status") != "ok"]
    if not lost:
        return
    doc.table(["status", "engine", "dt", "iterations", "reason"],
              [[p.get("status"), label(p), dt_text(dt_of(p)).replace(" ", "\u00a0"),
                p.get("iterations") if p.get("iterations") is not None else "-", str(p.get("reason", ""))[:300]]
               for p in lost],
              "Not measured: a diverged run (non-finite state) is a recorded point with its reason; a skipped one "
              "names why the engine could not run the scene.", name="speed-accuracy-lost")


def section(doc, g, h):
    """The speed-accuracy section of merged sweep g (every scene of every shard)."""
    pts = g["points_list"]
    machine = g["first"]["machine"]
    doc.p(INTRO)
    scenes = list(dict.fromkeys(p.get("params", {}).get("scene", "?") for p in pts))
    # At most MAX_BARS points drawn in the section's plots (one a scene), as for every plot.
    drawn = not h.too_many_to_draw(doc, "Speed against accuracy", len(pts), "points")
    for sc in scenes:
        mine = [p for p in pts if p.get("params", {}).get("scene", "?") == sc]
        front = pareto_front(mine)
        doc.h(3, f"{sc}: speed against accuracy")
        doc.p(reading(mine, h, machine))
        if drawn:
            plot(doc, sc, mine, front, h)
        if any(p.get("status") == "ok" for p in mine):
            points_table(doc, mine, front, h)
        lost_table(doc, mine)
