"""`octocd report --history DIR` (design.md section 21; docs/regression.md): a history folder
(one octocd-history file per run: `bench --history`, `scripts/nightly.sh --history`,
`octocd history-append`) drawn on one static page, OUT/index.html (every plot a PNG inline,
no network), with its data as CSV beside it:

- per machine (machines are never mixed: a change of machine is not a change point), the
  steps/s of every point and window of every steps sweep over the runs that measured it:
  the median of the repetitions and their min-max;
- change points of each such series found by binary segmentation with a rank test (below),
  steps merged into windows (a creep of some percent a night is found as a change over the
  nights it crept);
- the engine matrix's verdicts (pass, expected, new, fixed, n/a) as a grid of engine x scene x
  row against night, and the night each current failure appeared, with its commit.

The change-point test. A series is x_1..x_n = log(median steps/s) over its runs. For every
split t in [M, n - M] (M = MIN_SEGMENT nights on each side) the Mann-Whitney rank-sum of the
first t values, standardized under exchangeability: z_t = |sum_{i<=t} r_i - t(n+1)/2| /
sqrt(t(n-t)(n+1)/12) (r the ranks). Z = max_t z_t; its p-value is the approximation of James,
James and Siegmund (1987, Biometrika 74: 71-83) for the maximum of the standardized Brownian
bridge over [M/n, 1 - M/n]: p = Z phi(Z) [(1 - Z^-2) log(((n-M)/M)^2) + 4 Z^-2] (a
continuous-time bound: conservative for the n discrete splits). A series is split where
z_t is largest when p <= level / S (S the machine's series: the level is family-wise over
them, Bonferroni), and each part is searched again the same way (binary segmentation).
The rank test makes no assumption on the noise's law (heavy tails of a loaded machine); the
smallest step it sees half the time, for Gaussian noise of standard deviation s (estimated
robustly as 1.4826 MAD of successive differences / sqrt 2), at a split with t and n - t nights
on either side: delta = s sqrt(2) PhiInv(1/2 + b / sqrt(12 t (n-t) / (n+1))), b the critical
z; the page gives it at mid-history and for a change 10 nights before the last.

Every file of the folder is untrusted: read by report_data's strict JSON reader, checked
field by field; a damaged or foreign file is named (on stderr and on the page) and
skipped, never fatal. Text from the files (names, reasons, machine strings, commits) is
cut to MAX_TEXT_SHOWN characters and escaped (HTML), and a CSV text cell that starts with
= + - @ (or a tab or carriage return) gets a leading apostrophe (no formula injection).
"""

import base64
import csv
import datetime
import functools
import html
import io
import math
import os
import stat
import sys

from report_common import STOP, Stopped, csv_guard, fail, np, plt, printable
from report_data import _parse
from report_html import Outputs
from report_plots import engine_colour, engine_marker, log_ticks

MIN_SEGMENT = 3         # nights on each side of a split
MAX_RAMP = 30          # nights on either side of a change point a ramp may span
MERGE_GAP = 10          # change points of one direction with fewer nights than this between them: one window
MAX_CHANGES = 64        # change points per series (a search stops there)
MAX_FILE_BYTES = 64 << 20
MAX_FILES = 100000
MAX_TEXT_SHOWN = 200    # characters of a name, reason, machine or commit on the page and in CSV
MAX_GRID_ROWS = 300     # rows of a verdict grid drawn (every row is in the CSV)
MAX_SERIES_PLOTS = 100  # series drawn per machine (those with a change first); every one is in the CSV
MAX_CHANGE_ROWS = 500   # rows of a machine's table of changes on the page (every one is in the CSV)
DPI = 100               # the plots' pixels per inch: a font of FONT_PT points is FONT_PT x 100/72 px
FONT_PT = 8             # the smallest font on a plot: 11 px
STATUSES = ["pass", "expected", "new", "fixed", "n/a", "error"]
# Okabe-Ito (colour-blind safe): pass bluish green, expected yellow, new vermillion, fixed
# blue, n/a grey, error (the case gave no verdict: crashed, timed out) black; white where a
# run has no such row.
STATUS_COLORS = {"pass": "#009E73", "expected": "#F0E442", "new": "#D55E00", "fixed": "#0072B2",
                 "n/a": "#BBBBBB", "error": "#000000", "": "#FFFFFF"}


class Skip(Exception):
    """A history file that is damaged or not a history file: named and skipped."""


def _skip(msg):
    raise Skip(msg)


@functools.lru_cache(maxsize=65536)
def _short(text, limit):
    return printable(text, limit).replace("\n", " ")


def short(text, limit=MAX_TEXT_SHOWN):
    """Untrusted text for the page and the CSV: one line, printable, at most `limit` characters
    (cached: the same names recur every night)."""
    return _short(str(text), limit)


def short_lines(text, limit=40):
    """A label of several lines (run_label): each line short()."""
    return "\n".join(short(line, limit) for line in str(text).split("\n"))


def csv_cell(v):
    """A CSV cell: numbers as they are, text shortened and, when it starts with = + - @ tab or
    CR, behind an apostrophe (a spreadsheet reads no formula from it)."""
    if isinstance(v, bool) or v is None:
        return "" if v is None else str(v).lower()
    if isinstance(v, (int, float, np.integer, np.floating)):
        return repr(float(v)) if isinstance(v, (float, np.floating)) else str(int(v))
    return csv_guard(short(v))


