"""The report's sections of bench sweeps (report/make_report.py): the machine and settings
block, skipped points, the paper's tables (Table 5, Table 6, Table A1, Fig. A2), broadphase
scaling, most instances at the target steps/s and any other sweep."""

import math
import os

from report_common import (PAPER, bounded, load_mark, load_warning, med, np, num, overlap, plt,
    point_load, spread_text)
from report_html import html_text, md_escape
from report_plots import (axis_label, broadphase_class, engines_of, first_window, log_ticks, point_label,
    contacts_counted, engine_colour, is_process_point, stage_shares, steps_bars, steps_points, too_many_to_draw)


def engines_ran_text(g):
    """What each engine of a sweep ran, with figures: its points measured (of its points), the
    range of their median steps/s, its broadphase (an engine's own by the registry's class
    name), the geometry it collided where recorded, and its skipped or failed points."""
    seen = {}
    for p in g["points_list"]:
        e = p.get("params", {}).get("engine", "?")
        d = seen.setdefault(e, {"broadphase": [], "geometry": [], "points": 0, "ok": 0, "sps": [], "lost": {}})
        d["points"] += 1
        if p.get("status") != "ok":
            d["lost"][p.get("status", "?")] = d["lost"].get(p.get("status", "?"), 0) + 1
            d.setdefault("why", str(p.get("reason", ""))[:120])
            continue
        d["ok"] += 1
        w = next(iter(p["windows"].values()), None) if isinstance(p.get("windows"), dict) else None
        m = med(w.get("steps_per_s")) if isinstance(w, dict) else None
        if isinstance(m, (int, float)) and not isinstance(m, bool) and math.isfinite(m):
            d["sps"].append(m)
        bp = p.get("engine_broadphase")
        if bp:
            label = broadphase_class(bp, bp)
            if label not in d["broadphase"]:
                d["broadphase"].append(label)
        if p.get("geometry") and p["geometry"] not in d["geometry"]:
            d["geometry"].append(p["geometry"])
    if not seen:
        return ""

    def one(e, d):
        parts = [f"{d['ok']} of {d['points']} point(s) measured"]
        if d["sps"]:
            lo, hi = min(d["sps"]), max(d["sps"])
            parts[0] += f", {num(lo)} steps/s" if lo == hi else f", {num(lo)}–{num(hi)} steps/s (medians)"
        parts += [f"{n} {st}" for st, n in d["lost"].items()]
        if d["lost"] and d.get("why"):
            parts[-1] += f" ({d['why']})"
        if d["broadphase"]:
            parts.append(f"broadphase {', '.join(d['broadphase'])}")
        if d["geometry"]:
            parts.append(f"geometry {' | '.join(d['geometry'])}")
        return f"{e}: " + ", ".join(parts)
    return "Engines ran: " + "; ".join(one(e, d) for e, d in seen.items())


def sps_text(p):
    """A steps point's steps/s spread, with the timed frames when the time budget cut them
    (docs/bench-format.md "Time budget": figures over fewer frames than the sweep's)."""
    text = spread_text(first_window(p)["steps_per_s"])
    b = p.get("budget")
    if isinstance(b, dict):
        f, fa = b.get("frames"), b.get("frames_asked")
        if isinstance(f, int) and isinstance(fa, int) and not isinstance(f, bool) and f != fa:
            text += f" over {f:,} of {fa:,} frames"
    return text


def settings_text(s, files):
    """One run's settings (engines, repetitions, frames) and its files."""
    return (f"engines {', '.join(s.get('engines', []))}: {s.get('repeat')} repetitions per point"
            + (f", {s.get('frames')} frames per run (warm-up {s.get('warmup')})" if "frames" in s else "")
            + (f", {s.get('warm_replays')} untimed replay(s) first" if "warm_replays" in s else "")
            + (f", each timed repetition at least {s.get('min_time_ms')} ms" if "min_time_ms" in s else "")
            + budget_text(s)
            + f" (files: {files_text(files)})")


def budget_text(s):
    """The time budget of a steps or speed-accuracy run (docs/bench-format.md "Time budget")."""
    if s.get("protocol") == "paper":
        return ", the full protocol (no time budget)"
    if s.get("protocol") != "budget":
        return ""
    def seconds(k):  # a number of seconds, else 0 (the figures are the run's, text is no number)
        v = s.get(k)
        return v if isinstance(v, (int, float)) and not isinstance(v, bool) and v == v and v > 0 else 0
    lim = seconds("max_time_s")
    return ((f", time budget: at most {lim:g} s a point (a slow point's repetitions cut to fewer timed frames, "
             "or it is skipped with an estimate: its `budget` says the frames and repetitions reached)" if lim else
             ", no time limit")
            + (f", repetitions until {seconds('min_time_s'):g} s" if seconds("min_time_s") else ""))


