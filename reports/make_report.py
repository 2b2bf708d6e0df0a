#!/usr/bin/env python3
"""octocd report: bench results (octocd-bench JSON) and traces (octocd-trace HDF5) into
OUT/index.html (self-contained: every plot inline as SVG, no network) and OUT/report.md
(plots as OUT/plots/*.svg). Run by `octocd report` (cli/report.cpp); usable directly:

    /usr/bin/python3 reports/make_report.py -o OUT RESULT.json [TRACE.h5 ...]

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
"""
import argparse
import csv
import datetime
import errno
import html
import io
import json
import math
import os
import shutil
import stat
import subprocess
import sys

PAPER = json.load(open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "paper_tables.json")))
STAGES = ["integrate", "aabbs", "broadphase", "midphase", "response", "metrics"]
STAGE_COLORS = ["#4e79a7", "#a0cbe8", "#f28e2b", "#e15759", "#59a14f", "#b6992d"]
ENGINE_COLORS = {"cpu": "#4e79a7", "cuda": "#59a14f", "bullet": "#e15759"}
NOISE_NOTE = ("Timings on a shared machine move with its load (other processes, builds): compare figures "
              "taken in one run; spreads are min-max over the repetitions.")


def fail(msg):
    print(f"octocd report: error: {msg}", file=sys.stderr)
    sys.exit(2)


try:
    import numpy as np
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError as e:  # exit 1: a missing dependency is not bad input
    print(f"octocd report: runtime failure: {e}; install Debian's python3-matplotlib and python3-numpy",
          file=sys.stderr)
    sys.exit(1)

plt.rcParams.update({"svg.fonttype": "none", "font.family": "sans-serif", "font.size": 9,
                     "axes.grid": True, "grid.alpha": 0.3, "figure.dpi": 100})


# ---- input -----------------------------------------------------------------------------------

def regular_file(path):
    """Refuses a FIFO, a device or a folder before it is opened (open() on a FIFO blocks)."""
    try:
        st = os.stat(path)
    except OSError as e:
        fail(f"{path}: cannot open ({errno.errorcode.get(e.errno, e.errno)}: {e.strerror}); allowed: result files "
             "of `octocd bench` (.json) and traces (.h5)")
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" \
            if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "not a plain file"
        fail(f"{path}: not a regular file ({kind}); allowed: result files of `octocd bench` (.json) and traces "
             "(.h5) stored in regular files")


def load(path):
    regular_file(path)
    with open(path, "rb") as f:
        head = f.read(8)
    if head == b"\x89HDF\r\n\x1a\n":
        return ("trace", path)
    try:
        with open(path) as f:
            j = json.load(f)
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        fail(f"{path}: neither an HDF5 trace nor JSON ({e}); allowed: octocd-bench results (.json), "
             "octocd-trace files (.h5)")
    fmt, ver = (j.get("format"), j.get("version")) if isinstance(j, dict) else (None, None)
    if fmt != "octocd-bench" or ver != 1:
        fail(f"{path}: format: {fmt!r} version {ver!r}; allowed: octocd-bench version 1 (a result of "
             "`octocd bench`) or an octocd trace")
    for key in ("sweep", "points", "machine", "build", "settings"):
        if key not in j:
            fail(f"{path}: {key}: missing; allowed: a complete octocd-bench result")
    return ("result", path, j)


def check_points(path, j):
    """The fields the report reads, checked per point: one line naming file, point and key."""
    if not isinstance(j.get("points"), list):
        fail(f"{path}: points: not an array; allowed: an array of points (docs/bench-format.md)")
    for i, p in enumerate(j["points"]):
        where = f"{path}: points[{i}]"
        if not isinstance(p, dict):
            fail(f"{where}: not an object; allowed: a point object")
        if not isinstance(p.get("id"), str):
            fail(f"{where}.id: {p.get('id')!r}; allowed: a string")
        if p.get("status") != "ok":
            continue
        if not isinstance(p.get("params"), dict):
            fail(f"{where}.params: {p.get('params')!r}; allowed: an object")
        spreads = []
        if "windows" in p:
            if not isinstance(p["windows"], dict) or not p["windows"]:
                fail(f"{where}.windows: {json.dumps(p['windows'])[:60]}; allowed: an object of windows")
            for wn, w in p["windows"].items():
                if not isinstance(w, dict):
                    fail(f"{where}.windows.{wn}: {json.dumps(w)[:60]}; allowed: an object of figures")
                spreads += [(f"windows.{wn}.{k}", v) for k, v in w.items() if k not in ("first", "last", "frames")]
                if "steps_per_s" not in w:
                    fail(f"{where}.windows.{wn}.steps_per_s: missing; allowed: a spread object")
        elif "ms_per_frame" in p:
            spreads.append(("ms_per_frame", p["ms_per_frame"]))
        else:
            fail(f"{where}: neither windows nor ms_per_frame; allowed: a measured point (docs/bench-format.md)")
        for k, v in spreads:
            if k.endswith("stage_ms") and isinstance(v, dict):
                spreads_v = list(v.items())
            else:
                spreads_v = [("", v)]
            for sub, x in spreads_v:
                name = f"{where}.{k}" + (f".{sub}" if sub else "")
                if not isinstance(x, dict) or not isinstance(x.get("n"), int):
                    fail(f"{name}: {json.dumps(x)[:60]}; allowed: a spread {{median, min, max, n, ...}}")
                # null: a non-finite figure (JSON has no NaN); the gate fails such a point, exit 4.
                if x["n"] > 0 and not all(x.get(f) is None or isinstance(x.get(f), (int, float))
                                          and not isinstance(x.get(f), bool) for f in ("median", "min", "max")):
                    fail(f"{name}: {json.dumps(x)[:60]}; allowed: numbers median, min, max")


def merge(results, pool=False):
    """Groups result files of one sweep definition on one machine; points by id. With pool
    (a side of the performance gate), a point in several files (runs of one build) is kept
    once, its other runs in g["pooled"][id] (the gate pools their repetitions)."""
    groups = {}
    for path, j in results:
        m = j["machine"]
        key = (j["sweep"]["name"], json.dumps(j["sweep"]["definition"], sort_keys=True),
               m.get("hostname"), m.get("cpu"), m.get("gpu"))
        g = groups.setdefault(key, {"files": [], "points": {}, "first": j, "origin": {}, "searches": [], "json": {},
                                    "pooled": {}})
        if g["files"] and j["build"].get("build_id") != g["first"]["build"].get("build_id"):
            fail(f"{path}: build.build_id: {j['build'].get('build_id')!r}, but {g['files'][0]} (same sweep) has "
                 f"{g['first']['build'].get('build_id')!r}; allowed: shards of one build in one report (compare two "
                 "builds with --baseline BASE.json NEW.json)")
        g["files"].append(path)
        g["json"][path] = j
        searches = j.get("searches", [])
        if not isinstance(searches, list) or not all(isinstance(x, dict) for x in searches):
            fail(f"{path}: searches: {json.dumps(searches)[:60]}; allowed: an array of search summaries "
                 "(docs/bench-format.md, kind max-instances)")
        g["searches"].extend(searches)
        for p in j["points"]:
            pid = p.get("id")
            if pid in g["points"] and pool:
                g["pooled"].setdefault(pid, [(g["origin"][pid], g["points"][pid])]).append((path, p))
                continue
            if pid in g["points"]:
                fail(f"{path}: points: '{pid}' is also in {g['origin'][pid]}; allowed: each point in one "
                     "result file (shards of one sweep are disjoint)")
            g["points"][pid] = p
            g["origin"][pid] = path
    out = []
    for g in groups.values():
        g["points_list"] = sorted(g["points"].values(), key=lambda p: p.get("index", 0))
        out.append(g)
    return out