def csv_text(header, rows):
    f = io.StringIO(newline="")
    w = csv.writer(f)
    w.writerow(header)
    for r in rows:
        w.writerow([csv_cell(x) for x in r])
    return f.getvalue()


# ---------------------------------------------------------------- reading the folder

def _text(v, field, path):
    if not isinstance(v, str):
        _skip(f"{path}: {field}: {type(v).__name__}, not text; allowed: an octocd-history file (docs/regression.md)")
    return v


def _spread(s):
    """(median, min, max, n) of a spread, or None when it is not one with finite positive figures."""
    if not isinstance(s, dict):
        return None
    try:
        med, lo, hi = float(s["median"]), float(s.get("min", s["median"])), float(s.get("max", s["median"]))
        n = int(s.get("n", 1))
    except (KeyError, TypeError, ValueError, OverflowError):
        return None
    if not all(math.isfinite(x) and x > 0 for x in (med, lo, hi)) or not lo <= med <= hi:
        return None
    return med, lo, hi, n


def read_entry(path, raw, timing="wall"):
    """One history file's run: {date, commit, version, machine, series: {(sweep, point,
    window): (median, min, max, n)}, verdicts: {(engine, scene, row): (status, reason)}},
    or Skip naming the file and the field. `timing`: wall (steps_per_s), cpu
    (cpu_steps_per_s: steps per process CPU second, hardly moved by other processes' load;
    points without it are left out) or auto (cpu where the point has it, else wall); a CPU
    figure's window is named "WINDOW (cpu)", so the two never share a series."""
    j = _parse(path, raw, fail=_skip)
    if not isinstance(j, dict) or j.get("format") != "octocd-history":
        _skip(f"{path}: format: {str(j.get('format') if isinstance(j, dict) else type(j).__name__)[:60]!r}; "
              "allowed: an octocd-history file (docs/regression.md)")
    if j.get("version") != 1:
        _skip(f"{path}: version: {str(j.get('version'))[:20]}; allowed: 1")
    date = _text(j.get("date"), "date", path)
    try:
        when = datetime.datetime.strptime(date, "%Y-%m-%dT%H:%M:%SZ")
    except ValueError:
        _skip(f"{path}: date: {date[:40]!r}; allowed: an ISO 8601 UTC time such as 2026-01-31T02:00:00Z")
    build = j.get("build")
    machine = j.get("machine")
    if not isinstance(build, dict) or not isinstance(machine, dict):
        _skip(f"{path}: build or machine: not an object; allowed: an octocd-history file (docs/regression.md)")
    commit = _text(build.get("commit", ""), "build.commit", path)
    version = _text(build.get("version", ""), "build.version", path)
    host = _text(machine.get("hostname", ""), "machine.hostname", path)
    cpu = _text(machine.get("cpu", ""), "machine.cpu", path)
    gpu = machine.get("gpu", "")
    gpu = gpu if isinstance(gpu, str) else ""
    bench = j.get("bench", [])
    verdicts = j.get("verdicts", [])
    if not isinstance(bench, list) or not isinstance(verdicts, list):
        _skip(f"{path}: bench or verdicts: not an array; allowed: an octocd-history file (docs/regression.md)")
    series, engines = {}, {}
    for bi, r in enumerate(bench):
        if not isinstance(r, dict) or r.get("format") != "octocd-bench" or not isinstance(r.get("points"), list):
            _skip(f"{path}: bench[{bi}]: not a result of octocd bench; allowed: octocd-bench results")
        sweep = r.get("sweep", {}).get("name", "?") if isinstance(r.get("sweep"), dict) else "?"
        for p in r["points"]:
            if not isinstance(p, dict) or p.get("status") != "ok" or not isinstance(p.get("windows"), dict):
                continue
            for wname, w in p["windows"].items():
                if not isinstance(w, dict):
                    continue
                use_cpu = timing == "cpu" or (timing == "auto" and "cpu_steps_per_s" in w)
                s = _spread(w.get("cpu_steps_per_s" if use_cpu else "steps_per_s"))
                if s is not None:
                    key = (str(sweep), str(p.get("id", "?")), str(wname) + (" (cpu)" if use_cpu else ""))
                    series[key] = s
                    params = p.get("params")
                    engine = params.get("engine") if isinstance(params, dict) else None
                    if isinstance(engine, str):
                        engines[key] = engine
    rows = {}
    for vi, v in enumerate(verdicts):
        if not isinstance(v, dict):
            _skip(f"{path}: verdicts[{vi}]: not an object; allowed: rows {{engine, scene, row, status}}")
        st = v.get("status")
        if st not in STATUSES:
            _skip(f"{path}: verdicts[{vi}].status: {str(st)[:40]!r}; allowed: {', '.join(STATUSES)}")
        key = tuple(_text(v.get(k), f"verdicts[{vi}].{k}", path) for k in ("engine", "scene", "row"))
        reason = ""
        for o in v.get("expectations", []) if isinstance(v.get("expectations"), list) else []:
            if isinstance(o, dict) and isinstance(o.get("reason"), str) and o["reason"]:
                reason = o["reason"]
                break
        rows[key] = (st, reason)
    return {"file": os.path.basename(path), "date": date, "when": when, "commit": commit, "version": version,
            "machine": " · ".join(x for x in (host, cpu, gpu if gpu and not gpu.startswith("no CUDA") else "") if x),
            "series": series, "engines": engines, "verdicts": rows,
            "has_verdicts": bool(verdicts) or j.get("kind") == "nightly"}