def files_text(files, shown=4):
    """The files' names; of many (a run's shards), the first few, the count and the last."""
    names = [os.path.basename(f) for f in files]
    if len(names) <= shown + 2:
        return ", ".join(names)
    return f"{len(names)} files, {', '.join(names[:shown])}, ..., {names[-1]}"


def machine_block(doc, g):
    j = g["first"]
    m, b, s = j["machine"], j["build"], j["settings"]
    sw = j["sweep"]
    n_ok = sum(1 for p in g["points_list"] if p.get("status") == "ok")
    total = g.get("points_total", j.get("points_total", len(g["points_list"])))
    runs = g.get("runs") or [{"files": g["files"], "settings": s}]
    B = bounded  # each value from the file cut with its length said; md_escape/html_text escape the lines
    parts = [f"Sweep `{B(sw['name'])}` ({B(sw.get('kind'))}): {B(sw.get('description', ''))}",
             f"Machine: {B(m.get('cpu'))}, host {B(m.get('hostname'))}; GPU: {B(m.get('gpu'))}"
             + (f"; driver: {B(m.get('driver'))}" if m.get("driver") else ""),
             f"Build {b.get('build_id')}, source revision {b.get('git_revision')}; run {j.get('started')} to "
             f"{j.get('updated', '?')}"
             + (f"; load average {', '.join(f'{x:.1f}' for x in m['load_average'])} at the start"
                if m.get("load_average") else "")
             + (f", {', '.join(f'{x:.1f}' for x in m['load_average_end'])} at the end"
                if m.get("load_average_end") else "")
             + (f"; CPU engine on {m['omp_threads']} threads" if m.get("omp_threads") else ""),
             "Settings: " + "; ".join(settings_text(r["settings"], r["files"]) for r in runs),
             f"Points: {len(g['points_list'])} of {total} in these files ({n_ok} measured)"
             + ("" if len(g["points_list"]) >= total else " — incomplete: missing shards or an interrupted run")]
    ran = engines_ran_text(g)
    if ran:
        parts.append(ran)
    # Notes only where they apply: repetitions and load matter to timed points (not to a
    # divergence sweep's distances), the verdicts only to sections that take one.
    timed = sw.get("kind") != "divergence"
    verdicts = sw.get("name") in ("table5", "table6", "tableA1") or sw.get("kind") == "speed-accuracy"
    measured = [p for p in g["points_list"] if p.get("status") == "ok"]
    if timed and measured and any(r["settings"].get("repeat") == 1 for r in runs):
        parts.append("1 repetition per point: the figures have no spread" +
                     (", and no verdict (fastest, slower) can be taken from them." if verdicts else "."))
    lw = load_warning(m)
    loaded = [p for p in measured if point_load(p, m)] if timed else []
    if loaded:
        parts.append(f"⚠ {len(loaded)} of {len(measured)} measured points ran under load (e.g. '{loaded[0]['id']}': "
                     f"{point_load(loaded[0], m)})" + ("; the verdicts that use them are marked ⚠." if verdicts else ".")
                     + (f" Run: {lw}." if lw else ""))
    doc.html.append('<div class="meta">' + "<br>".join(html_text(x) for x in parts) + "</div>")
    doc.md.extend("> " + md_escape(x.replace("`", "")) + "  " for x in parts)
    doc.md.append("")


def skipped_block(doc, g):
    by_reason = {}
    for p in g["points_list"]:
        if p.get("status") in ("skipped", "failed"):
            key = (p["status"], p.get("params", {}).get("engine", "?"), p.get("reason", ""))
            by_reason.setdefault(key, []).append(p["id"])
    if not by_reason:
        return
    rows = []
    for (status, engine, reason), ids in sorted(by_reason.items()):
        shown = ", ".join(ids[:3]) + (f" and {len(ids) - 3} more" if len(ids) > 3 else "")
        rows.append([status, engine, len(ids), reason[:300], shown])
    doc.table(["status", "engine", "points", "reason", "points (ids)"], rows)


def not_measured(g, scene, engine):
    """A table cell for an engine with no figure on a scene: why, from its skipped or failed
    point ("- (skipped: ...)"), else "- (not in these files)"."""
    for p in g["points_list"]:
        par = p.get("params", {})
        if par.get("engine") == engine and par.get("scene") == scene and p.get("status") in ("skipped", "failed"):
            return f"- ({p['status']}: {str(p.get('reason', ''))[:60]})"
    return "- (not in these files)"


def pairs_cell(p, spread):
    """A pair or test count of point p: "- (not reported)" for an engine that times no stage
    (a process engine reports 0 pairs: it gives octocd no broadphase figures)."""
    if is_process_point(p):
        return "- (not reported)"
    return num(med(spread))


