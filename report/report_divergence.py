"""The report's divergence section (design.md section 20, after Chung and Pollard, CAVW 2016;
docs/predictability.md): results of `octocd bench` sweeps of kind `divergence`
(docs/bench-format.md), per scene

- a plot of the mean distance of the bodies from the unperturbed run over time, log scale, each
  engine in its colour and marker of every plot of the report (report_plots.engine_colour,
  engine_marker; an engine that did not run the scene named in the legend with why), its name
  at the end of its line, one line per eps of the ladder (darker: larger eps);
- a table of the fitted growth exponents (1/s) per engine and eps, with the distance at the
  first and last frame;
- a table of the points not measured (skipped, failed) with their reasons.

Called by make_report.py (`section(doc, g, h)`, `check_point(where, p, fail)`,
`write_csv(path, g)`): `doc` is the report's Doc, `g` a merged sweep, `h` the shared helpers.
"""
import csv
import io
import math

from report_common import is_number, plt
from report_plots import engine_colour, engine_marker, note_engine, unmeasured_engines

KIND = "divergence"
STATUSES = ("ok", "skipped", "failed")
MAX_FRAMES = 1000001  # mean_m and max_m per point, at most (a sweep's frames + 1)

INTRO = ("Per scene and engine, copies of the scene whose dynamic bodies start eps metres from their place (a "
         "seeded random direction per body and copy) run beside the unperturbed run; the plot shows the mean "
         "distance of the bodies from the unperturbed run over time (log scale; a distance of 0, a copy still bit "
         "for bit on the unperturbed run, cannot be drawn on a log axis and is left out). A regular scene keeps "
         "the distance near eps (a resting stack: the solver may even pull it back); a chaotic one (a pile) "
         "grows it by orders of magnitude until it saturates at the scene's size. The growth exponent lambda is "
         "the least-squares slope of ln(mean distance) over time over the whole run (d(t) ~ d0 exp(lambda t)); "
         "saturation lowers it, so read it beside the plot. Positions are float32: an eps below a body's "
         "coordinate resolution (about 6e-8 m at 1 m, 1e-6 m at 10 m) rounds away, and the distance at frame 0 "
         "says what remained.")


def check_point(where, p, fail):
    """The divergence fields of one point (eps_m; of a point with status ok also dt, mean_m,
    max_m and exponent_per_s), checked after report_data.check_points checked its status (one
    of STATUSES) and params: one line naming the file, point and key through `fail` (exit 2)."""
    if not (is_number(p.get("eps_m")) and math.isfinite(p["eps_m"]) and 0 <= p["eps_m"] <= 1):
        fail(f"{where}.eps_m: {p.get('eps_m')!r}; allowed: a perturbation in metres in [0, 1]")
    if p["status"] != "ok":
        return
    if not (is_number(p.get("dt")) and math.isfinite(p["dt"]) and p["dt"] > 0):
        fail(f"{where}.dt: {p.get('dt')!r}; allowed: a time step in seconds > 0")
    for key in ("mean_m", "max_m"):
        v = p.get(key)
        if not isinstance(v, list) or not 1 <= len(v) <= MAX_FRAMES or not all(
                x is None or (is_number(x) and x >= 0) for x in v):
            fail(f"{where}.{key}: {str(v)[:60]}; allowed: a list of distances >= 0 (m) or null, one per frame")
    if len(p["mean_m"]) != len(p["max_m"]):
        fail(f"{where}.max_m: {len(p['max_m'])} frames, mean_m {len(p['mean_m'])}; allowed: one per frame each")
    e = p.get("exponent_per_s")
    if e is not None and not (is_number(e) and math.isfinite(e)):
        fail(f"{where}.exponent_per_s: {e!r}; allowed: a number (1/s) or null")


def _scene(p):
    return p.get("params", {}).get("scene", "?")


def _engine(p):
    return p.get("params", {}).get("engine", "?")


def _sci(v):
    return "-" if not is_number(v) else ("0" if v == 0 else f"{v:.3g}")


def _slug(text):
    return "".join(c if c.isalnum() else "-" for c in text).strip("-").lower() or "scene"