def read_folder(folder, workers=1, timing="wall"):
    """(entries sorted by date then name, skipped [(file, why)]); files read by `workers`
    processes."""
    entries, skipped = [], []
    try:
        names = sorted(os.listdir(folder))
    except OSError as e:
        fail(f"--history {folder}: cannot be read ({e.strerror}); allowed: a history folder (docs/regression.md)")
    if len(names) > MAX_FILES:
        fail(f"--history {folder}: {len(names)} files; allowed: at most {MAX_FILES}")
    results = map_tasks(functools.partial(_read_one, timing=timing), [os.path.join(folder, n) for n in names],
                        workers)
    for name, (entry, why) in zip(names, results):
        if entry is not None:
            entries.append(entry)
        else:
            skipped.append((name, why))
    for name, why in skipped:
        print(f"octocd report: skipped {printable(why)}", file=sys.stderr)
    entries.sort(key=lambda e: (e["when"], e["file"]))
    return entries, skipped


def _read_one(path, timing="wall"):
    """(entry, None) or (None, why) for one file of the folder (never raises: a worker's answer)."""
    name = os.path.basename(path)
    try:
        st = os.lstat(path)
        if ".tmp." in name:
            raise Skip(f"{path}: a temporary file of an unfinished write (left by a stopped writer)")
        if not stat.S_ISREG(st.st_mode):
            kind = "a link" if stat.S_ISLNK(st.st_mode) else "a folder" if stat.S_ISDIR(st.st_mode) \
                else "a FIFO or device"
            raise Skip(f"{path}: not a regular file ({kind})")
        if not name.endswith(".json"):
            raise Skip(f"{path}: not a .json file; allowed: octocd-history files DATE-COMMIT-KIND.json")
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0))
        with os.fdopen(fd, "rb") as f:
            st = os.fstat(f.fileno())  # the file opened, not the name looked at
            if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_FILE_BYTES:
                raise Skip(f"{path}: not a regular file of at most {MAX_FILE_BYTES} bytes")
            raw = f.read(MAX_FILE_BYTES + 1)
        return read_entry(path, raw, timing), None
    except Skip as e:
        return None, str(e)
    except (OSError, RecursionError, MemoryError) as e:
        return None, f"{path}: cannot be read ({type(e).__name__}: {e})"
    except Exception as e:  # noqa: BLE001  (any other malformation: named and skipped)
        return None, f"{path}: malformed ({type(e).__name__}: {e})"


# ---------------------------------------------------------------- the change-point test

def _phi(z):
    return math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)


def max_z_pvalue(z, n, m=MIN_SEGMENT):
    """p of the largest standardized rank statistic z over the splits [m, n - m] of n values
    (James, James and Siegmund 1987; see the module's text)."""
    if z <= 0 or n < 2 * m:
        return 1.0
    L = 2.0 * math.log((n - m) / m)
    p = z * _phi(z) * ((1 - 1 / (z * z)) * L + 4 / (z * z))
    return min(1.0, max(p, 0.0))


def critical_z(alpha, n, m=MIN_SEGMENT):
    """The z at which max_z_pvalue falls to alpha (bisection)."""
    lo, hi = 0.5, 40.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if max_z_pvalue(mid, n, m) > alpha:
            lo = mid
        else:
            hi = mid
    return hi


def _ranks(x):
    order = np.argsort(x, kind="mergesort")
    r = np.empty(len(x))
    r[order] = np.arange(1, len(x) + 1)
    # ties: the mean rank of each tied run
    xs = x[order]
    if len(xs) > 1 and np.any(xs[1:] == xs[:-1]):
        i = 0
        while i < len(xs):
            k = i
            while k + 1 < len(xs) and xs[k + 1] == xs[i]:
                k += 1
            if k > i:
                r[order[i:k + 1]] = 0.5 * (i + k) + 1
            i = k + 1
    return r


def best_split(x, m=MIN_SEGMENT):
    """(t, z): the split after the first t values whose standardized rank statistic is largest."""
    n = len(x)
    r = _ranks(x)
    s = np.cumsum(r - (n + 1) / 2.0)[:-1]
    t = np.arange(1, n, dtype=float)
    z = np.abs(s) / np.sqrt(t * (n - t) * (n + 1) / 12.0)
    z[: m - 1] = 0
    z[n - m:] = 0
    k = int(np.argmax(z))
    return k + 1, float(z[k])


def change_points(x, alpha, m=MIN_SEGMENT):
    """Binary segmentation: sorted [(t, p)], t the index of the first value after the change."""
    found = []
    stack = [(0, len(x))]
    while stack and len(found) < MAX_CHANGES:
        a, b = stack.pop()
        if b - a < 2 * m:
            continue
        t, z = best_split(x[a:b], m)
        p = max_z_pvalue(z, b - a, m)
        if p <= alpha:
            found.append((a + t, p))
            stack += [(a, a + t), (a + t, b)]
    return sorted(found)


