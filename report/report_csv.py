"""The report's data as CSV (report/make_report.py, --csv DIR): per point and repetition,
plus a summary row per figure."""

import io

from report_common import csv_writer


CSV_UNITS = {"steps_per_s": "1/s", "cpu_steps_per_s": "1/s", "step_ms": "ms", "stage_ms": "ms", "pairs": "1/frame",
             "cell_candidates": "1/frame", "box_pairs": "1/frame", "vertex_tests": "1/frame", "contacts": "1/frame",
             "memory_bytes": "B", "penetration_mean": "m", "penetration_max": "m",
             "penetration_share_above_slop": "1", "wall_s": "s", "ms_per_frame": "ms", "speed": "s/s"}


def file_slug(name):
    return "".join(c if c.isalnum() or c in "-_." else "-" for c in name).strip("-") or "sweep"


def is_spread(x):
    return isinstance(x, dict) and isinstance(x.get("values"), list)


def point_spreads(p):
    """[(window or '', column, spread)] of a point: every figure with its repetitions."""
    out = []
    for wn, w in (p.get("windows") or {}).items():
        for k, v in w.items():
            if is_spread(v):
                out.append((wn, k, v))
            elif k == "stage_ms" and isinstance(v, dict):
                out += [(wn, f"stage_ms.{st}", x) for st, x in v.items() if is_spread(x)]
    out += [("", k, v) for k, v in p.items() if is_spread(v)]
    return out


def csv_number(v):
    return repr(float(v)) if isinstance(v, (int, float)) and not isinstance(v, bool) else ""


def sweep_csv(doc, path, g):
    """One sweep as data: per point and window one row per repetition (kind rep, repetition
    0..n-1) and one summary row (kind summary: the median over the repetitions); numbers only,
    the unit of each figure in its header (`steps_per_s [1/s]`); a point without figures
    (skipped, failed) one summary row with its status and no figures."""
    pts = g["points_list"]
    axes = sorted({a for p in pts for a in (p.get("params", {}).get("axes") or {})})
    figs = []
    for p in pts:
        for _, k, _ in point_spreads(p):
            if k not in figs:
                figs.append(k)
    head = ["sweep", "point", "index", "status", "scene", "engine", "broadphase", "bodies"] + \
        [f"axis.{a}" for a in axes] + ["window", "first_frame", "last_frame", "kind", "repetition"] + \
        [f"{k} [{CSV_UNITS.get(k.split('.')[0], '1')}]" for k in figs]
    name = g["first"]["sweep"]["name"]
    f = io.StringIO(newline="")
    if True:
        w = csv_writer(f)
        w.writerow(head)
        for p in pts:
            par = p.get("params", {})
            base = [name, p.get("id"), p.get("index"), p.get("status"), par.get("scene", ""), par.get("engine", ""),
                    par.get("broadphase", ""), p.get("bodies", par.get("bodies", ""))] + \
                [(par.get("axes") or {}).get(a, "") for a in axes]
            sp = point_spreads(p)
            windows = list(dict.fromkeys(wn for wn, _, _ in sp if wn)) or [""]
            if not sp:
                w.writerow(base + ["", "", "", "summary", ""] + [""] * len(figs))
                continue
            for wn in windows:
                wd = (p.get("windows") or {}).get(wn, {})
                cols = {k: v for x, k, v in sp if x in (wn, "")}
                n = max(len(v["values"]) for v in cols.values())
                pre = base + [wn, wd.get("first", ""), wd.get("last", "")]
                for r in range(n):
                    w.writerow(pre + ["rep", r] + [csv_number(cols[k]["values"][r]) if k in cols and
                                                    r < len(cols[k]["values"]) else "" for k in figs])
                w.writerow(pre + ["summary", ""] + [csv_number(cols[k].get("median")) if k in cols else ""
                                                      for k in figs])
    doc.files.put(path, f.getvalue())