def plot_scene(doc, scene, pts):
    """One figure: mean distance over time per engine and eps, log scale; False when nothing to draw."""
    ok = [p for p in pts if p.get("status") == "ok"]
    engines = list(dict.fromkeys(_engine(p) for p in ok))
    eps_all = sorted({p["eps_m"] for p in ok})
    drawn = False
    fig, ax = plt.subplots(figsize=(8.0, 4.6))
    for e in engines:
        colour, marker = engine_colour(e), engine_marker(e)
        mine = sorted((p for p in ok if _engine(p) == e), key=lambda p: p["eps_m"])
        end = None  # the end of the engine's largest-eps line: its name is written there
        for p in mine:
            rank = eps_all.index(p["eps_m"])
            alpha = 0.35 + 0.65 * (rank + 1) / max(len(eps_all), 1)
            t = [f * p["dt"] for f in range(len(p["mean_m"]))]
            y = [v if is_number(v) and v > 0 else float("nan") for v in p["mean_m"]]
            if all(math.isnan(v) for v in y):
                continue
            ax.plot(t, y, color=colour, alpha=alpha, lw=1.2, marker=marker, markevery=max(len(t) // 8, 1), ms=4,
                    label=e, gid=f"engine:{e}")
            end = max((k for k in range(len(y)) if not math.isnan(y[k])), default=None)
            end = (t[end], y[end]) if end is not None else None
            drawn = True
        if end is not None:
            note_engine(fig, e)
            ax.annotate(e, end, xytext=(3, 0), textcoords="offset points", fontsize=8, color="#222",
                        va="center", ha="left")
    if not drawn:
        plt.close(fig)
        return False
    on = fig.__dict__.get("octocd_engines", {})
    lost = {e: "every distance 0 (a log axis cannot draw it)" for e in engines if e not in on}
    lost.update(unmeasured_engines(pts, ok))
    for e, why in lost.items():
        note_engine(fig, e, why)
        ax.plot([], [], color=engine_colour(e), marker=engine_marker(e), lw=1.2, label=f"{e}: no line ({why[:60]})")
    ax.set_yscale("log")
    # Plain tick labels (1e-06, 0.001, 1): matplotlib's own log labels are mathtext, which the
    # report does not parse (report_common: every text is plain).
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    ax.yaxis.set_major_locator(LogLocator(base=10))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}" if v > 0 else ""))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("time (s)")
    ax.set_ylabel("mean distance from the unperturbed run (m, log scale)")
    ax.set_title(f"{scene}: divergence over time (one line per eps {', '.join(_sci(x) for x in eps_all)} m; "
                 "darker: larger eps)", fontsize=9)
    handles, labels = ax.get_legend_handles_labels()
    seen = {}
    for hd, lb in zip(handles, labels):
        seen.setdefault(lb, hd)
    ax.legend(seen.values(), seen.keys(), fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.14),
              ncol=min(len(seen), 6))
    doc.figure(fig, f"divergence-{_slug(scene)}",
               f"{scene}: mean distance of the bodies from the unperturbed run over time, log scale; colour: engine, "
               "one line per eps (darker: larger); frames at distance 0 are left out")
    return True


def exponent_table(doc, scene, pts):
    ok = [p for p in pts if p.get("status") == "ok"]
    if not ok:
        return
    rows = []
    for p in sorted(ok, key=lambda p: (list(dict.fromkeys(_engine(q) for q in ok)).index(_engine(p)), p["eps_m"])):
        e = p.get("exponent_per_s")
        rows.append([_engine(p), _sci(p["eps_m"]), p.get("copies", "-"), _sci(p["mean_m"][0]), _sci(p["mean_m"][-1]),
                     _sci(max((x for x in p["max_m"] if is_number(x)), default=None)),
                     f"{e:.3g}" if is_number(e) else "- (" + str(p.get("exponent_reason", "none"))[:80] + ")"])
    doc.table(["engine", "eps (m)", "copies", "mean distance at frame 0 (m)", "at the last frame (m)",
               "largest distance (m)", "growth exponent (1/s)"], rows,
              f"{scene}: the growth exponent is the least-squares slope of ln(mean distance) over time over the "
              "whole run; ~0: the distance stays where it started; > 0: it grows (chaos, or a resting contact "
              "broken); < 0: the solver pulls the copies back.", name=f"divergence-{_slug(scene)}")


def lost_table(doc, pts):
    lost = [p for p in pts if p.get("status") != "ok"]
    if not lost:
        return
    doc.table(["status", "scene", "engine", "eps (m)", "reason"],
              [[p.get("status"), _scene(p), _engine(p), _sci(p.get("eps_m")), str(p.get("reason", ""))[:300]]
               for p in lost], "Not measured: why each engine did not run the scene.", name="divergence-lost")


def section(doc, g, h):
    """The divergence section of merged sweep g."""
    pts = g["points_list"]
    doc.p(INTRO)
    for scene in dict.fromkeys(_scene(p) for p in pts):
        mine = [p for p in pts if _scene(p) == scene]
        doc.h(3, f"{scene}")
        if not plot_scene(doc, scene, mine):
            doc.p(f"{scene}: no distance above 0 to draw (every copy bit for bit on the unperturbed run, or no "
                  "engine ran it).", "note")
        exponent_table(doc, scene, mine)
    lost_table(doc, pts)


def write_csv(path, g):
    """The sweep as data: per point and frame the mean and max distance (m) and the point's exponent."""
    f = io.StringIO(newline="")
    w = csv.writer(f)
    w.writerow(["sweep", "scene", "engine", "eps [m]", "copies", "frame", "t [s]", "mean_distance [m]",
                "max_distance [m]", "exponent [1/s]", "status"])
    name = g["first"]["sweep"]["name"]
    for p in g["points_list"]:
        if p.get("status") != "ok":
            w.writerow([name, _scene(p), _engine(p), p.get("eps_m"), p.get("copies"), "", "", "", "", "",
                        p.get("status")])
            continue
        for fr, (m, x) in enumerate(zip(p["mean_m"], p["max_m"])):
            w.writerow([name, _scene(p), _engine(p), p["eps_m"], p.get("copies"), fr, fr * p["dt"], m, x,
                        p.get("exponent_per_s"), "ok"])
    return f.getvalue()