def ramp(x, a, t1, t2, b, A, B, reach=MAX_RAMP):
    """(s1, s2): the nights over which x[a:b] moves from level A to level B around the change
    points t1 <= t2: the model A before s1, a straight line from A to B over s1..s2-1, B from
    s2, fitted by least squares over s1 in [t1 - reach, t2], s2 in [t1, t2 + reach]; a ramp
    (s2 > s1) only where it beats the best step by the Bayesian information criterion (one
    parameter more: n log(SSE_step / SSE_ramp) > log n), else the best step (s, s)."""
    y = x[a:b]
    n = len(y)
    i = np.arange(n, dtype=float)
    lo, hi = max(1, t1 - a - reach), min(n - 1, t2 - a + reach)
    best_step, best_ramp = (math.inf, t1 - a, t1 - a), (math.inf, t1 - a, t1 - a)
    for s1 in range(lo, t2 - a + 1):
        for s2 in range(max(s1, t1 - a), hi + 1):
            if s2 == s1:
                m = np.where(i < s1, A, B)
            else:
                m = A + (B - A) * (i - s1 + 1) / (s2 - s1 + 1)
                m = np.where(i < s1, A, np.where(i >= s2, B, m))
            sse = float(np.sum((y - m) ** 2))
            if s2 == s1 and sse < best_step[0]:
                best_step = (sse, s1, s2)
            elif s2 > s1 and sse < best_ramp[0]:
                best_ramp = (sse, s1, s2)
    if best_ramp[0] > 0 and n * math.log(max(best_step[0], 1e-300) / best_ramp[0]) > math.log(n):
        return a + best_ramp[1], a + best_ramp[2]
    return a + best_step[1], a + best_step[2]


def changes(x, alpha, m=MIN_SEGMENT):
    """The change points of x (log values) as changes: [{first, last, before, after, ratio,
    p}]. Change points of one direction fewer than MERGE_GAP nights apart are one change
    (a creep is often found as several); first..last are the indices of the nights its level
    moved on (first == last: a step at night first; else a ramp, from ramp()), before/after
    the medians (log) of the segments around it."""
    cps = change_points(x, alpha, m)
    if not cps:
        return []
    bounds = [0] + [t for t, _ in cps] + [len(x)]
    levels = [float(np.median(x[bounds[i]:bounds[i + 1]])) for i in range(len(bounds) - 1)]
    groups = []
    for i, (t, p) in enumerate(cps):
        sign = 1 if levels[i + 1] > levels[i] else -1
        if groups and groups[-1]["sign"] == sign and t - groups[-1]["t2"] < MERGE_GAP:
            g = groups[-1]
            g["t2"], g["p"], g["seg_after"] = t, min(g["p"], p), i + 1
        else:
            groups.append({"t1": t, "t2": t, "p": p, "sign": sign, "seg_before": i, "seg_after": i + 1})
    for g in groups:
        g["before"], g["after"] = levels[g["seg_before"]], levels[g["seg_after"]]
        g["ratio"] = math.exp(g["after"] - g["before"])
        s1, s2 = ramp(x, bounds[g["seg_before"]], g["t1"], g["t2"], bounds[g["seg_after"] + 1], g["before"],
                      g["after"])
        g["first"], g["last"] = s1, max(s1, s2 - 1)
    return groups


def noise(x):
    """Robust standard deviation of the night-to-night noise of x: 1.4826 MAD(diff) / sqrt 2."""
    if len(x) < 3:
        return float("nan")
    d = np.diff(x)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2))


def smallest_step(sigma, n, t, alpha, m=MIN_SEGMENT):
    """The relative step seen half the time at a split t of n (Gaussian noise sigma on the log
    scale), or None when no step can be seen there."""
    if not math.isfinite(sigma) or n < 2 * m or not m <= t <= n - m:
        return None
    b = critical_z(alpha, n, m)
    q = 0.5 + b / math.sqrt(12.0 * t * (n - t) / (n + 1))
    if q >= 1:
        return None
    from statistics import NormalDist
    return math.exp(sigma * math.sqrt(2) * NormalDist().inv_cdf(q)) - 1


# ---------------------------------------------------------------- the page

def _png(fig, quantize=True):
    """The figure as base64 PNG, reduced to a 64-colour palette where PIL is there (Debian's
    python3-matplotlib depends on python3-pil): 2.5x smaller than RGBA for these line plots,
    so 100 series stay well under the page's 10 MB."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    plt.close(fig)
    data = buf.getvalue()
    if not quantize:  # the verdict grid: its status colours kept exact
        return base64.b64encode(data).decode("ascii")
    try:
        from PIL import Image
        im = Image.open(io.BytesIO(data)).convert("RGB").quantize(colors=64, method=Image.Quantize.MEDIANCUT)
        out = io.BytesIO()
        im.save(out, format="PNG", optimize=True)
        data = out.getvalue() if len(out.getvalue()) < len(data) else data
    except (ImportError, OSError, AttributeError, ValueError):
        pass
    return base64.b64encode(data).decode("ascii")


def measure_of(window):
    """(what the series measures, its axis label) from its window's name: a name ending in
    " (cpu)" is steps per process CPU second (cpu_steps_per_s), else wall-clock steps/s."""
    if str(window).endswith(" (cpu)"):
        return ("steps per CPU second of the bench process (cpu_steps_per_s; bench prints wall steps/s)",
                "steps per CPU s (log)")
    return "wall-clock steps/s (steps_per_s, as bench prints them)", "wall steps/s (log)"


def run_label(e):
    """A run on an axis: its date, time (two runs of one day apart) and commit, on two lines."""
    return f"{e['date'][:10]} {e['date'][11:16]}\n{e['commit'][:10]}"


def when_text(e):
    """A run's start on the page: date and time to the minute (UTC)."""
    return f"{e['date'][:10]} {e['date'][11:16]}"