def contacts_note(pts):
    """What the contacts column counts on each engine of `pts` (report_plots.CONTACTS_COUNTED):
    counts of different things, not comparable across engines."""
    engines = list(dict.fromkeys(p["params"]["engine"] for p in pts))
    if not engines:
        return ""
    what = {}
    for e in engines:
        proc = any(is_process_point(p) for p in pts if p["params"]["engine"] == e)
        what.setdefault(contacts_counted(e, proc), []).append(e)
    return ("Contacts count different things on each engine (not comparable across engines): "
            + "; ".join(f"{', '.join(es)}: {w}" for w, es in what.items()) + ".")


def find(pts, **kw):
    for p in pts:
        ok = True
        for k, v in kw.items():
            if k in ("scene", "engine"):
                ok &= p["params"].get(k) == v
            else:
                ok &= axis_label(p, k) == v or str(p["params"].get("axes", {}).get(k)) == v
        if ok:
            return p
    return None


def table_inputs(g, table):
    """The steps points of sweep group g, the paper's figures of `table` (PAPER key) and the engines."""
    return steps_points(g), PAPER[table], engines_of(g)


def section_table5(doc, g):
    pts, paper, engines = table_inputs(g, "table5")
    doc.p("Ours: steps/s of the simulation step alone (median over repetitions, min–max in brackets); the paper's: "
          "FPS of the whole Unity application on its GPU. Absolute numbers do not compare; the order of A, B and C "
          "per scene does. " + paper["source"] + ". " + PAPER["hardware"] + ".")
    rows = []
    for sc, ref in paper["rows"].items():
        for cfg in ("A", "B", "C"):
            r = [f"{sc} ({ref['count']})" if cfg == "A" else "", cfg, f"{ref[cfg][0]} ± {ref[cfg][1]}"]
            for e in engines:
                p = find(pts, scene=sc, engine=e, midphase=cfg)
                if p is None and cfg != "A" and find(pts, scene=sc, engine=e, midphase="A") is not None:
                    r.append("(= A: no midphase)")
                else:
                    r.append(sps_text(p) if p else not_measured(g, sc, e))
            best = []
            rows.append(r)
    doc.table(["scene (bodies)", "config", "paper FPS"] + [f"{e} steps/s" for e in engines], rows)
    # Order check: which configuration is fastest per scene, paper vs ours.
    rows = []
    for sc, ref in paper["rows"].items():
        pb = max(("A", "B", "C"), key=lambda c: ref[c][0])
        r = [sc, pb]
        for e in engines:
            found = {c: find(pts, scene=sc, engine=e, midphase=c) for c in ("A", "B", "C")}
            sp = {c: first_window(p)["steps_per_s"] for c, p in found.items() if p}
            vals = {c: med(x) for c, x in sp.items()}
            only = found["A"] if found["A"] is not None and "midphase" in (found["A"].get("ignores") or {}) else None
            if only is not None:  # an engine without a midphase ran once: its figure, no order to judge
                r.append(f"{load_mark(g['first']['machine'], only)}{point_label(only, 'midphase')}, one configuration: "
                         f"{spread_text(sp['A'])} steps/s")
                continue
            if len(vals) != 3:
                r.append(not_measured(g, sc, e) if not vals else f"- ({len(vals)} of 3 configurations measured)")
                continue
            order = sorted(vals, key=vals.get, reverse=True)
            if min(sp[order[0]].get("n", 1), sp[order[1]].get("n", 1)) < 2:
                verdict = f"no verdict (1 repetition; {order[0]} by median)"
            elif overlap(sp[order[0]], sp[order[1]]):
                verdict = f"inconclusive ({order[0]} ~ {order[1]}: ranges overlap)"
            else:
                verdict = order[0]
            verdict = load_mark(g["first"]["machine"], *found.values()) + verdict
            r.append(verdict + " (" + ", ".join(f"{c} {num(v / vals['A'] if vals.get('A') else 1.0)}x"
                                                for c, v in vals.items()) + " of A)")
        rows.append(r)
    doc.table(["scene", "paper: fastest"] + [f"{e}: fastest (speed vs A)" for e in engines], rows)
    steps_bars(doc, pts, "midphase", "Table 5: steps/s per scene, midphase A [2] / B [1,2] / C [0,1,2], per engine",
               "table5-steps", paper={(sc, c): ref[c][0] for sc, ref in paper["rows"].items() for c in ("A", "B", "C")},
               all_points=g["points_list"])
    stage_shares(doc, pts, "midphase", "Table 5: share of each stage in the step", "table5-stages",
                 all_points=g["points_list"])
    counts = []
    for p in pts:
        w = first_window(p)
        counts.append([p["params"]["scene"], point_label(p, "midphase"), p["params"]["engine"], num(med(w["step_ms"]), 4),
                       pairs_cell(p, w["pairs"]), pairs_cell(p, w["box_pairs"]), pairs_cell(p, w["vertex_tests"]),
                       num(med(w["contacts"]))])
    doc.table(["scene", "config", "engine", "step ms", "AABB pairs", "box pairs", "vertex tests",
               "contacts (each engine's own count)"], counts,
              "Per frame, means over the timed frames (median over repetitions). " + contacts_note(pts))