# ---- formatting ------------------------------------------------------------------------------

def num(v, digits=3):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    a = abs(v)
    if a >= 1000:
        return f"{v:,.0f}"
    if a >= 100:
        return f"{v:.1f}"
    if a == 0:
        return "0"
    return f"{v:.{max(digits - 1 - int(math.floor(math.log10(a))), 0)}f}"


def med(s):
    return s.get("median") if isinstance(s, dict) else None


def spread_text(s, digits=3):
    """median (min–max, n=N); '(1 rep.)' when there was one repetition: no spread to judge by."""
    if not isinstance(s, dict) or "median" not in s:
        return "-"
    n = s.get("n", 1)
    if n > 1:
        return f"{num(s['median'], digits)} ({num(s['min'], digits)}–{num(s['max'], digits)}, n={n})"
    return f"{num(s['median'], digits)} (1 rep.)"


def overlap(a, b):
    """Whether two spreads' min-max ranges overlap (or either has one repetition): no verdict then."""
    if min(a.get("n", 1), b.get("n", 1)) < 2:
        return True
    return not (a["max"] < b["min"] or b["max"] < a["min"])


def load_warning(m):
    """Why timings of this machine description are suspect (OpenMP threads oversubscribing the
    cores, or a load at the start or end above them), or ''. A run-level note; verdicts are
    marked per point (point_load)."""
    threads, omp = m.get("threads") or 0, m.get("omp_threads") or 1
    why = []
    if threads and omp > threads:
        why.append(f"{omp} OpenMP threads on {threads} cores")
    # At the start the load is the others'; at the end it includes the bench's own threads.
    for key, when, own in (("load_average", "start", omp), ("load_average_end", "end", 0)):
        la = m.get(key)
        if threads and isinstance(la, list) and la and isinstance(la[0], (int, float)) and la[0] + own > threads + 1:
            why.append(f"load {la[0]:.1f} at the {when} leaves {max(threads - la[0], 0):.1f} of {threads} cores free "
                       f"for {omp} OpenMP thread(s)" + (" (its own included)" if when == "end" else ""))
    return "; ".join(why)


def own_threads(p, m):
    """The threads the bench itself ran while measuring point p: the CPU engine's OpenMP
    threads, one for any other engine (cuda's host thread, Bullet)."""
    return (m.get("omp_threads") or 1) if p.get("params", {}).get("engine") == "cpu" else 1


def point_load(p, m):
    """Why point p's timing is suspect, or '': the load of the other processes exceeded the
    cores left free for the bench's own threads while it ran. Read from the point's load
    average (recorded at its end, the bench's own threads included: others = load - own);
    a point without one is judged by the run's load at the start (others') and end."""
    threads = m.get("threads") or 0
    if not threads:
        return ""
    own = own_threads(p, m)
    if own > threads:
        return f"{own} threads on {threads} cores"
    la = p.get("load_average")
    if isinstance(la, list) and la and isinstance(la[0], (int, float)):
        others = [(max(la[0] - own, 0.0), "during the point")]
    else:
        others = []
        for key, sub in (("load_average", 0), ("load_average_end", own)):
            x = m.get(key)
            if isinstance(x, list) and x and isinstance(x[0], (int, float)):
                others.append((max(x[0] - sub, 0.0), "at the run's " + ("start" if sub == 0 else "end")))
    for load, when in others:
        free = threads - load
        if own > free + 1e-9:
            return f"load of other processes {load:.1f} {when} left {max(free, 0):.1f} of {threads} cores free for " \
                   f"{own} thread(s)"
    return ""


def load_mark(m, *points):
    """'⚠ ' when one of the points a verdict compares was measured under load (point_load)."""
    return "⚠ " if any(p is not None and point_load(p, m) for p in points) else ""