def run_labels(runs):
    """run_label of each run; runs of one minute and commit numbered (#2, #3) so no two are alike."""
    out, seen = [], {}
    for e in runs:
        lab = run_label(e)
        seen[lab] = seen.get(lab, 0) + 1
        out.append(lab if seen[lab] == 1 else f"{lab} #{seen[lab]}")
    return out


def series_plot(key, nights, s, found, labels, engine=None):
    """steps/s of one point over its runs: the median, the min-max band, change windows shaded;
    in the colour and marker `engine` has on every plot of the report (report_plots), a grey
    line when the point names no engine."""
    fig, ax = plt.subplots(figsize=(9, 2.6))
    x = np.asarray(nights)
    colour = engine_colour(engine) if engine else "#555555"
    ax.fill_between(x, s[:, 1], s[:, 2], color=colour, alpha=0.25, linewidth=0, label="min-max of repetitions")
    ax.plot(x, s[:, 0], color=colour, linewidth=0.9, label="median", marker=engine_marker(engine) if engine else None,
            markersize=3)
    for g in found:
        color = "#D55E00" if g["ratio"] < 1 else "#009E73"
        if g["last"] > g["first"]:  # a change over a window of runs
            ax.axvspan(x[g["first"]] - 0.5, x[g["last"]] - 0.5, color=color, alpha=0.3, linewidth=0)
        ax.axvline(x[g["first"]] - 0.5, color=color, linewidth=1.2)
    ax.set_yscale("log")
    # Plain numbers on the log axis (report_plots.log_ticks; no mathtext, which cost most of the
    # drawing time); a range under 3x gets about 4 ticks inside it instead of 1, 2, 5 per decade.
    log_ticks(ax)
    if np.nanmax(s[:, 2]) < 3 * np.nanmin(s[:, 1]):
        from matplotlib.ticker import MaxNLocator
        ax.yaxis.set_major_locator(MaxNLocator(4))
    what, ylabel = measure_of(key[2])
    ax.set_ylabel(ylabel, fontsize=FONT_PT)
    ax.tick_params(labelsize=FONT_PT)
    ax.set_xlabel("run of this machine (its start, commit)", fontsize=FONT_PT)
    ax.set_title(short(" | ".join(key[:2]) + f" | window {key[2].removesuffix(' (cpu)')}: {what}", 160),
                 fontsize=FONT_PT + 1, loc="left")
    n = len(labels)
    ticks = sorted({0, n - 1} | {int(round(i * (n - 1) / 5)) for i in range(6)}) if n > 1 else [0]
    ax.set_xticks(ticks)
    ax.set_xticklabels([short_lines(labels[i]) for i in ticks], fontsize=FONT_PT)
    fig.tight_layout()
    return _png(fig)


def verdict_grid(keys, runs, matrix):
    """engine x scene x row (y) against night (x), one colour per status."""
    from matplotlib.colors import ListedColormap
    order = ["", *STATUSES]
    cmap = ListedColormap([STATUS_COLORS[s] for s in order])
    fig_h = max(2.4, 0.17 * len(keys) + 1.6)
    fig, ax = plt.subplots(figsize=(10, fig_h))
    ax.imshow(matrix, aspect="auto", interpolation="nearest", cmap=cmap, vmin=-0.5, vmax=len(order) - 0.5)
    ax.set_yticks(range(len(keys)))
    ax.set_yticklabels([short(" · ".join(k), 60) for k in keys], fontsize=FONT_PT)
    n = len(runs)
    ticks = sorted({0, n - 1} | {int(round(i * (n - 1) / 6)) for i in range(7)}) if n > 1 else [0]
    labels = run_labels(runs)
    ax.set_xticks(ticks)
    ax.set_xticklabels([short_lines(labels[i]) for i in ticks], fontsize=FONT_PT, rotation=30, ha="right")
    ax.grid(False)
    from matplotlib.patches import Patch
    ax.legend(handles=[Patch(color=STATUS_COLORS[s], label=s) for s in STATUSES], loc="upper left",
              bbox_to_anchor=(1.0, 1.0), fontsize=FONT_PT)
    fig.tight_layout()
    return _png(fig, quantize=False)


def render(task):
    """One plot (a picklable task, so that plots can be drawn by several processes)."""
    kind = task[0]
    if kind == "series":
        return series_plot(*task[1:])
    return verdict_grid(*task[1:])