def section_table6(doc, g):
    pts, paper, engines = table_inputs(g, "table6")
    doc.p("Relative change ratio RCR = (C - L0) / L0 x 100 % as in the paper; 'inconclusive' when the two min-max "
          "ranges overlap (or one repetition), ⚠ when measured under load. " + paper["source"] + ".")
    rows = []
    for sc, ref in paper["rows"].items():
        r = [f"{sc} ({ref['count']})", f"{ref['L0'][0]} ± {ref['L0'][1]}", f"{ref['C'][0]} ± {ref['C'][1]}",
             f"{ref['rcr']:+.1f}%"]
        for e in engines:
            l0, c = find(pts, scene=sc, engine=e, midphase="L0"), find(pts, scene=sc, engine=e, midphase="C")
            r.append(sps_text(l0) if l0 else not_measured(g, sc, e))
            r.append(sps_text(c) if c else ("(= L0: no midphase)" if l0 else not_measured(g, sc, e)))
            if l0 and c:
                sa, sb = first_window(l0)["steps_per_s"], first_window(c)["steps_per_s"]
                a, b = med(sa), med(sb)
                r.append(f"{100.0 * (b - a) / a:+.1f}%"
                         + ("" if not overlap(sa, sb) else " (1 repetition: no verdict)"
                            if min(sa.get("n", 1), sb.get("n", 1)) < 2 else " (inconclusive: ranges overlap)")
                         + (" ⚠" if load_mark(g["first"]["machine"], l0, c) else ""))
            else:
                r.append("-")
        rows.append(r)
    head = ["scene (bodies)", "paper L0 FPS", "paper C FPS", "paper RCR"]
    for e in engines:
        head += [f"{e} L0", f"{e} C", f"{e} RCR"]
    doc.table(head, rows)
    steps_bars(doc, pts, "midphase", "Table 6: steps/s, Level 0 (aabb-only) vs C [0,1,2], per engine", "table6-steps",
               paper={(sc, c): ref[c][0] for sc, ref in paper["rows"].items() for c in ("L0", "C")},
               all_points=g["points_list"])
    stage_shares(doc, pts, "midphase", "Table 6: share of each stage in the step", "table6-stages",
                 all_points=g["points_list"])


