"""What every part of octocd's report shares (report/make_report.py is the entry point): the
one-line error (exit 2), numpy and matplotlib (exit 1 without them), the paper's tables, the
stage colours (the engines' are report_plots.ENGINE_COLORS), the file being read (CURRENT, for
the error of a malformed one) and the octocd binary that reads traces (OCTOCD), number formatting and the marks of points
measured under load."""

import csv
import json
import math
import os
import re
import sys


PAPER = json.load(open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "paper_tables.json")))
STAGES = ["integrate", "aabbs", "broadphase", "midphase", "response", "metrics"]
STAGE_COLORS = ["#4e79a7", "#a0cbe8", "#f28e2b", "#e15759", "#59a14f", "#b6992d"]
NOISE_NOTE = ("Timings on a shared machine move with its load (other processes, builds): compare figures "
              "taken in one run; spreads are min-max over the repetitions.")


MAX_MESSAGE = 2000  # characters of an error line; text from a file beyond it is cut (a MB-long name)


def printable(text, limit=MAX_MESSAGE):
    """`text` safe for one line of a terminal: control characters, lone surrogates (JSON's
    "\\ud800") and other code points a UTF-8 stream cannot take written as escapes
    (\\xNN, \\udNNN), cut to `limit` characters with the number left out said."""
    text = str(text)
    cut = len(text) - limit
    if cut > 0:
        text = text[:limit]
    out = "".join(c if c.isprintable() or c == " " else
                  (f"\\x{ord(c):02x}" if ord(c) < 0x100 else c.encode("unicode_escape").decode("ascii"))
                  for c in text)
    return out + (f"... ({cut} more characters)" if cut > 0 else "")


MAX_TEXT = 4096  # characters of one value from a file in report.md, index.html or a CSV cell
MAX_LINE = 16384  # characters of one line or cell of report.md or index.html (values within it: MAX_TEXT)


def bounded(text, limit=MAX_TEXT):
    """`text` (a name, a description, a trace's attribute) cut to `limit` characters with its
    whole length said: a 16 MiB attribute gives 4,096 characters and "... (16,777,216
    characters)", never a 16 MB report."""
    text = str(text)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text):,} characters)"


_CSV_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|[+-]?(inf|nan)")


def csv_guard(text):
    """A text cell of a CSV file a spreadsheet opens (OWASP, "CSV Injection"): bounded, and
    when it begins with = + - @ TAB or CR behind an apostrophe, so no formula runs from it; a
    number written as text (`-3.5`, `+1e-3`, `-inf`) stays a number."""
    t = bounded(text)
    if t[:1] in ("=", "+", "-", "@", "\t", "\r") and not _CSV_NUMBER.fullmatch(t):
        return "'" + t
    return t


class csv_writer:
    """csv.writer whose writerow puts every text cell through csv_guard (numbers as they
    are): the one CSV sink of the report."""

    def __init__(self, f):
        self._w = csv.writer(f)

    def writerow(self, cells):
        self._w.writerow([csv_guard(c) if isinstance(c, str) else c for c in cells])


class Stopped(BaseException):
    """SIGTERM arrived (octocd report forwards it): raised in the main thread like SIGINT's
    KeyboardInterrupt, so a stop unwinds (the pool of drawing workers ended) and is one line."""


MAIN_PID = os.getpid()
STOP = [0]  # the stopping signal once one arrived (a raise swallowed in a fork hook is raised again)


def on_sigterm(sig, frame):
    """SIGTERM's handler: Stopped in the main process; a forked worker that has not yet reset
    its handlers (report_history._worker_init) ends at once, silently."""
    if os.getpid() != MAIN_PID:
        os._exit(128 + sig)
    STOP[0] = sig
    raise Stopped(sig)


def fail(msg):
    """Bad input: one line naming the file and what is allowed, exit 2 (never a traceback).
    The line is printable(): text from a hostile file cannot break it or the terminal."""
    print(f"octocd report: error: {printable(msg)}", file=sys.stderr)
    sys.exit(2)


try:
    import numpy as np  # noqa: F401  (the other report_*.py modules take np from here)
except ImportError as e:  # exit 1: a missing dependency is not bad input
    print(f"octocd report: runtime failure: {e}; install Debian's python3-matplotlib and python3-numpy",
          file=sys.stderr)
    sys.exit(1)


class _Pyplot:
    """matplotlib.pyplot, imported at the first use of an attribute: a report that ends on an
    input error, or draws nothing, never pays for its import (about 0.5 s of CPU).
    Every text matplotlib draws is plain text: a `$...$` in a scene's, engine's or sweep's name
    is never read as mathtext (a malformed one would fail the whole page), nor TeX."""

    _module = None

    def __getattr__(self, name):
        if _Pyplot._module is None:
            try:
                import matplotlib
                matplotlib.use("Agg")
                import matplotlib.pyplot as pyplot
            except ImportError as e:  # exit 1: a missing dependency is not bad input
                print(f"octocd report: runtime failure: {e}; install Debian's python3-matplotlib and "
                      "python3-numpy", file=sys.stderr)
                sys.exit(1)
            pyplot.rcParams.update({"svg.fonttype": "none", "font.family": "sans-serif", "font.size": 9,
                                    "axes.grid": True, "grid.alpha": 0.3, "figure.dpi": 100,
                                    "text.parse_math": False, "text.usetex": False})
            _Pyplot._module = pyplot
        return getattr(_Pyplot._module, name)


plt = _Pyplot()


CURRENT = ["the inputs"]  # the file being read, for the one-line error of a malformed one
OCTOCD = [None]  # the octocd binary that reads traces (--octocd)


def is_number(x):
    """Whether `x` (a value read from a JSON file) is a number: an int or float, never a bool."""
    return isinstance(x, (int, float)) and not isinstance(x, bool)


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
    """Why timings of this machine description are suspect (the CPU engine's threads oversubscribing the
    cores, or a load at the start or end above them), or ''. A run-level note; verdicts are
    marked per point (point_load)."""
    threads, omp = m.get("threads") or 0, m.get("omp_threads") or 1
    why = []
    if threads and omp > threads:
        why.append(f"{omp} CPU engine threads on {threads} cores")
    # At the start the load is the others'; at the end it includes the bench's own threads.
    for key, when, own in (("load_average", "start", omp), ("load_average_end", "end", 0)):
        la = m.get(key)
        if threads and isinstance(la, list) and la and isinstance(la[0], (int, float)) and la[0] + own > threads + 1:
            why.append(f"load {la[0]:.1f} at the {when} leaves {max(threads - la[0], 0):.1f} of {threads} cores free "
                       f"for {omp} CPU engine thread(s)" + (" (its own included)" if when == "end" else ""))
    return "; ".join(why)


def own_threads(p, m):
    """The threads the bench itself ran while measuring point p: the CPU engine's
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
    # The load average is a 1-minute mean that also counts the bench's own threads while they
    # wait on I/O or the device: a point is marked only when other processes took at least one
    # whole core the bench's threads needed (load 0.5 beside 16 threads on 16 cores is no mark).
    for load, when in others:
        free = threads - load
        if own >= free + 1.0:
            return f"load of other processes {load:.1f} {when} left {max(free, 0):.1f} of {threads} cores free for " \
                   f"{own} thread(s)"
    return ""


def load_mark(m, *points):
    """'⚠ ' when one of the points a verdict compares was measured under load (point_load)."""
    return "⚠ " if any(p is not None and point_load(p, m) for p in points) else ""