def _worker_init():
    """A drawing worker: a stop is its parent's to handle (SIGINT ignored; SIGTERM, which the
    parent's pool sends when it stops, ends it at once without a traceback), and it ends with
    its parent (Linux PR_SET_PDEATHSIG: a parent killed outright leaves no worker writing
    tracebacks into a closed pipe)."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM, signal.SIGINT})  # held by map_tasks while forking
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        if os.getppid() == 1:  # the parent ended before prctl
            os._exit(0)
    except (OSError, AttributeError):
        pass


def map_tasks(fn, tasks, workers):
    """[fn(t) for t in tasks], by `workers` forked processes when there are enough tasks."""
    if workers <= 1 or len(tasks) < 8:
        return [fn(t) for t in tasks]
    import multiprocessing
    try:
        ctx = multiprocessing.get_context("fork")
        # SIGTERM is held while the workers are forked (a stop inside a fork hook would be
        # swallowed and printed), then delivered; each worker unblocks it in _worker_init.
        import signal
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT})
        try:
            pool = ctx.Pool(workers, initializer=_worker_init)
        finally:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM, signal.SIGINT})
        with pool:
            out = pool.map(fn, tasks, chunksize=max(1, len(tasks) // (8 * workers)))
    except OSError:
        out = [fn(t) for t in tasks]
    if STOP[0]:  # a SIGTERM whose Stopped a fork hook swallowed
        raise Stopped(STOP[0])
    return out


def fmt_pct(r, why):
    """A relative step as a percentage, or `why` none can be given."""
    return why if r is None else f"{100 * r:.1f} %"


def run(folder, out, level, title=None, workers=None, csv_dir=None, timing="auto"):
    if workers is None:
        workers = min(4, os.cpu_count() or 1)
    entries, skipped = read_folder(folder, workers, timing)
    E = html.escape
    page = []
    files = {}
    tasks = []
    machines = []
    for e in entries:
        if e["machine"] not in machines:
            machines.append(e["machine"])
    pts_rows, chg_rows, ver_rows, first_rows = [], [], [], []
    page.append(f"<p class=note>Made by octocd report on {datetime.datetime.utcnow().strftime('%Y-%m-%d %H:%M UTC')} "
                f"from {len(entries)} run(s) of {len(machines)} machine(s) in the history folder; {len(skipped)} "
                "file(s) skipped. Machines are kept apart: each has its own series, tests and grid.</p>")
    if skipped:
        page.append("<h2 id=skipped>Skipped files</h2><ul>" +
                    "".join(f"<li><code>{E(short(n, 120))}</code>: {E(short(w, 400))}</li>" for n, w in skipped[:200]) +
                    (f"<li>... and {len(skipped) - 200} more (history-skipped.csv)</li>" if len(skipped) > 200 else "")
                    + "</ul>")
    for mi, mach in enumerate(machines):
        runs = [e for e in entries if e["machine"] == mach]
        page.append(f"<h2 id=m{mi}>Machine {mi + 1}: {E(short(mach))}</h2>")
        page.append(f"<p>{len(runs)} run(s), {E(runs[0]['date'])} to {E(runs[-1]['date'])}.</p>")
        # ---- performance series
        keys = []
        seen = set()
        for e in runs:
            for k in e["series"]:
                if k not in seen:
                    seen.add(k)
                    keys.append(k)
        S = max(1, len(keys))
        alpha = level / S
        if keys:
            ncpu = sum(1 for k in keys if k[2].endswith(" (cpu)"))
            page.append(f"<h3>steps/s over commits ({len(keys)} series)</h3>")
            page.append("<p class=note>Each series is one point and window of a bench sweep: " +
                        (f"{ncpu} in steps per CPU second of the bench process (cpu_steps_per_s, window marked "
                         "'(cpu)': hardly moved by other processes' load; bench prints wall steps/s), "
                         if ncpu else "") +
                        (f"{len(keys) - ncpu} in wall-clock steps/s (steps_per_s, as bench prints them)"
                         if len(keys) > ncpu else "").rstrip(", ") +
                        " (--timing cpu, wall or auto chooses). Each run is labelled by its own start (date and "
                        "time) and the commit of the build that made it; each series is drawn in its engine's "
                        "colour and marker, those of the report's plots.</p>")
            page.append(f"<p class=note>Change points: binary segmentation with the standardized Mann-Whitney rank "
                        f"statistic maximized over splits (at least {MIN_SEGMENT} runs each side), p by James, James "
                        f"and Siegmund's approximation; level {level:g} family-wise over this machine's {S} series "
                        f"(each at {alpha:.3g}); change points of one direction fewer than {MERGE_GAP} runs apart are "
                        "one change over a window. Red: slower, green: faster.</p>")
        chg_html = []
        plots = []
        all_labels = run_labels(runs)
        for k in keys:
            idx = [i for i, e in enumerate(runs) if k in e["series"]]
            s = np.array([runs[i]["series"][k] for i in idx], dtype=float)
            labels = [all_labels[i] for i in idx]
            x = np.log(s[:, 0])
            found = changes(x, alpha)
            sig = noise(x)
            n = len(x)
            mid = smallest_step(sig, n, n // 2, alpha)
            recent = smallest_step(sig, n, n - 10, alpha) if n >= 20 else None
            for j, i in enumerate(idx):
                e = runs[i]
                pts_rows.append([mach, *k, j, e["date"], e["commit"], s[j, 0], s[j, 1], s[j, 2], int(s[j, 3])])
            for g in found:
                a, b = idx[g["first"]], idx[g["last"]]
                row = [mach, *k, runs[a]["date"], runs[a]["commit"], runs[b]["date"], runs[b]["commit"],
                       g["last"] - g["first"] + 1, math.exp(g["before"]), math.exp(g["after"]), g["ratio"], g["p"]]
                chg_rows.append(row)
                chg_html.append(
                    f"<tr><td>{E(short(' | '.join(k), 160))}</td><td>{E(when_text(runs[a]))} "
                    f"<code>{E(short(runs[a]['commit'], 40))}</code></td><td>{E(when_text(runs[b]))} "
                    f"<code>{E(short(runs[b]['commit'], 40))}</code></td><td>{g['last'] - g['first'] + 1}</td>"
                    f"<td>{math.exp(g['before']):.4g}</td><td>{math.exp(g['after']):.4g}</td>"
                    f"<td class={'slow' if g['ratio'] < 1 else 'fast'}>{100 * (g['ratio'] - 1):+.1f} %</td>"
                    f"<td>{g['p']:.2g}</td></tr>")
            engine = next((runs[i]["engines"][k] for i in reversed(idx) if k in runs[i]["engines"]), None)
            plots.append((k, ("series", k, list(range(n)), s, found, labels, engine), n, sig, mid, recent,
                          len(found)))
        if chg_html:
            page.append("<h4>Changes found</h4><table><tr><th>series</th><th>first run of the change</th>"
                        "<th>last run of the change</th><th>runs</th><th>steps/s before (median)</th>"
                        "<th>after</th><th>change</th><th>p</th></tr>" + "".join(chg_html[:MAX_CHANGE_ROWS]) +
                        "</table>")
            if len(chg_html) > MAX_CHANGE_ROWS:
                page.append(f"<p class=note>The table shows the first {MAX_CHANGE_ROWS} of {len(chg_html)} changes; "
                            "history-changes.csv holds every one.</p>")
        elif keys:
            page.append("<p>No change point in any series at this level.</p>")
        # At most MAX_SERIES_PLOTS plots a machine, the series with a change first (a night naming
        # thousands of points would take minutes to draw and a page no one reads).
        drawn = sorted(plots, key=lambda q: q[6] == 0)[:MAX_SERIES_PLOTS]
        if len(plots) > len(drawn):
            page.append(f"<p class=note>{len(plots) - len(drawn)} of {len(plots)} series are not drawn (a machine's "
                        f"page draws at most {MAX_SERIES_PLOTS}, those with a change first); their figures are in "
                        "history-points.csv and their changes above and in history-changes.csv.</p>")
        drawn_keys = {q[0] for q in drawn}
        for k, task, n, sig, mid, recent, nf in plots:
            if k not in drawn_keys:
                continue
            tasks.append(task)
            noise_text = (f"night-to-night noise {100 * sig:.2f} % (robust sd of log steps/s)" if math.isfinite(sig)
                          else "night-to-night noise: not estimated (fewer than 3 runs)")
            page.append(f"<figure><img alt='steps/s of {E(short(' | '.join(k), 160))}' src='@@PLOT{len(tasks) - 1}@@'>"
                        f"<figcaption>{n} runs; {noise_text}; smallest step seen half the time: "
                        f"{fmt_pct(mid, f'none at mid-history (fewer than {2 * MIN_SEGMENT} runs)')}"
                        f"{' at mid-history' if mid is not None else ''}, "
                        f"{fmt_pct(recent, 'none 10 runs before the last (fewer than 20 runs)')}"
                        f"{' 10 runs before the last' if recent is not None else ''}; {nf} change(s)."
                        "</figcaption></figure>")
        # ---- verdicts
        vruns = [e for e in runs if e["has_verdicts"]]
        if vruns and not any(e["verdicts"] for e in vruns):
            page.append("<p>No verdict rows in these runs (bench results only).</p>")
            vruns = []
        if vruns:
            vkeys = sorted({k for e in vruns for k in e["verdicts"]})
            code = {s: i for i, s in enumerate(["", *STATUSES])}
            M = np.zeros((len(vkeys), len(vruns)), dtype=np.int8)
            kidx = {k: i for i, k in enumerate(vkeys)}
            for j, e in enumerate(vruns):
                for k, (st, _) in e["verdicts"].items():
                    M[kidx[k], j] = code[st]
            # The CSV: per row, one line per stretch of nights with the same status (run-length).
            for i, k in enumerate(vkeys):
                row = M[i]
                starts = [0] + [j for j in range(1, len(vruns)) if row[j] != row[j - 1]]
                for q, j0 in enumerate(starts):
                    j1 = (starts[q + 1] if q + 1 < len(starts) else len(vruns)) - 1
                    st = ["", *STATUSES][row[j0]] or "absent"
                    ver_rows.append([mach, *k, st, vruns[j0]["date"], vruns[j0]["commit"], vruns[j1]["date"],
                                     vruns[j1]["commit"], j1 - j0 + 1])
            # Rows that passed every night, or were n/a every night (absent nights aside), are folded.
            passing = [i for i in range(len(vkeys)) if np.all((M[i] == code["pass"]) | (M[i] == code[""]))]
            never = [i for i in range(len(vkeys)) if np.all((M[i] == code["n/a"]) | (M[i] == code[""]))
                     and np.any(M[i] == code["n/a"])]
            folded = set(passing) | set(never)
            ever = [i for i in range(len(vkeys)) if i not in folded]
            page.append(f"<h3>Verdicts over time ({len(vkeys)} engine x scene x row, {len(vruns)} nights)</h3>")
            page.append(f"<p>{len(passing)} row(s) passed every night and {len(never)} were n/a every night (not "
                        "judged: the engine or scene lacks what the row needs), absent nights aside; they are left "
                        "out of the grid (history-verdicts.csv has them all).</p>")
            shown = ever[:MAX_GRID_ROWS]
            if len(ever) > MAX_GRID_ROWS:
                page.append(f"<p>The grid draws the first {MAX_GRID_ROWS} of {len(ever)} rows that were not always "
                            "passing.</p>")
            if shown:
                tasks.append(("grid", [vkeys[i] for i in shown],
                              [{"date": e["date"], "commit": e["commit"]} for e in vruns], M[shown]))
                page.append(f"<figure><img alt='verdicts of the engine matrix over nights' src='@@PLOT{len(tasks) - 1}@@'>"
                            "<figcaption>Each row an engine · scene · row, each column a night: pass, expected "
                            "(a known failure within its expectation), new (a failure no expectation covers, or "
                            "grown), fixed (an expectation that no longer fails), n/a, error (black: the case gave no "
                            "verdict, a run that crashed or timed out); white: not run that night."
                            "</figcaption></figure>")
            # ---- the first night of each current failure
            last = len(vruns) - 1
            cur = []
            for i, k in enumerate(vkeys):
                st = STATUSES[M[i, last] - 1] if M[i, last] else ""
                if st not in ("new", "expected", "error"):
                    continue
                j = last
                while j > 0 and M[i, j - 1] in (code["new"], code["expected"], code["error"]):
                    j -= 1
                first_new = next((q for q in range(j, last + 1) if M[i, q] == code["new"]), None)
                reason = vruns[last]["verdicts"][k][1]
                cur.append((k, st, j, first_new, reason))
                fn = vruns[first_new] if first_new is not None else None
                first_rows.append([mach, *k, st, vruns[j]["date"], vruns[j]["commit"], last - j + 1,
                                   fn["date"] if fn else "", fn["commit"] if fn else "", reason])
            if cur:
                page.append("<h4>Current failures and the night each appeared</h4><table><tr><th>engine</th>"
                            "<th>scene</th><th>row</th><th>now</th><th>failing since (night, commit)</th>"
                            "<th>nights</th><th>first new in this run of nights</th><th>reason</th></tr>" +
                            "".join(f"<tr><td>{E(short(k[0]))}</td><td>{E(short(k[1]))}</td><td>{E(short(k[2]))}</td>"
                                    f"<td class={'exp' if st == 'expected' else 'slow'}>{st}</td>"
                                    f"<td>{E(when_text(vruns[j]))} <code>{E(short(vruns[j]['commit'], 40))}</code></td>"
                                    f"<td>{last - j + 1}</td><td>" +
                                    (f"{E(when_text(vruns[q]))} <code>{E(short(vruns[q]['commit'], 40))}</code>"
                                     if q is not None else "none: expected every night of this stretch") + f"</td><td>{E(short(reason))}</td></tr>"
                                    for k, st, j, q, reason in cur) + "</table>")
            else:
                page.append("<p>No row fails on the last night.</p>")
    if not entries:
        page.append("<p>No history file could be read.</p>")
    pngs = map_tasks(render, tasks, workers)
    body = "\n".join(page)
    for i, b in enumerate(pngs):
        body = body.replace(f"'@@PLOT{i}@@'", f"'data:image/png;base64,{b}'", 1)
    t = E(short(title or "octocd history"))
    doc = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{t}</title>"
           "<meta http-equiv='Content-Security-Policy' content=\"default-src 'none'; img-src data:; "
           "style-src 'unsafe-inline'; script-src 'unsafe-inline'\">"
           "<style>body{font:14px sans-serif;max-width:1100px;margin:1em auto;padding:0 1em}"
           "table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px}"
           ".note{color:#555;font-size:12px}.slow{color:#D55E00;font-weight:bold}.fast{color:#009E73}"
           ".exp{color:#8a7a00}img{max-width:100%}figure{margin:0.5em 0}</style></head>"
           f"<body data-plots='{len(pngs)}'><h1>{t}</h1>\n{body}\n"
           "<script>window.addEventListener('load',function(){var im=document.images,ok=0;"
           "for(var i=0;i<im.length;i++){if(im[i].complete&&im[i].naturalWidth>0)ok++;}"
           "document.body.setAttribute('data-drawn',ok+'/'+im.length);});</script></body></html>\n")
    o = Outputs()
    o.put(os.path.join(out, "index.html"), doc)
    out_csv = csv_dir or out
    o.put(os.path.join(out_csv, "history-points.csv"),
          csv_text(["machine", "sweep", "point", "window", "run", "date", "commit", "steps_per_s_median [1/s]",
                    "steps_per_s_min [1/s]", "steps_per_s_max [1/s]", "repetitions"], pts_rows))
    o.put(os.path.join(out_csv, "history-changes.csv"),
          csv_text(["machine", "sweep", "point", "window", "first_date", "first_commit", "last_date", "last_commit",
                    "runs", "before_steps_per_s [1/s]", "after_steps_per_s [1/s]", "ratio", "p"], chg_rows))
    o.put(os.path.join(out_csv, "history-verdicts.csv"),
          csv_text(["machine", "engine", "scene", "row", "status", "from_date", "from_commit", "to_date", "to_commit",
                    "nights"], ver_rows))
    o.put(os.path.join(out_csv, "history-failures.csv"),
          csv_text(["machine", "engine", "scene", "row", "status", "since_date", "since_commit", "nights",
                    "first_new_date", "first_new_commit", "reason"], first_rows))
    o.put(os.path.join(out_csv, "history-skipped.csv"), csv_text(["file", "why"], skipped))
    o.commit()
    print(f"octocd report: wrote {os.path.join(out, 'index.html')} ({len(pngs)} plots, {len(doc) / 1e6:.2f} MB; "
          f"{len(entries)} runs, {len(skipped)} skipped, {len(chg_rows)} change(s)) and 5 CSV files in {out_csv}")
    return {"entries": len(entries), "skipped": skipped, "changes": chg_rows, "failures": first_rows,
            "plots": len(pngs), "bytes": len(doc)}