def section_tableA1(doc, g):
    pts, paper, engines = table_inputs(g, "tableA1")
    doc.p("50 bodies fall and stack (bunny-stack-50; the other meshes in the same scene). Our early phase: frames "
          "1-300; late: 2701-3000 of 3000. RCR = (O-A - SH) / O-A x 100 %, as the paper's printed numbers are "
          "computed. " + paper["source"] + ".")
    rows = []
    for mesh, ref in paper["rows"].items():
        for ph in ("early", "late"):
            r = [mesh if ph == "early" else "", ph, num(ref[ph]["SH"]), num(ref[ph]["O-A"]), f"{ref[ph]['rcr']:+.2f}%"]
            for e in engines:
                own = next((p for p in pts if p["params"]["engine"] == e and p["params"]["axes"].get("mesh") == mesh
                            and "broadphase" in (p.get("ignores") or {})), None)
                if own is not None:  # the engine's own broadphase, measured once: named, no SH/O-A
                    a = own["windows"].get(ph, {}).get("steps_per_s")
                    r += [spread_text(a) if a else "-", f"(one broadphase: {point_label(own, 'broadphase')})", "-"]
                    continue
                sh, oa = find(pts, engine=e, mesh=mesh, broadphase="SH"), find(pts, engine=e, mesh=mesh, broadphase="O-A")
                a = sh["windows"].get(ph, {}).get("steps_per_s") if sh else None
                b = oa["windows"].get(ph, {}).get("steps_per_s") if oa else None
                r += [spread_text(a) if a else "-", spread_text(b) if b else "-"]
                r.append(f"{100.0 * (b['median'] - a['median']) / b['median']:+.1f}%" if a and b else "-")
            rows.append(r)
    head = ["mesh", "phase", "paper SH FPS", "paper O-A FPS", "paper RCR"]
    for e in engines:
        mine = [p for p in pts if p["params"]["engine"] == e]
        if mine and all("broadphase" in (p.get("ignores") or {}) for p in mine):  # its own broadphase only
            head += [f"{e} steps/s", f"{e} broadphase", f"{e} RCR"]
        else:
            head += [f"{e} SH", f"{e} O-A", f"{e} RCR"]
    doc.table(head, rows, "Ours in steps/s (median, min–max over repetitions).")
    # Steps/s over frames (the paper's Fig. 5).
    meshes = list(dict.fromkeys(p["params"]["axes"].get("mesh") for p in pts))
    if meshes and all("series" in p for p in pts):
        fig, axes = plt.subplots(1, len(meshes), figsize=(3.1 * len(meshes), 2.8), squeeze=False)
        for ax, mesh in zip(axes[0], meshes):
            for p in pts:
                if p["params"]["axes"].get("mesh") != mesh:
                    continue
                s = p["series"]
                bp = point_label(p, "broadphase")
                ax.plot(s["last_frame"], s["steps_per_s"], label=f"{p['params']['engine']} {bp}",
                        color=engine_colour(p["params"]["engine"]),
                        linestyle="-" if bp == "O-A" else "--")
            ax.set_title(mesh)
            ax.set_xlabel("frame")
            ax.set_yscale("log")
            log_ticks(ax)
        axes[0][0].set_ylabel("steps/s per 100 frames (log scale)")
        h, l = axes[0][0].get_legend_handles_labels()
        fig.legend(h, l, fontsize=9, ncol=min(len(l), 6), loc="upper center", bbox_to_anchor=(0.5, -0.02))
        fig.tight_layout()
        doc.figure(fig, "tableA1-series", "Table A1 / Fig. 5: steps/s over the 3000 frames, spatial hash (dashed) vs "
                   "octree (solid), per mesh and engine (median over repetitions of each 100-frame block)")
    steps_bars(doc, [dict(p, windows={"late": p["windows"]["late"]}) for p in pts if "late" in p["windows"]],
               "broadphase", "Table A1, late phase: steps/s per mesh, SH vs O-A, per engine", "tableA1-late",
               xkey=lambda p: p["params"]["axes"].get("mesh", p["params"]["scene"]), all_points=g["points_list"])
    rows = []
    for p in pts:
        for ph in ("early", "late"):
            w = p["windows"].get(ph)
            if w:
                rows.append([p["params"]["axes"].get("mesh"), point_label(p, "broadphase"), p["params"]["engine"], ph,
                             num(med(w["stage_ms"]["broadphase"]), 4), num(med(w["pairs"])),
                             num(med(w["cell_candidates"])), num(med(w["memory_bytes"]) / 1e6 if med(w["memory_bytes"]) else 0)])
    doc.table(["mesh", "broadphase", "engine", "phase", "broadphase ms", "AABB pairs", "cell candidates", "memory MB"],
              rows, "Per frame means. Memory: bytes held by the pipeline's buffers (the paper reports the Unity "
              "process footprint: 23-45 MB).")


def section_figA2(doc, g):
    pts = steps_points(g)
    doc.p(PAPER["figA2"]["source"] + ". Ours: contact-weighted mean of the per-frame mean AABB penetration d_p over "
          "all frames, the largest d_p, and the share of contacts with d_p > delta.")
    engines = [e for e in engines_of(g) if any(p["params"]["engine"] == e for p in pts)]
    betas = sorted({float(p["params"]["axes"]["beta"]) for p in pts})
    deltas = sorted({float(p["params"]["axes"]["delta"]) for p in pts})
    if not betas or not deltas:
        return
    figs = [("penetration_mean", "mean d_p (mm)", 1e3), ("penetration_max", "max d_p (mm)", 1e3),
            ("penetration_share_above_slop", "share of contacts with d_p > delta (%)", 100.0)]
    drawn = not too_many_to_draw(doc, "Fig. A2", len(engines) * len(betas) * len(deltas), "heat-map cells")
    for e in engines if drawn else []:
        fig, axes = plt.subplots(1, 3, figsize=(12, 3.3))
        for ax, (key, lab, scale) in zip(axes, figs):
            grid = np.full((len(betas), len(deltas)), np.nan)
            for p in pts:
                if p["params"]["engine"] != e:
                    continue
                i = betas.index(float(p["params"]["axes"]["beta"]))
                k = deltas.index(float(p["params"]["axes"]["delta"]))
                grid[i, k] = med(first_window(p)[key]) * scale
            im = ax.imshow(grid, cmap="viridis", origin="lower", aspect="auto")
            for i in range(len(betas)):
                for k in range(len(deltas)):
                    if not np.isnan(grid[i, k]):
                        ax.text(k, i, num(grid[i, k]), ha="center", va="center", fontsize=7,
                                color="white" if grid[i, k] < np.nanmean(grid) else "black")
            ax.set_xticks(range(len(deltas)))
            ax.set_xticklabels([f"{d:g}" for d in deltas])
            ax.set_yticks(range(len(betas)))
            ax.set_yticklabels([f"{b:g}" for b in betas])
            ax.set_xlabel("delta (slop, m)")
            ax.set_ylabel("beta")
            ax.set_title(lab)
            ax.grid(False)
            fig.colorbar(im, ax=ax, shrink=0.8)
        doc.figure(fig, f"figA2-{e}", f"Fig. A2 on engine {e}: penetration for beta x delta (darker = less)")
    rows = []
    for p in pts:
        w = first_window(p)
        rows.append([p["params"]["engine"], p["params"]["axes"]["beta"], p["params"]["axes"]["delta"],
                     num(med(w["penetration_mean"]) * 1e3), num(med(w["penetration_max"]) * 1e3),
                     num(100 * med(w["penetration_share_above_slop"])), num(med(w["contacts"])),
                     spread_text(w["steps_per_s"])])
    doc.table(["engine", "beta", "delta (m)", "mean d_p (mm)", "max d_p (mm)", "> delta (%)", "contacts/frame",
               "steps/s"], rows)