def output_dir(path, option):
    """Exit 2 naming `option` unless `path` is a writable folder or can be made one: not a
    file, a device, a symbolic link (e.g. to /etc) or a read-only folder."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        parent = os.path.dirname(os.path.abspath(path))
        while not os.path.exists(parent):
            parent = os.path.dirname(parent)
        if not os.path.isdir(parent) or not os.access(parent, os.W_OK) or not os.stat(parent).st_mode & 0o222:
            fail(f"{option} {path}: cannot be created in {parent} (not a writable folder); allowed: a folder octocd "
                 "may write in")
        return
    if stat.S_ISLNK(st.st_mode):
        fail(f"{option} {path}: a symbolic link (to {os.readlink(path)}); allowed: a folder path that is not a link")
    if not stat.S_ISDIR(st.st_mode):
        kind = "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" \
            if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "a file"
        fail(f"{option} {path}: {kind}, not a folder; allowed: a folder (created when missing)")
    if not os.access(path, os.W_OK) or not st.st_mode & 0o222:
        fail(f"{option} {path}: a read-only folder; allowed: a folder octocd may write in")


class Outputs:
    """Every file of one report, kept in memory until commit(): then each is written to a
    temporary file beside its destination, and only when all are written are they renamed
    into place (a full disk or a size limit leaves the earlier report as it was)."""

    def __init__(self):
        self.files = {}  # path -> text

    def put(self, path, text):
        self.files[path] = text

    def commit(self):
        temps = []
        try:
            for path, text in self.files.items():
                os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
                tmp = os.path.join(os.path.dirname(path), f".{os.path.basename(path)}.tmp.{os.getpid()}")
                temps.append((tmp, path))
                with open(tmp, "w", newline="") as f:
                    f.write(text)
                    f.flush()
                    os.fsync(f.fileno())
            for tmp, path in temps:
                os.replace(tmp, path)
        except BaseException:
            for tmp, _ in temps:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
            raise


class Doc:
    """One report, written both as HTML and as Markdown (files committed by write())."""

    def __init__(self, out, csv_dir=None):
        self.out = out
        self.html, self.md = [], []
        self.nplot = 0
        self.ncsv = 0
        self.section = "report"
        self.csv_dir = csv_dir
        self.files = Outputs()

    def h(self, level, text, anchor=None):
        a = f' id="{anchor}"' if anchor else ""
        self.html.append(f"<h{level}{a}>{html.escape(text)}</h{level}>")
        self.md.append("#" * level + " " + text + "\n")

    def p(self, text, cls=None):
        c = f' class="{cls}"' if cls else ""
        self.html.append(f"<p{c}>{html.escape(text)}</p>")
        self.md.append(text + "\n")

    def table(self, header, rows, note=None, name="table"):
        cls = ' class="compact"' if len(header) > 9 else ""
        t = [f'<div class="wide"><table{cls}><thead><tr>' + "".join(f"<th>{html.escape(str(x))}</th>" for x in header) + "</tr></thead><tbody>"]
        for r in rows:
            t.append("<tr>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in r) + "</tr>")
        t.append("</tbody></table></div>")
        self.html.append("".join(t))
        self.md.append("| " + " | ".join(str(x) for x in header) + " |")
        self.md.append("|" + "|".join("---" for _ in header) + "|")
        for r in rows:
            self.md.append("| " + " | ".join(str(x).replace("|", "\\|") for x in r) + " |")
        self.md.append("")
        if note:
            self.p(note, "note")

    def figure(self, fig, name, caption):
        self.nplot += 1
        fname = f"{self.nplot:02d}-{name}.svg"
        buf = io.StringIO()
        fig.savefig(buf, format="svg", bbox_inches="tight")
        plt.close(fig)
        svg = buf.getvalue()
        self.files.put(os.path.join(self.out, "plots", fname), svg)
        body = svg[svg.find("<svg"):]
        self.html.append(f'<figure>{body}<figcaption>{html.escape(caption)}</figcaption></figure>')
        self.md.append(f"![{caption}](plots/{fname})\n\n*{caption}*\n")

    def write(self, title):
        css = """body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;max-width:1180px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}h1{border-bottom:2px solid #4e79a7;padding-bottom:.2em}
h2{margin-top:2em;border-bottom:1px solid #ccc}table{border-collapse:collapse;margin:.8em 0;font-size:.86em}
th,td{border:1px solid #ccc;padding:.25em .55em;text-align:right}th{background:#eef3f8}
td:first-child,th:first-child{text-align:left}tbody tr:nth-child(even){background:#fafafa}
figure{margin:1em 0}figure svg{max-width:100%;height:auto}figcaption{font-size:.85em;color:#555}
.note{font-size:.85em;color:#555}.meta{font-size:.85em;background:#f6f6f6;padding:.5em .8em;border-left:3px solid #4e79a7}
nav a{margin-right:1em}.wide{overflow-x:auto;max-width:100%}
table.compact{font-size:.72em}table.compact th,table.compact td{padding:.15em .3em}"""
        page = ["<!DOCTYPE html>", "<html lang=\"en\"><head><meta charset=\"utf-8\">",
                f"<title>{html.escape(title)}</title><style>{css}</style></head><body>",
                f"<h1>{html.escape(title)}</h1>"] + self.html + ["</body></html>"]
        self.files.put(os.path.join(self.out, "index.html"), "\n".join(page) + "\n")
        self.files.put(os.path.join(self.out, "report.md"), f"# {title}\n\n" + "\n".join(self.md) + "\n")
        self.files.commit()


# ---- sections ----------------------------------------------------------------------------------

def engines_ran_text(g):
    """What each engine of a sweep ran, as its measured points record it: its broadphase (an
    engine's own by the registry's class name) and, where recorded, the geometry it collided."""
    seen = {}
    for p in g["points_list"]:
        if p.get("status") != "ok":
            continue
        e = p.get("params", {}).get("engine", "?")
        bp = p.get("engine_broadphase")
        d = seen.setdefault(e, {"broadphase": [], "geometry": []})
        if bp:
            label = OWN_BROADPHASE_CLASS.get(bp, bp)
            if label not in d["broadphase"]:
                d["broadphase"].append(label)
        if p.get("geometry") and p["geometry"] not in d["geometry"]:
            d["geometry"].append(p["geometry"])
    if not seen:
        return ""
    return "Engines ran: " + "; ".join(
        f"{e}: broadphase {', '.join(d['broadphase']) or '?'}"
        + (f", geometry {' | '.join(d['geometry'])}" if d["geometry"] else "") for e, d in seen.items())


def machine_block(doc, g):
    j = g["first"]
    m, b, s = j["machine"], j["build"], j["settings"]
    sw = j["sweep"]
    n_ok = sum(1 for p in g["points_list"] if p.get("status") == "ok")
    total = j.get("points_total", len(g["points_list"]))
    parts = [f"Sweep `{sw['name']}` ({sw.get('kind')}): {sw.get('description', '')}",
             f"Machine: {m.get('cpu')}, host {m.get('hostname')}; GPU: {m.get('gpu')}"
             + (f"; driver: {m.get('driver')}" if m.get("driver") else ""),
             f"Build {b.get('build_id')}, source revision {b.get('git_revision')}; run {j.get('started')} to "
             f"{j.get('updated', '?')}"
             + (f"; load average {', '.join(f'{x:.1f}' for x in m['load_average'])} at the start"
                if m.get("load_average") else "")
             + (f", {', '.join(f'{x:.1f}' for x in m['load_average_end'])} at the end"
                if m.get("load_average_end") else "")
             + (f"; CPU engine on {m['omp_threads']} OpenMP threads" if m.get("omp_threads") else ""),
             f"Settings: engines {', '.join(s.get('engines', []))}; {s.get('repeat')} repetitions per point; "
             f"{s.get('frames')} frames per run (warm-up {s.get('warmup')})"
             + (f", {s.get('warm_replays')} untimed replay(s) first" if "warm_replays" in s else "")
             + (f", each timed repetition at least {s.get('min_time_ms')} ms" if "min_time_ms" in s else "")
             + f"; files: {', '.join(os.path.basename(f) for f in g['files'])}",
             f"Points: {len(g['points_list'])} of {total} in these files ({n_ok} measured)"
             + ("" if len(g["points_list"]) >= total else " — incomplete: missing shards or an interrupted run")]
    ran = engines_ran_text(g)
    if ran:
        parts.append(ran)
    if s.get("repeat") == 1:
        parts.append("1 repetition per point: the figures have no spread, and no verdict (fastest, slower) can be "
                     "taken from them.")
    lw = load_warning(m)
    measured = [p for p in g["points_list"] if p.get("status") == "ok"]
    loaded = [p for p in measured if point_load(p, m)]
    if loaded:
        parts.append(f"⚠ {len(loaded)} of {len(measured)} measured points ran under load (e.g. '{loaded[0]['id']}': "
                     f"{point_load(loaded[0], m)}); the verdicts that use them are marked ⚠."
                     + (f" Run: {lw}." if lw else ""))
    elif lw:
        parts.append(f"Load at the run's start or end: {lw}; no point ran with fewer free cores than its threads, "
                     "so no verdict is marked.")
    doc.html.append('<div class="meta">' + "<br>".join(html.escape(x) for x in parts) + "</div>")
    doc.md.extend("> " + x.replace("`", "") + "  " for x in parts)
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


def steps_points(g):
    return [p for p in g["points_list"] if p.get("status") == "ok" and "windows" in p]


def axis_label(p, axis):
    lab = p.get("params", {}).get("labels", {}).get(axis)
    val = p.get("params", {}).get("axes", {}).get(axis)
    return lab if lab is not None else str(val)


# The engine registry's own broadphases (core/src/engine_registry.cpp: EngineInfo::own_broadphase
# -> own_broadphase_class), for results whose points record only `engine_broadphase`; a test
# (tests/report/test_report_fixes.py) keeps this in step with the registry.
OWN_BROADPHASE_CLASS = {"bullet-dbvt": "btDbvtBroadphase"}


def point_label(p, axis):
    """What point p ran on `axis`: the axis label, or for an axis its engine ignores what the
    engine ran instead (its own broadphase by the registry's class name, "no midphase")."""
    ignores = p.get("ignores")
    if axis and isinstance(ignores, dict) and axis in ignores:
        if axis == "broadphase":
            eb = p.get("engine_broadphase") or ""
            return OWN_BROADPHASE_CLASS.get(eb, eb or "own broadphase")
        if axis == "midphase":
            return "no midphase"
    return axis_label(p, axis) if axis else ""


def engines_of(g):
    return g["first"]["settings"].get("engines", [])


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


def steps_bars(doc, pts, group_axis, title, name, xkey=lambda p: p["params"]["scene"], paper=None):
    """steps/s bars per scene (or xkey): one colour per engine, a hatch per group_axis value,
    each bar after an engine's first value of group_axis labelled with its speed-up over that
    one ("1.8x"); `paper` {(scene, label): FPS} draws the paper's figures (FPS of a whole Unity
    application) in a panel of their own beside ours, never on our steps/s axis."""
    scenes = list(dict.fromkeys(xkey(p) for p in pts))
    vals = list(dict.fromkeys(point_label(p, group_axis) for p in pts))
    engines = list(dict.fromkeys(p["params"]["engine"] for p in pts))
    combos = [(v, e) for e in engines for v in vals
              if any(p["params"]["engine"] == e and point_label(p, group_axis) == v for p in pts)]
    if not scenes or not combos:
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
        colour = ENGINE_COLORS.get(eng, "#777")
        shade = 1.0 - 0.35 * (vals.index(val) / max(len(vals) - 1, 1))  # lighter for later values
        ax.bar(xs, ys, width, yerr=[lo, hi], capsize=2, label=f"{eng} {val}".strip(), color=colour, alpha=shade,
               hatch=HATCHES[vals.index(val) % len(HATCHES)], edgecolor="#222", linewidth=0.6)
        # The speed-up over the engine's first value on this axis, printed over the bar.
        for i, sc in enumerate(scenes):
            mine = fpts.get((sc, eng), {})
            ref_val = next((v for v in vals if v in mine), None)
            if ref_val is None or ref_val == val or val not in mine or not med(mine[ref_val]) or not med(mine[val]):
                continue
            ax.annotate(speedup_text(med(mine[val]) / med(mine[ref_val])), (xs[i], mine[val]["max"]),
                        xytext=(0, 2), textcoords="offset points", ha="center", va="bottom", fontsize=7,
                        rotation=90 if len(combos) > 4 else 0)
    ax.set_xticks(np.arange(len(scenes)))
    ax.set_xticklabels(scenes, rotation=0)
    ax.set_yscale("log")
    log_ticks(ax)
    ax.margins(y=0.15)
    ax.set_ylabel("octocd steps/s (median, bars min–max)")
    ax.set_title("octocd" + (f" (Nx: speed-up over the engine's first {group_axis})" if group_axis else ""),
                 fontsize=9)
    fig.suptitle(title, fontsize=10)
    ax.legend(fontsize=9, ncol=min(len(combos), 4), loc="upper center", bbox_to_anchor=(0.5, -0.1))
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
        pax.set_xticks(np.arange(len(scenes)))
        pax.set_xticklabels(scenes, rotation=30, ha="right", fontsize=7)
        pax.margins(y=0.2)
        pax.set_ylabel("paper FPS (Unity, whole application)")
        pax.set_title("the paper's FPS (its own axis)", fontsize=9)
        pax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.3), ncol=len(paper_vals))
    doc.figure(fig, name, title + ("; the paper's FPS in the right-hand panel, on its own axis" if paper_vals else ""))


def speedup_text(r):
    """A speed-up as printed on plots and in tables: 1.84x, 0.52x."""
    return f"{num(r)}x"


def stage_shares(doc, pts, group_axis, title, name):
    """Per point the share of each stage in the step (bars, %) with the stage's time in ms printed
    in its segment and the step's total ms at the bar's end; the same as a table (ms and %)."""
    rows = [p for p in pts if p.get("has_stage", {}).get("midphase", True)]
    if not rows:
        return
    labels, shares, times = [], [], []
    for p in rows:
        w = first_window(p)
        st = [med(w["stage_ms"].get(s, {})) or 0.0 for s in STAGES]
        tot = sum(st) or 1.0
        shares.append([100.0 * x / tot for x in st])
        times.append(st)
        labels.append(f"{p['params']['scene']} {point_label(p, group_axis)} {p['params']['engine']}")
    fig, ax = plt.subplots(figsize=(9, 0.26 * len(rows) + 1.3))
    left = np.zeros(len(rows))
    arr = np.array(shares)
    for k, s in enumerate(STAGES):
        ax.barh(np.arange(len(rows)), arr[:, k], left=left, color=STAGE_COLORS[k], label=s)
        for i in range(len(rows)):
            if arr[i, k] >= 9.0:  # room for the figure inside the segment
                ax.text(left[i] + arr[i, k] / 2, i, num(times[i][k], 2), ha="center", va="center", fontsize=6,
                        color="black")
        left += arr[:, k]
    for i in range(len(rows)):
        ax.text(101, i, f"{num(sum(times[i]), 3)} ms", ha="left", va="center", fontsize=7)
    ax.set_yticks(np.arange(len(rows)))
    ax.set_yticklabels(labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("share of the step (%); in the segments: the stage's median ms per frame; right: the step's ms")
    ax.set_title(title)
    ax.legend(fontsize=9, ncol=6, loc="upper center", bbox_to_anchor=(0.5, -0.12 - 1.0 / max(len(rows), 4)))
    doc.figure(fig, name, title + " (ms per frame printed in each segment and at the bar's end)")
    doc.table(["point"] + [f"{s} ms (%)" for s in STAGES] + ["sum ms"],
              [[lab] + [f"{num(t, 3)} ({num(sh, 2)}%)" for t, sh in zip(ts, shs)] + [num(sum(ts), 3)]
               for lab, ts, shs in zip(labels, times, shares)],
              "Median ms per frame of each stage over the repetitions, its share of their sum in brackets.",
              name=name)


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


def section_table5(doc, g):
    pts = steps_points(g)
    paper = PAPER["table5"]
    engines = engines_of(g)
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
                    r.append(spread_text(first_window(p)["steps_per_s"]) if p else "-")
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
                r.append("-")
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
               "table5-steps", paper={(sc, c): ref[c][0] for sc, ref in paper["rows"].items() for c in ("A", "B", "C")})
    stage_shares(doc, pts, "midphase", "Table 5: share of each stage in the step", "table5-stages")
    counts = []
    for p in pts:
        w = first_window(p)
        counts.append([p["params"]["scene"], point_label(p, "midphase"), p["params"]["engine"], num(med(w["step_ms"]), 4),
                       num(med(w["pairs"])), num(med(w["box_pairs"])), num(med(w["vertex_tests"])),
                       num(med(w["contacts"]))])
    doc.table(["scene", "config", "engine", "step ms", "AABB pairs", "box pairs", "vertex tests", "contacts"], counts,
              "Per frame, means over the timed frames (median over repetitions).")


def section_table6(doc, g):
    pts = steps_points(g)
    paper = PAPER["table6"]
    engines = engines_of(g)
    doc.p("Relative change ratio RCR = (C - L0) / L0 x 100 % as in the paper; 'inconclusive' when the two min-max "
          "ranges overlap (or one repetition), ⚠ when measured under load. " + paper["source"] + ".")
    rows = []
    for sc, ref in paper["rows"].items():
        r = [f"{sc} ({ref['count']})", f"{ref['L0'][0]} ± {ref['L0'][1]}", f"{ref['C'][0]} ± {ref['C'][1]}",
             f"{ref['rcr']:+.1f}%"]
        for e in engines:
            l0, c = find(pts, scene=sc, engine=e, midphase="L0"), find(pts, scene=sc, engine=e, midphase="C")
            r.append(spread_text(first_window(l0)["steps_per_s"]) if l0 else "-")
            r.append(spread_text(first_window(c)["steps_per_s"]) if c else ("(= L0: no midphase)" if l0 else "-"))
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
               paper={(sc, c): ref[c][0] for sc, ref in paper["rows"].items() for c in ("L0", "C")})
    stage_shares(doc, pts, "midphase", "Table 6: share of each stage in the step", "table6-stages")


def section_tableA1(doc, g):
    pts = steps_points(g)
    paper = PAPER["tableA1"]
    engines = engines_of(g)
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
                        color=ENGINE_COLORS.get(p["params"]["engine"], "#333"),
                        linestyle="-" if bp == "O-A" else "--")
            ax.set_title(mesh)
            ax.set_xlabel("frame")
            ax.set_yscale("log")
            log_ticks(ax)
        axes[0][0].set_ylabel("steps/s per 100 frames")
        h, l = axes[0][0].get_legend_handles_labels()
        fig.legend(h, l, fontsize=9, ncol=min(len(l), 6), loc="upper center", bbox_to_anchor=(0.5, -0.02))
        fig.tight_layout()
        doc.figure(fig, "tableA1-series", "Table A1 / Fig. 5: steps/s over the 3000 frames, spatial hash (dashed) vs "
                   "octree (solid), per mesh and engine (median over repetitions of each 100-frame block)")
    steps_bars(doc, [dict(p, windows={"late": p["windows"]["late"]}) for p in pts if "late" in p["windows"]],
               "broadphase", "Table A1, late phase: steps/s per mesh, SH vs O-A, per engine", "tableA1-late",
               xkey=lambda p: p["params"]["axes"].get("mesh", p["params"]["scene"]))
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
    for e in engines:
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
    fig, ax = plt.subplots(figsize=(8, 5))
    cmap = plt.get_cmap("tab20")
    rows = []
    sizes = sorted({p["bodies"] for p in pts})
    for k, (key, ps) in enumerate(sorted(series.items())):
        ps = sorted(ps, key=lambda p: p["bodies"])
        xs = np.array([p["bodies"] for p in ps], dtype=float)
        ys = np.array([med(p["ms_per_frame"]) for p in ps], dtype=float)
        lo = ys - np.array([p["ms_per_frame"]["min"] for p in ps])
        hi = np.array([p["ms_per_frame"]["max"] for p in ps]) - ys
        ax.errorbar(xs, ys, yerr=[lo, hi], marker="o", ms=3, capsize=2, label=f"{key[0]} {key[1]}",
                    color=cmap(k % 20), linestyle="-" if key[0] == "cpu" else "--")
        good = ys > 0
        sl = slope(xs[good], ys[good]) if good.sum() >= 2 else float("nan")
        ns = [p["params"].get("bodies", p["bodies"]) for p in ps]  # lattice sizes asked (walls apart)
        last = math.log2(ys[-1] / ys[-2]) if len(ys) >= 2 and ys[-2] > 0 and ns[-1] == 2 * ns[-2] else float("nan")
        by = {p["bodies"]: p for p in ps}
        rows.append([key[0], key[1]] + [num(med(by[s]["ms_per_frame"]), 3) if s in by else "-" for s in sizes]
                    + [f"{sl:.2f}" if not math.isnan(sl) else "-", f"{last:.2f}" if not math.isnan(last) else "-",
                       "yes" if all(p.get("matches_recorded", True) for p in ps) else "NO"])
    ax.set_xscale("log")
    ax.set_yscale("log")
    log_ticks(ax, "x")
    log_ticks(ax, "y")
    ax.set_xlabel("bodies")
    ax.set_ylabel("broadphase ms per frame")
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
    engines = [e for e in ("cpu", "cuda", "bullet") if e in named] + [e for e in named if e not in ENGINE_COLORS]
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
    if pts:
        fig, ax = plt.subplots(figsize=(8, 4.6))
        cmap = plt.get_cmap("tab10")
        keys = list(dict.fromkeys((p["params"]["scene"], p["params"]["engine"]) for p in pts))
        for k, key in enumerate(keys):
            mine = [p for p in pts if (p["params"]["scene"], p["params"]["engine"]) == key]
            for role, style in (("probe", "o"), ("confirm", "x")):
                ps = sorted((p for p in mine if p.get("role", "probe") == role),
                            key=lambda p: p["params"]["axes"]["instances"])
                if not ps:
                    continue
                xs = [p["params"]["axes"]["instances"] for p in ps]
                ys = [med(first_window(p)["steps_per_s"]) for p in ps]
                ax.plot(xs, ys, marker=style, ms=3 if role == "probe" else 6, color=cmap(k % 10),
                        label=f"{key[0]} {key[1]}" + (" (bracket ends, confirmed)" if role == "confirm" else ""),
                        linestyle={"cpu": "-", "cuda": "--"}.get(key[1], ":") if role == "probe" else "none")
        ax.axhline(target, color="black", linewidth=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        log_ticks(ax, "x")
        log_ticks(ax, "y")
        ax.set_xlabel("instances")
        ax.set_ylabel("steps/s over the window (median; cut probes: upper bound)")
        ax.set_title(f"Probes of the search; the line is the target {target:g} steps/s")
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        doc.figure(fig, "max-instances-probes", "max-instances: every probe's steps/s against its instance count "
                   "(solid cpu, dashed cuda, dotted bullet; x: the bracket's ends measured again)")


def section_generic(doc, g):
    rows = []
    for p in g["points_list"]:
        if p.get("status") != "ok":
            continue
        if "windows" in p:
            for wn, w in p["windows"].items():
                rows.append([p["id"], wn, spread_text(w["steps_per_s"]), num(med(w["step_ms"]), 4), num(med(w["pairs"])),
                             num(med(w["contacts"])), num(med(w["penetration_mean"]) * 1e3)])
        elif "ms_per_frame" in p:
            rows.append([p["id"], "replay", "-", spread_text(p["ms_per_frame"]), num(p.get("pairs")), "-", "-"])
    doc.table(["point", "window", "steps/s", "step ms", "pairs", "contacts", "mean d_p (mm)"], rows)
    pts = steps_points(g)
    if pts:
        axis = next(iter(pts[0]["params"].get("axes", {})), None)
        steps_bars(doc, pts, axis, f"{g['first']['sweep']['name']}: steps/s", "sweep-steps")
        stage_shares(doc, pts, axis, f"{g['first']['sweep']['name']}: stage shares", "sweep-stages")


TRACE_COLORS = ["#4e79a7", "#e15759", "#59a14f", "#f28e2b", "#76b7b2", "#b07aa1", "#9c755f", "#edc948"]


TRACE_COLUMNS = ("frame", "step_ms", "contacts", "aabb_pairs", "kinetic_energy", "penetration_mean",
                 "penetration_max")


def read_trace(path):
    """The /frames columns of one trace (its complete rows: at most committed_frames) and its
    attributes, from `octocd trace-summary --json` (octocd's hardened reader: external
    links, external storage, virtual datasets, FIFOs and corrupt files are refused, exit 2
    naming the file and dataset)."""
    octocd = OCTOCD[0]
    if not octocd:
        print("octocd report: runtime failure: traces are read by the octocd binary (`octocd trace-summary`): give "
              "--octocd PATH or put octocd on PATH", file=sys.stderr)
        sys.exit(1)
    try:
        r = subprocess.run([octocd, "trace-summary", "--json", "--", path], capture_output=True, text=True)
    except OSError as e:
        print(f"octocd report: runtime failure: cannot run {octocd} ({e.strerror})", file=sys.stderr)
        sys.exit(1)
    if r.returncode == 2:
        msg = r.stderr.strip().splitlines()[-1] if r.stderr.strip() else f"{path}: refused"
        for prefix in ("octocd: error: ", "error: "):
            msg = msg[len(prefix):] if msg.startswith(prefix) else msg
        fail(msg if path in msg else f"{path}: {msg}")
    if r.returncode != 0:
        why = f"killed by signal {-r.returncode}" if r.returncode < 0 else f"exit {r.returncode}"
        print(f"octocd report: runtime failure: {path}: `octocd trace-summary` {why}: {r.stderr.strip()[-500:]}",
              file=sys.stderr)
        sys.exit(1)
    j = json.loads(r.stdout)
    n = int(j["frames"])
    cols = {}
    for k in TRACE_COLUMNS:
        v = j["columns"].get(k)
        cols[k] = np.array([np.nan if x is None else x for x in v], dtype=float) if v is not None else np.zeros(n)
    attrs = {k: j["attributes"].get(k) for k in ("scene_name", "engine", "broadphase", "midphase", "body_count",
                                                 "device", "build_id", "start_time")}
    return {"path": path, "n": n, "cols": cols, "attrs": attrs}


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
    """One table row per trace, and the traces overlaid on shared axes (one colour each)."""
    traces = []
    for path in paths:
        CURRENT[0] = path
        traces.append(read_trace(path))
    doc.h(2, "Traces" if len(traces) > 1 else f"Trace {os.path.basename(paths[0])}")
    rows = []
    for t in traces:
        a, n, c = t["attrs"], t["n"], t["cols"]
        step = c["step_ms"]
        doc.p(f"{os.path.basename(t['path'])}: scene {a.get('scene_name')}, engine {a.get('engine')}, broadphase "
              f"{a.get('broadphase')}, midphase {a.get('midphase')}, {a.get('body_count')} bodies, {n} frames; device "
              f"{a.get('device')}; build {a.get('build_id')}; started {a.get('start_time')}.")
        comment = penetration_comment(c, os.path.basename(t["path"]))
        if comment:
            doc.p(comment)
        rows.append([os.path.basename(t["path"]), n, num(1000.0 * n / step.sum()) if step.sum() > 0 else "-",
                     num(step.mean(), 4) if n else "-", num(c["contacts"].mean()) if n else "-",
                     int(c["contacts"].max()) if n else "-", num(1e3 * c["penetration_max"].max()) if n else "-",
                     num(c["kinetic_energy"][-1]) if n else "-"])
    doc.table(["trace", "frames", "steps/s", "mean step ms", "mean contacts", "max contacts", "max d_p (mm)",
               "final kinetic energy (J)"], rows, name="traces")
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), sharex=True)
    for k, t in enumerate(traces):
        c, col = t["cols"], TRACE_COLORS[k % len(TRACE_COLORS)]
        lab = os.path.basename(t["path"])
        axes[0].plot(c["frame"], c["kinetic_energy"], color=col, label=lab)
        axes[1].plot(c["frame"], c["contacts"], color=col, label=f"{lab} contacts")
        axes[1].plot(c["frame"], c["aabb_pairs"], color=col, linestyle=":", label=f"{lab} AABB pairs")
        axes[2].plot(c["frame"], 1e3 * c["penetration_max"], color=col, label=f"{lab} max")
        axes[2].plot(c["frame"], 1e3 * c["penetration_mean"], color=col, linestyle="--", alpha=0.7,
                     label=f"{lab} mean")
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

GATE_MIN_REPS = 5


def u_null_sf_counts(m, n):
    """Counts of U = 0 .. m*n under H0 for samples of m and n (no ties): the coefficients of
    the Gaussian binomial [m+n choose m]_q = prod_{i=1..m} (1 - q^(n+i)) / (1 - q^i)."""
    c = [1] + [0] * (m * n)
    for i in range(1, m + 1):
        for k in range(m * n, n + i - 1, -1):  # times (1 - q^(n+i))
            c[k] -= c[k - n - i]
        for k in range(i, m * n + 1):  # divided by (1 - q^i)
            c[k] += c[k - i]
    return c


def u_critical(m, n, alpha):
    """The smallest c with P(U >= c) <= alpha under H0, or None when no c is (too few repetitions)."""
    counts = u_null_sf_counts(m, n)
    total, tail = sum(counts), 0
    for c in range(m * n, -1, -1):
        if (tail + counts[c]) / total > alpha:
            return c + 1 if c + 1 <= m * n else None
        tail += counts[c]
    return 0


def ratio_interval(new_t, base_t, alpha):
    """Hodges-Lehmann ratio new/base with its 1 - 2 alpha interval (from U's critical value)."""
    d = sorted(math.log(x) - math.log(y) for x in new_t for y in base_t)
    mn = len(d)
    c = u_critical(len(new_t), len(base_t), alpha)
    est = math.exp(float(np.median(d)))
    if c is None:
        return est, 0.0, math.inf
    return est, math.exp(d[mn - c]), math.exp(d[c - 1])


def gate_test(new_t, base_t, threshold, alpha):
    """One figure: (verdict, p_slower, ratio, lo, hi). p_slower: one-sided Mann-Whitney U of
    new times against baseline times x (1 + threshold/100)."""
    from scipy.stats import mannwhitneyu
    f = 1.0 + threshold / 100.0
    scaled = [y * f for y in base_t]
    p_slow = float(mannwhitneyu(new_t, scaled, alternative="greater", method="exact").pvalue)
    p_fast = float(mannwhitneyu([x * f for x in new_t], base_t, alternative="less", method="exact").pvalue)
    ratio, lo, hi = ratio_interval(new_t, base_t, alpha)
    if p_slow < alpha:
        verdict = "SLOWER"
    elif p_fast < alpha:
        verdict = "faster"
    elif lo >= 1.0 / f and hi <= f:
        verdict = "same"
    else:
        verdict = "not shown slower"
    return verdict, p_slow, ratio, lo, hi


def timing_of(p, cpu=False):
    """[(label, spread, higher_is_better)] of a point: steps/s per window (with cpu: steps per
    process CPU second, where the point has them), or replay ms/frame."""
    out = []
    if isinstance(p.get("windows"), dict):
        for wn, w in p["windows"].items():
            if cpu and isinstance(w, dict) and "cpu_steps_per_s" in w:
                out.append((f"CPU steps/s ({wn})", w["cpu_steps_per_s"], True))
            else:
                out.append((f"steps/s ({wn})", w.get("steps_per_s") if isinstance(w, dict) else None, True))
    elif "ms_per_frame" in p:
        out.append(("broadphase ms/frame", p["ms_per_frame"], False))
    return out


def has_cpu_timing(p):
    w = p.get("windows")
    return isinstance(w, dict) and bool(w) and all(isinstance(x, dict) and "cpu_steps_per_s" in x for x in w.values())


def machine_text(j):
    m, b = j["machine"], j["build"]
    return f"{m.get('hostname')} ({m.get('cpu')}), build {b.get('build_id')}"


def finite_positive(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0


def repetitions(spread, where, side_file):
    """The raw repetitions of a spread, checked against its stored summary (median, min, max,
    n): a summary that does not match its repetitions (an edited or forged file) is bad input.
    Values may be non-finite or <= 0 (the caller judges them)."""
    if not isinstance(spread, dict) or not isinstance(spread.get("values"), list):
        fail(f"{side_file}: {where}.values: missing; allowed: a spread with its repetitions (octocd bench writes "
             "them; the gate decides on the repetitions, never on stored ranges)")
    vals = spread["values"]
    nums = [v for v in vals if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)]
    if len(nums) == len(vals) and vals:
        expect = {"n": len(vals), "median": float(np.median(vals)), "min": min(vals), "max": max(vals)}
        for k, e in expect.items():
            got = spread.get(k)
            if not isinstance(got, (int, float)) or isinstance(got, bool) or \
                    not math.isclose(got, e, rel_tol=1e-9, abs_tol=1e-300):
                fail(f"{side_file}: {where}.{k}: {got!r}, but its {len(vals)} repetitions give {e!r}; allowed: a "
                     "summary that matches its values (an edited or forged result is refused)")
    elif spread.get("n") != len(vals):
        fail(f"{side_file}: {where}.n: {spread.get('n')!r}, but it holds {len(vals)} values; allowed: n = the "
             "number of values")
    return vals


def check_same_sweep(base, new, across):
    bj, nj = base["first"], new["first"]
    for key, what in (("name", "sweep.name"), ("definition", "sweep.definition")):
        if bj["sweep"].get(key) != nj["sweep"].get(key):
            fail(f"{base['files'][0]}: {what}: baseline of another sweep ({bj['sweep'].get('name')!r} vs "
                 f"{nj['sweep'].get('name')!r} in {new['files'][0]}); allowed: a baseline of the same sweep definition")
    bm, nm = bj["machine"], nj["machine"]
    if (bm.get("hostname"), bm.get("cpu")) != (nm.get("hostname"), nm.get("cpu")) and not across:
        fail(f"{new['files'][0]}: machine: {nm.get('hostname')!r} ({nm.get('cpu')}), but the baseline "
             f"{base['files'][0]} ran on {bm.get('hostname')!r} ({bm.get('cpu')}); allowed: runs of one machine, or "
             "--across-machines (a ratio then mixes the machines' speed with the builds')")
    return (bm.get("hostname"), bm.get("cpu")) != (nm.get("hostname"), nm.get("cpu"))


def stopped_text(g):
    """Why a side's result is not a finished run ('' when it is)."""
    why = []
    for path in g["files"]:
        j = g["json"][path]
        if j.get("stopped"):
            why.append(f"{path}: stopped by {j['stopped']}")
        elif j.get("complete") is not True:
            why.append(f"{path}: complete: {json.dumps(j.get('complete'))} (an interrupted or unfinished run)")
    return "; ".join(why)


def gate_decide(base, new, threshold, alpha, across=False, timing="auto"):
    """NEW beside BASE per point and timing figure. Returns a dict: rows (one per point and
    figure, numbers), broken (points of the baseline the new run lacks, failed, skipped or
    measured as non-finite or <= 0: exit 4), few (figures with < 5 repetitions a side: exit 2),
    slower (rows SLOWER: exit 4), across, notes. Bad input (another sweep, another machine
    without `across`, a forged summary, a broken baseline) exits 2 here."""
    across = check_same_sweep(base, new, across)
    bwhy = stopped_text(base)
    if bwhy:
        fail(f"--baseline: {bwhy}; allowed: a finished run of `octocd bench` as the baseline")
    out = {"rows": [], "broken": [], "few": [], "slower": [], "across": across, "notes": []}
    nwhy = stopped_text(new)
    if nwhy:
        out["broken"].append(("the new run", f"not a finished run: {nwhy}"))
    newp = new["points"]
    def runs_of(g, pid):
        """[(file, point)] of a point: one per run of the side (several runs pooled)."""
        return g["pooled"].get(pid) or [(g["origin"][pid], g["points"][pid])]

    for q in base["points_list"]:
        st = {x.get("status") for _, x in runs_of(base, q["id"])}
        if "ok" in st and len(st) > 1:
            fail(f"--baseline: '{q['id']}': ok in some runs, {', '.join(sorted(st - {'ok'}))} in others "
                 f"({', '.join(f for f, _ in runs_of(base, q['id']))}); allowed: a baseline whose runs measured it")
    base_ok = [p for p in base["points_list"] if p.get("status") == "ok"]
    if not base_ok:
        fail(f"--baseline {base['files'][0]}: no measured point (every point failed or skipped); allowed: a baseline "
             "with measured points")
    for q in base_ok:
        pid = q["id"]
        bfile = base["origin"][pid]
        p = newp.get(pid)
        if p is None:
            out["broken"].append((pid, "missing in the new run"))
            continue
        nfile = new["origin"][pid]
        bad = [(f, x) for f, x in runs_of(new, pid) if x.get("status") != "ok"]
        if bad:
            f, x = bad[0]
            out["broken"].append((pid, f"{x.get('status')} in the new run ({f}): {x.get('reason', 'no reason')}"))
            continue
        # Steps per process CPU second where both runs have them (host engines: the load of
        # other processes on a shared machine hardly moves them), else wall-clock steps/s.
        cpu = timing == "cpu" or (timing == "auto" and has_cpu_timing(q) and has_cpu_timing(p))
        if timing == "cpu" and not (has_cpu_timing(q) and has_cpu_timing(p)):
            fail(f"--timing cpu: '{pid}' has no cpu_steps_per_s in "
                 + (base["origin"][pid] if not has_cpu_timing(q) else new["origin"][pid])
                 + "; allowed: results of a bench that records them (host engines), or --timing auto|wall")
        bt, nt = timing_of(q, cpu), timing_of(p, cpu)
        if [x[0] for x in bt] != [x[0] for x in nt]:
            out["broken"].append((pid, f"the new run ({nfile}) has figures {[x[0] for x in nt]}, the baseline "
                                       f"{[x[0] for x in bt]}"))
            continue
        i = next(k for k, x in enumerate(base["points_list"]) if x["id"] == pid)
        for k, ((label, bs, hib), (_, ns, _)) in enumerate(zip(bt, nt)):
            key = ("cpu_steps_per_s" if label.startswith("CPU") else "steps_per_s") if hib else "ms_per_frame"
            # Every run of a side: its repetitions pooled (each run's summary checked).
            bv, nv = [], []
            for side, vals in ((base, bv), (new, nv)):
                for f, x in runs_of(side, pid):
                    tx = timing_of(x, cpu)
                    if k >= len(tx) or tx[k][0] != label:
                        out["broken"].append((pid, f"{f} has figures {[t[0] for t in tx]}, expected {label}"))
                        continue
                    vals += repetitions(tx[k][1], f"point '{pid}' {label}", f)
            bad_b = [v for v in bv if not finite_positive(v)]
            if bad_b:
                fail(f"{bfile}: points[{i}] '{pid}' {label}: repetition(s) {bad_b[:3]}; allowed: finite figures > 0 "
                     "in the baseline")
            bad_n = [v for v in nv if not finite_positive(v)]
            if bad_n or not nv:
                out["broken"].append((pid, f"{label} in the new run ({nfile}): "
                                           + (f"repetition(s) {', '.join(str(v) for v in bad_n[:3])}: not finite "
                                              "and > 0" if bad_n else "no repetitions")))
                continue
            if min(len(bv), len(nv)) < GATE_MIN_REPS:
                out["few"].append((pid, label, len(bv), len(nv)))
                continue
            bt_s = [1.0 / v for v in bv] if hib else list(bv)
            nt_s = [1.0 / v for v in nv] if hib else list(nv)
            verdict, pval, ratio, lo, hi = gate_test(nt_s, bt_s, threshold, alpha)
            row = {"point": pid, "figure": label, "key": key, "base": bv, "new": nv, "base_median": float(np.median(bv)),
                   "new_median": float(np.median(nv)), "ratio": ratio, "lo": lo, "hi": hi, "p": pval,
                   "verdict": verdict}
            out["rows"].append(row)
            if verdict == "SLOWER":
                out["slower"].append(row)
    base_ids = {p["id"] for p in base_ok}
    extra = [p["id"] for p in new["points_list"] if p["id"] not in base_ids and p.get("status") == "ok"]
    if extra:
        out["notes"].append(f"{len(extra)} point(s) of the new run not measured in the baseline (not gated): "
                            + ", ".join(extra))
    return out


def section_gate(doc, base, new, threshold, alpha, across, timing="auto"):
    """The gate's section of the report; returns gate_decide's result."""
    res = gate_decide(base, new, threshold, alpha, across, timing)
    bj, nj = base["first"], new["first"]
    doc.section = "gate"
    doc.h(2, f"Performance gate: {nj['sweep']['name']}", "gate")
    conf = 100.0 * (1.0 - 2.0 * alpha)
    doc.p(f"Baseline: {machine_text(bj)}, {', '.join(os.path.basename(f) for f in base['files'])}. "
          f"New: {machine_text(nj)}, {', '.join(os.path.basename(f) for f in new['files'])}. "
          + (f"Across machines (--across-machines): {bj['machine'].get('hostname')} vs "
             f"{nj['machine'].get('hostname')}: a ratio mixes the machines' speed with the builds'. "
             if res["across"] else "Same machine. ")
          + f"Ratio = new time / baseline time (> 1 slower): the median of the pairwise ratios of the repetitions "
          f"(Hodges-Lehmann) with its {conf:g} % interval. A figure is SLOWER (exit 4) when the one-sided "
          f"Mann-Whitney U test of the new times against the baseline times x {1 + threshold / 100:g} rejects at level "
          f"{alpha:g} (p < {alpha:g}): slower by more than {threshold:g} % with confidence; 'same' when the interval "
          f"lies within {threshold:g} % either way; 'not shown slower' otherwise (passes). At least "
          f"{GATE_MIN_REPS} repetitions a side; a baseline point the new run lacks, failed, skipped or measured as "
          "non-finite or <= 0 fails the gate (exit 4).")
    warn = [f"{side}: {w}" for side, w in (("baseline", load_warning(bj["machine"])),
                                            ("new", load_warning(nj["machine"]))) if w]
    rows = [[r["point"], r["figure"], f"{num(r['base_median'])} (n={len(r['base'])})",
             f"{num(r['new_median'])} (n={len(r['new'])})", f"{r['ratio']:.3f}", f"{r['lo']:.3f}–{r['hi']:.3f}",
             f"{r['p']:.3g}", (load_mark(bj["machine"], base["points"].get(r["point"]))
                               or load_mark(nj["machine"], new["points"].get(r["point"]))
                               if r["verdict"] != "same" else "") + r["verdict"]] for r in res["rows"]]
    rows += [[pid, "", "", "", "", "", "", "FAILED: " + why] for pid, why in res["broken"]]
    doc.table(["point", "figure", "baseline median", "new median", "ratio (time)", f"{conf:g} % interval",
               "p (slower)", "verdict"], rows,
              ("Measured under load: " + "; ".join(warn) + ". " if warn else "") + " ".join(res["notes"]),
              name="gate")
    counts = {}
    for r in res["rows"]:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    doc.p("Verdicts: " + ", ".join(f"{v} {c}" for v, c in sorted(counts.items()))
          + (f", FAILED {len(res['broken'])}" if res["broken"] else "") + "." if counts or res["broken"]
          else "No point measured in both runs.")
    if doc.csv_dir:
        gate_csv(doc, os.path.join(doc.csv_dir, "gate.csv"), res)
        doc.ncsv += 1
    return res


# ---- CSV: the data, numbers only ---------------------------------------------------------------

CSV_UNITS = {"steps_per_s": "1/s", "cpu_steps_per_s": "1/s", "step_ms": "ms", "stage_ms": "ms", "pairs": "1/frame",
             "cell_candidates": "1/frame", "box_pairs": "1/frame", "vertex_tests": "1/frame", "contacts": "1/frame",
             "memory_bytes": "B", "penetration_mean": "m", "penetration_max": "m",
             "penetration_share_above_slop": "1", "wall_s": "s", "ms_per_frame": "ms"}


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
        w = csv.writer(f)
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


def gate_summary(res, threshold, alpha):
    """The gate's verdict on stdout: every failed and every slower point named."""
    conf = 100.0 * (1.0 - 2.0 * alpha)
    for pid, why in res["broken"]:
        print(f"octocd report: gate: FAILED: {pid}: {why}")
    for r in res["slower"]:
        print(f"octocd report: gate: SLOWER: {r['point']}: {r['figure']}: time ratio {r['ratio']:.3f} "
              f"({conf:g} % interval {r['lo']:.3f}-{r['hi']:.3f}; Mann-Whitney U p = {r['p']:.3g} against "
              f"{1 + threshold / 100:g}x)")
    n = len(res["rows"])
    if res["broken"]:
        print(f"octocd report: gate: FAILED: {len(res['broken'])} point(s) of the baseline missing, failed, skipped "
              f"or not measured in the new run" + (f"; {len(res['slower'])} of {n} figure(s) SLOWER" if res["slower"]
                                                  else ""))
    elif res["slower"]:
        print(f"octocd report: gate: FAILED: {len(res['slower'])} of {n} figure(s) SLOWER by more than "
              f"{threshold:g} % (one-sided Mann-Whitney U, level {alpha:g})")
    else:
        print(f"octocd report: gate: passed: {n} figure(s), none shown slower by more than {threshold:g} % "
              f"(one-sided Mann-Whitney U, level {alpha:g})")


def gate_csv(doc, path, res):
    """The gate as data: per point and figure one row per side and repetition (kind rep) and
    one summary row (kind summary: both medians, ratio, interval, p, slower 0/1)."""
    f = io.StringIO(newline="")
    if True:
        w = csv.writer(f)
        w.writerow(["point", "figure", "kind", "side", "repetition", "value", "unit", "base_median", "new_median",
                    "ratio_time", "ratio_lo", "ratio_hi", "p_slower", "slower"])
        for r in res["rows"]:
            unit = "ms" if r["key"] == "ms_per_frame" else "1/s"
            for side in ("base", "new"):
                for k, v in enumerate(r[side]):
                    w.writerow([r["point"], r["figure"], "rep", side, k, repr(float(v)), unit] + [""] * 7)
            w.writerow([r["point"], r["figure"], "summary", "", "", "", unit, repr(r["base_median"]),
                        repr(r["new_median"]), repr(r["ratio"]), repr(r["lo"]), repr(r["hi"]), repr(r["p"]),
                        int(r["verdict"] == "SLOWER")])
    doc.files.put(path, f.getvalue())


SECTIONS = {"table5": ("Table 5: midphase configurations A, B, C", section_table5),
            "table6": ("Table 6: Level 0 (AABB only) vs hierarchical C", section_table6),
            "tableA1": ("Table A1: spatial hash vs octree, early and late phases", section_tableA1),
            "figA2": ("Fig. A2: penetration for beta x delta", section_figA2),
            "broadphase-scaling": ("Broadphase scaling", section_scaling),
            "max-instances": ("Most instances at 30 steps/s (paper section 5.3)", section_max_instances)}


CURRENT = ["the inputs"]  # the file being read, for the one-line error of a malformed one
OCTOCD = [None]  # the octocd binary that reads traces (--octocd)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--title", default="octocd benchmark report")
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
    ap.add_argument("inputs", nargs="+")
    a = ap.parse_args()
    OCTOCD[0] = a.octocd
    output_dir(a.output, "-o")
    if a.csv:
        output_dir(a.csv, "--csv")
    if not (0 <= a.threshold < 1000) or math.isnan(a.threshold):
        fail(f"--threshold: {a.threshold}; allowed: a percentage in [0, 1000)")
    if not (0 < a.level <= 0.25):
        fail(f"--level: {a.level}; allowed: a significance level in (0, 0.25]")
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
            pid, label, nb, nn = gate["few"][0]
            fail(f"too few repetitions to decide: '{pid}' {label} has {nb} in the baseline and {nn} in the new run"
                 + (f" (and {len(gate['few']) - 1} more figure(s))" if len(gate["few"]) > 1 else "")
                 + f"; allowed: >= {GATE_MIN_REPS} repetitions a side (octocd bench --repeat {GATE_MIN_REPS})")
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
        nav.append((f"s{i}", title))
        doc.section = name
        CURRENT[0] = ", ".join(g["files"])
        doc.h(2, title, f"s{i}")
        machine_block(doc, g)
        fn(doc, g)
        skipped_block(doc, g)
        if doc.csv_dir:
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
    130), never a traceback (scripts/fuzz_report_json.py fuzzes it so)."""
    try:
        main()
    except SystemExit:
        raise
    except KeyboardInterrupt:  # SIGINT (octocd report forwards it): nothing was committed
        print("octocd report: stopped by SIGINT; the earlier report (if any) is left as it was", file=sys.stderr)
        sys.exit(130)
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
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, ZeroDivisionError) as e:
        # A result that passed the format check but holds something else where a figure should be.
        fail(f"{CURRENT[0]}: malformed result ({type(e).__name__}: {e}); allowed: a result of octocd bench as "
             "docs/bench-format.md describes it")


if __name__ == "__main__":
    run()