def slope(xs, ys):
    """Least-squares slope of log2(time) against log2(bodies): time ~ n^slope, x2 per doubling = 2^slope."""
    with np.errstate(all="ignore"):
        lx, ly = np.log2(np.asarray(xs, float)), np.log2(np.asarray(ys, float))
    ok = np.isfinite(lx) & np.isfinite(ly)  # a 0, negative or 1e308 figure has no log (fuzzed results)
    lx, ly = lx[ok], ly[ok]
    if len(lx) < 2 or np.ptp(lx) == 0:
        return float("nan")
    try:
        return float(np.polyfit(lx, ly, 1)[0])
    except (np.linalg.LinAlgError, ValueError):
        return float("nan")


def section_scaling(doc, g):
    pts = [p for p in g["points_list"] if p.get("status") in ("ok", "failed") and "ms_per_frame" in p]
    doc.p("Every broadphase replays identical recorded frames (positions the recording run's broadphase saw); the "
          "time is the engine's own broadphase stage per frame (median over repetitions after an untimed replay). "
          "Slope: least-squares exponent k of time ~ n^k over the sizes measured (1 = linear; each doubling of n "
          "multiplies the time by 2^k); 'last doubling' is log2 of the time ratio between the two largest sizes.")
    series = {}
    for p in pts:
        key = (p["params"]["engine"], p["params"]["broadphase"])
        series.setdefault(key, []).append(p)
    if not series:
        return
    drawn = not too_many_to_draw(doc, "Broadphase scaling", len(pts), "points")
    fig, ax = plt.subplots(figsize=(8, 5)) if drawn else (None, None)
    rows = []
    sizes = sorted({p["bodies"] for p in pts})
    styles = ["-", "--", ":", "-."]
    bps = {}  # engine -> its broadphases in order: the line style and marker of each
    for key, ps in sorted(series.items()):
        nb = bps.setdefault(key[0], {}).setdefault(key[1], len(bps[key[0]]))
        ps = sorted(ps, key=lambda p: p["bodies"])
        xs = np.array([p["bodies"] for p in ps], dtype=float)
        ys = np.array([med(p["ms_per_frame"]) for p in ps], dtype=float)
        lo = ys - np.array([p["ms_per_frame"]["min"] for p in ps])
        hi = np.array([p["ms_per_frame"]["max"] for p in ps]) - ys
        if drawn:
            ax.errorbar(xs, ys, yerr=[lo, hi], marker="osD^v<>"[nb % 7], ms=3, capsize=2, label=f"{key[0]} {key[1]}",
                        color=engine_colour(key[0]), linestyle=styles[nb % len(styles)])
        good = ys > 0
        sl = slope(xs[good], ys[good]) if good.sum() >= 2 else float("nan")
        ns = [p["params"].get("bodies", p["bodies"]) for p in ps]  # lattice sizes asked (walls apart)
        last = math.log2(ys[-1] / ys[-2]) if len(ys) >= 2 and ys[-2] > 0 and ns[-1] == 2 * ns[-2] else float("nan")
        by = {p["bodies"]: p for p in ps}
        rows.append([key[0], key[1]] + [num(med(by[s]["ms_per_frame"]), 3) if s in by else "-" for s in sizes]
                    + [f"{sl:.2f}" if not math.isnan(sl) else "-", f"{last:.2f}" if not math.isnan(last) else "-",
                       "yes" if all(p.get("matches_recorded", True) for p in ps) else "NO"])
    if drawn:
        ax.set_xscale("log")
        ax.set_yscale("log")
        log_ticks(ax, "x")
        log_ticks(ax, "y")
        ax.set_xlabel("bodies (log scale)")
        ax.set_ylabel("broadphase ms per frame (log scale)")
        ax.set_title("Broadphase scaling on identical recorded AABBs (solid: cpu, dashed: cuda)")
        ax.legend(fontsize=9, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        doc.figure(fig, "scaling", "Broadphase scaling, log-log: ms per frame against bodies")
    doc.table(["engine", "broadphase"] + [f"{s:,}" for s in sizes] + ["slope k", "last doubling", "pairs = recorded"],
              rows, "ms per frame, median over repetitions; '-' = not measured (skipped: see below).")
    # Per doubling: log2 of the time ratio between consecutive sizes (1.0 = linear).
    nominal = lambda p: p["params"].get("bodies", p["bodies"])  # lattice size asked (walls apart)
    sizes_n = sorted({nominal(p) for p in pts})
    steps = [(a, b) for a, b in zip(sizes_n, sizes_n[1:]) if b == 2 * a]
    if steps:
        rows = []
        for key, ps in sorted(series.items()):
            by = {nominal(p): med(p["ms_per_frame"]) for p in ps}
            rows.append([key[0], key[1]] + [f"{math.log2(by[b] / by[a]):.2f}" if by.get(a) and by.get(b) else "-"
                                            for a, b in steps])
        doc.table(["engine", "broadphase"] + [f"{a:,}→{b:,}" for a, b in steps], rows,
                  "Slope per doubling of the body count: log2(time(2n) / time(n)); 1 = linear, 2 = quadratic.")
    rows = []
    for s in sizes:
        p = next((p for p in pts if p["bodies"] == s), None)
        if p:
            rows.append([f"{s:,}", num(p.get("pairs", 0)), p.get("frames", "")])
    doc.table(["bodies", "pairs per frame", "frames replayed"], rows)


def section_max_instances(doc, g):
    """The most instances at the target steps/s per model and engine, beside the paper's counts."""
    j = g["first"]
    st = j["settings"]
    target = st.get("target_steps_per_s", 30)
    win = st.get("window", {})
    searches = g["searches"]
    # Every engine searched in any of the files (runs of one engine each merge into one table).
    named = list(dict.fromkeys(engines_of(g) + [x.get("engine") for x in searches if x.get("engine")]))
    first = ("cpu", "cuda", "bullet")  # the paper's engines first, then the others in the files' order
    engines = [e for e in first if e in named] + [e for e in named if e not in first]
    doc.p(f"Largest instance count N whose steps/s over frames {win.get('first')}-{win.get('last')} (the settled "
          f"window) is >= {target:g}, per model (its Table 5 random scene grown at the same density) and engine: "
          "doubling from 1, then bisection to the bracket [N, N+1] (or to the resolution "
          f"{st.get('resolution', 0):g} x N); probes {st.get('probe_repeat', 1)} repetition(s), the bracket's ends "
          f"{st.get('repeat')} repetition(s), median decides. A failing repetition is cut once its window's step time "
          f"shows it below {target:g} steps/s (its value is then that upper bound). Ours: steps/s of the simulation "
          "step alone; the paper's: FPS of the whole Unity application on an RTX 3090 Ti. "
          "0 = a single instance is already below the target; '>= cap' = the cap still passed; memory = the next "
          "count did not fit (the engine's memory check before its first step).")
    scenes = list(dict.fromkeys(x.get("scene") for x in searches))
    by = {(x.get("scene"), x.get("engine")): x for x in searches}

    def cell(x):
        if x is None:
            return "-"
        status = x.get("status")
        if status != "ok":
            return f"{status}: {str(x.get('reason', ''))[:80]}"
        n, br = x.get("max_instances"), x.get("bracket") or [None, None]
        sps = x.get("steps_per_s")
        if br[1] is None:
            return f">= {n:,} (cap)" + (f", {spread_text(sps)} steps/s" if sps else "")
        if n == 0:
            return f"0 ({x.get('limited_by')}: {str(x.get('reason', ''))[:80]})"
        lim = "" if x.get("limited_by") == "steps/s" else f", {x.get('limited_by')}"
        return f"{n:,} [{br[0]:,}, {br[1]:,}]: {spread_text(sps)} steps/s" + lim

    rows, sources = [], []
    for sc in scenes:
        any_x = next((x for x in searches if x.get("scene") == sc), {})
        paper = any_x.get("paper") or {}
        if paper.get("source"):
            sources.append(f"{any_x.get('model', sc)}: {paper['source']}")
        rows.append([f"{any_x.get('model', sc)} ({sc})", f"{paper['count']:,}" if paper.get("count") else "-"]
                    + [cell(by.get((sc, e))) for e in engines])
    doc.table(["model (scene)", "paper: most instances at >= 30 FPS"]
              + [f"{e}: N [bracket]: steps/s at N" for e in engines], rows,
              "Paper sources: " + "; ".join(sources) + "." if sources else None, name="max-instances")
    rows = []
    for x in searches:
        br = x.get("bracket")
        br = f"[{br[0]}, {br[1] if br[1] is not None else '-'}]" if isinstance(br, list) and len(br) == 2 else "-"
        rows.append([x.get("model"), x.get("engine"), x.get("status"), x.get("max_instances", "-"),
                     br, spread_text(x.get("steps_per_s")),
                     ("≤ " if x.get("steps_per_s_above_cut") else "") + spread_text(x.get("steps_per_s_above")), x.get("limited_by", "-"), x.get("probes", 0),
                     x.get("confirmations", 0), str(x.get("reason", ""))[:200]])
    doc.table(["model", "engine", "status", "N", "bracket", "steps/s at N", "steps/s at bracket top", "limited by",
               "probes", "confirmations", "reason"], rows,
              "≤: the top's repetitions were cut once below the target, so the figure is an upper bound.",
              name="searches")
    pts = [p for p in g["points_list"] if p.get("status") == "ok" and "windows" in p
           and "instances" in p.get("params", {}).get("axes", {})]
    if pts and not too_many_to_draw(doc, "max-instances: the probes of the search", len(pts), "points"):
        fig, ax = plt.subplots(figsize=(8, 4.6))
        keys = list(dict.fromkeys((p["params"]["scene"], p["params"]["engine"]) for p in pts))
        scenes = list(dict.fromkeys(key[0] for key in keys))  # a line style per scene, a colour per engine
        for key in keys:
            mine = [p for p in pts if (p["params"]["scene"], p["params"]["engine"]) == key]
            for role, style in (("probe", "o"), ("confirm", "x")):
                ps = sorted((p for p in mine if p.get("role", "probe") == role),
                            key=lambda p: p["params"]["axes"]["instances"])
                if not ps:
                    continue
                xs = [p["params"]["axes"]["instances"] for p in ps]
                ys = [med(first_window(p)["steps_per_s"]) for p in ps]
                ax.plot(xs, ys, marker=style, ms=3 if role == "probe" else 6, color=engine_colour(key[1]),
                        label=f"{key[0]} {key[1]}" + (" (bracket ends, confirmed)" if role == "confirm" else ""),
                        linestyle=["-", "--", ":", "-."][scenes.index(key[0]) % 4] if role == "probe" else "none")
        ax.axhline(target, color="black", linewidth=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        log_ticks(ax, "x")
        log_ticks(ax, "y")
        ax.set_xlabel("instances (log scale)")
        ax.set_ylabel("steps/s over the window (median; cut probes: upper bound; log scale)")
        ax.set_title(f"Probes of the search; the line is the target {target:g} steps/s")
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        doc.figure(fig, "max-instances-probes", "max-instances: every probe's steps/s against its instance count "
                   "(a colour per engine, a line style per model; x: the bracket's ends measured again)")


def section_generic(doc, g):
    rows = []
    for p in g["points_list"]:
        if p.get("status") != "ok":
            continue
        if "windows" in p:
            for wn, w in p["windows"].items():
                pen = med(w.get("penetration_mean"))
                rows.append([p["id"], wn, spread_text(w["steps_per_s"]), num(med(w.get("step_ms")), 4),
                             pairs_cell(p, w.get("pairs")), num(med(w.get("contacts"))),
                             num(pen * 1e3 if isinstance(pen, (int, float)) else None)])
        elif "ms_per_frame" in p:
            rows.append([p["id"], "replay", "-", spread_text(p["ms_per_frame"]), num(p.get("pairs")), "-", "-"])
    pts = steps_points(g)
    doc.table(["point", "window", "steps/s", "step ms", "AABB pairs", "contacts (each engine's own count)",
               "mean d_p (mm)"], rows,
              "Per frame, means over the timed frames (median over repetitions); '-': not measured. "
              + contacts_note(pts))
    if pts:
        axis = next(iter(pts[0]["params"].get("axes", {})), None)
        steps_bars(doc, pts, axis, f"{g['first']['sweep']['name']}: steps/s", "sweep-steps",
                   all_points=g["points_list"])
        stage_shares(doc, pts, axis, f"{g['first']['sweep']['name']}: stage shares", "sweep-stages",
                     all_points=g["points_list"])
