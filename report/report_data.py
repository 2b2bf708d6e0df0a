"""The report's inputs (report/make_report.py): bench results (octocd-bench JSON) checked
and merged per sweep and machine, and traces read through `octocd trace-summary --json`
(octocd's hardened reader; never h5py here)."""

import errno
import json
import math
import os
import re
import stat
import subprocess
import sys

from report_common import OCTOCD, fail, np
import report_speed_accuracy as RSA  # sweeps of kind speed-accuracy (design.md section 15)
import report_divergence as RDV  # sweeps of kind divergence (design.md section 20)


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


MAX_RESULT_BYTES = 64 << 20  # as octocd's kMaxJsonFileBytes: a larger result is refused before it is read
MAX_DEPTH = 64  # nesting levels, as octocd's strict JSON reader (octocd bench writes 6)
MAX_TEXT = 65536  # characters of any string (a reason, a description)
MAX_NAME = 4096  # characters of a name the report draws: sweep, point id, engine, scene, window, machine
MAX_POINTS = 100000  # points of one result (a sweep expands to at most as many: docs/bench-format.md)
MAX_REPS = 1000  # repetitions of one spread (octocd bench --repeat is at most 1000)
MAX_FIGURE = 1e15  # |value| of a spread's figure: beyond any count, byte size or rate bench measures
INT_RANGE = (-(1 << 63), (1 << 64) - 1)  # integers octocd writes (int64, uint64)
LOADED = {}  # path -> load()'s answer: each file read and checked once per report (main() clears it)
SURROGATE_ESCAPE = re.compile(r"\\u[dD][89a-fA-F]")  # where a lone surrogate could come from


class _BigInt:
    """An integer literal of more than 20 digits (json's parse_int): refused by _walk with
    its field, never converted (a 400-digit integer overflowed float() later)."""
    __slots__ = ("text",)

    def __init__(self, text):
        self.text = text


class _Refused(Exception):
    """A JSON text the reader refuses before it has a field to name (a key twice)."""


def _pairs(pairs):
    d = dict(pairs)
    if len(d) != len(pairs):
        seen = set()
        for k, _ in pairs:
            if k in seen:
                raise _Refused(f"key {k!r} twice in one object (the last one would silently win)")
            seen.add(k)
    return d


def field_path(parts):
    """'points[3].windows.all' from ['points', 3, 'windows', 'all']."""
    out = ""
    for x in parts:
        out += f"[{x}]" if isinstance(x, int) else (("." if out else "") + str(x))
    return out


def _walk(path, v, parts, surrogates, fail=fail):
    """Checks every value of a result, naming its field: nesting within MAX_DEPTH, integers
    within int64/uint64, strings within MAX_TEXT characters and valid Unicode (no lone
    surrogate written as \\ud800: no UTF-8 file can hold one)."""
    t = type(v)
    if t is dict or t is list:
        if len(parts) >= MAX_DEPTH:
            fail(f"{path}: {field_path(parts)}: nested deeper than {MAX_DEPTH} levels; allowed: a result of octocd "
                 "bench (6 levels)")
        items = v.items() if t is dict else enumerate(v)
        for k, x in items:
            parts.append(k)
            if t is dict and (len(k) > MAX_TEXT or (surrogates and _has_surrogate(k))):
                fail(f"{path}: {field_path(parts[:-1])}: a key of {len(k)} characters or not valid Unicode; allowed: "
                     f"keys of at most {MAX_TEXT} characters")
            _walk(path, x, parts, surrogates, fail)
            parts.pop()
    elif t is str:
        if len(v) > MAX_TEXT:
            fail(f"{path}: {field_path(parts)}: a string of {len(v)} characters; allowed: at most {MAX_TEXT}")
        if surrogates and _has_surrogate(v):
            fail(f"{path}: {field_path(parts)}: {v[:60]!r} is not valid Unicode (a lone surrogate); allowed: text "
                 "UTF-8 can hold")
    elif t is int:
        if not INT_RANGE[0] <= v <= INT_RANGE[1]:
            fail(f"{path}: {field_path(parts)}: the integer {str(v)[:30]}... ({len(str(v))} digits) is out of range; "
                 "allowed: integers within [-2^63, 2^64) (int64 and uint64, as octocd writes them)")
    elif t is _BigInt:
        fail(f"{path}: {field_path(parts)}: the integer {v.text[:30]}... ({len(v.text)} digits) is out of range; "
             "allowed: integers within [-2^63, 2^64) (int64 and uint64, as octocd writes them)")


def _has_surrogate(text):
    return any("\ud800" <= c <= "\udfff" for c in text)


def _parse(path, raw, fail=fail):
    """The JSON of a result file (bytes), parsed as octocd's strict reader parses: UTF-8, no
    key twice in one object, at most MAX_DEPTH levels, integers within 64 bits; every
    refusal exit 2 naming the file (and the field where there is one), or `fail(message)`
    when given (the history reader's: it raises, and the file is skipped)."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        fail(f"{path}: not UTF-8 at byte {e.start}; allowed: octocd-bench results (.json, UTF-8), octocd-trace files "
             "(.h5)")
    if "\0" in text:
        fail(f"{path}: a NUL byte at character {text.index(chr(0))}; allowed: JSON text")
    try:
        j = json.loads(text, object_pairs_hook=_pairs, parse_int=lambda s: int(s) if len(s) <= 20 else _BigInt(s))
    except RecursionError:
        fail(f"{path}: nested deeper than the reader can follow; allowed: a result of octocd bench (6 levels, at most "
             f"{MAX_DEPTH})")
    except _Refused as e:
        fail(f"{path}: {e}; allowed: each key once in an object")
    except (json.JSONDecodeError, ValueError) as e:
        fail(f"{path}: neither an HDF5 trace nor JSON ({e}); allowed: octocd-bench results (.json), "
             "octocd-trace files (.h5)")
    _walk(path, j, [], SURROGATE_ESCAPE.search(text) is not None, fail)
    return j


def _check_header(path, j):
    """The header fields the report reads, by type and range (exit 2 naming file and field)."""
    def bad(field, v, allowed):
        fail(f"{path}: {field}: {json.dumps(v)[:80] if not isinstance(v, _BigInt) else v.text[:80]}; allowed: "
             f"{allowed}")

    def obj(field, v):
        if not isinstance(v, dict):
            bad(field, v, "an object (docs/bench-format.md)")
        return v

    def text(field, d, key, limit=MAX_NAME, required=False):
        if key not in d:
            if required:
                fail(f"{path}: {field}.{key}: missing; allowed: a string")
            return
        if not isinstance(d[key], str) or len(d[key]) > limit:
            bad(f"{field}.{key}", d[key] if not isinstance(d[key], str) else d[key][:80] + "...",
                f"a string of at most {limit} characters")

    def integer(field, d, key, lo, hi):
        if key in d and not (type(d[key]) is int and lo <= d[key] <= hi):
            bad(f"{field}.{key}", d[key], f"an integer in [{lo}, {hi}]")

    sweep = obj("sweep", j["sweep"])
    text("sweep", sweep, "name", required=True)
    if not sweep["name"]:
        bad("sweep.name", "", "a non-empty string")
    for k in ("kind", "origin"):
        text("sweep", sweep, k)
    text("sweep", sweep, "description", MAX_TEXT)
    obj("sweep.definition", sweep.get("definition"))
    settings = obj("settings", j["settings"])
    if "engines" in settings and not (isinstance(settings["engines"], list) and all(
            isinstance(e, str) and len(e) <= MAX_NAME for e in settings["engines"])):
        bad("settings.engines", settings["engines"], "a list of engine names (strings)")
    integer("settings", settings, "repeat", 1, MAX_REPS)
    for k in ("frames", "warmup"):
        integer("settings", settings, k, 0, 1 << 40)
    if "shard" in settings:
        sh = obj("settings.shard", settings["shard"])
        integer("settings.shard", sh, "count", 1, 100000)
        integer("settings.shard", sh, "index", 0, max(sh.get("count", 1) - 1, 0) if type(sh.get("count")) is int
                else 0)
    machine = obj("machine", j["machine"])
    for k in ("hostname", "cpu", "gpu", "driver"):
        text("machine", machine, k)
    for k in ("threads", "omp_threads"):
        integer("machine", machine, k, 0, 1 << 20)
    for k in ("load_average", "load_average_end"):
        la = machine.get(k)
        if la is not None and not (isinstance(la, list) and len(la) <= 3 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and 0 <= x <= 1e6
                for x in la)):
            bad(f"machine.{k}", la, "a list of up to 3 load averages, finite numbers in [0, 1e6]")
    build = obj("build", j["build"])
    for k in ("build_id", "git_revision"):
        text("build", build, k)
    for k in ("started", "updated", "stopped"):
        text("", j, k)
    if "complete" in j and not isinstance(j["complete"], bool):
        bad("complete", j["complete"], "true or false")
    integer("", j, "points_total", 0, 1 << 40)
    if not isinstance(j["points"], list) or len(j["points"]) > MAX_POINTS:
        bad("points", f"an array of {len(j['points'])} points" if isinstance(j["points"], list) else j["points"],
            f"an array of at most {MAX_POINTS} points (docs/bench-format.md)")
    if "searches" in j and not (isinstance(j["searches"], list) and all(isinstance(x, dict) for x in j["searches"])):
        bad("searches", j["searches"], "an array of search summaries (docs/bench-format.md, kind max-instances)")


def load(path):
    """("trace", path) for an HDF5 file, else ("result", path, json) of a bench result read
    and checked (_parse, _check_header); each path is read once (LOADED)."""
    if path in LOADED:
        return LOADED[path]
    regular_file(path)
    with open(path, "rb") as f:
        head = f.read(8)
        if head == b"\x89HDF\r\n\x1a\n":
            LOADED[path] = ("trace", path)
            return LOADED[path]
        size = os.fstat(f.fileno()).st_size
        if size > MAX_RESULT_BYTES:
            fail(f"{path}: {size} bytes; allowed: a result of at most {MAX_RESULT_BYTES} bytes (64 MiB)")
        raw = head + f.read(MAX_RESULT_BYTES + 1 - len(head))
    if len(raw) > MAX_RESULT_BYTES:
        fail(f"{path}: more than {MAX_RESULT_BYTES} bytes; allowed: a result of at most 64 MiB")
    j = _parse(path, raw)
    fmt, ver = (j.get("format"), j.get("version")) if isinstance(j, dict) else (None, None)
    if fmt != "octocd-bench" or ver != 1 or type(ver) is not int:
        fail(f"{path}: format: {str(fmt)[:60]!r} version {str(ver)[:20]}; allowed: octocd-bench version 1 (a result "
             "of `octocd bench`) or an octocd trace")
    for key in ("sweep", "points", "machine", "build", "settings"):
        if key not in j:
            fail(f"{path}: {key}: missing; allowed: a complete octocd-bench result")
    _check_header(path, j)
    LOADED[path] = ("result", path, j)
    return LOADED[path]


TIMING = ("steps_per_s", "cpu_steps_per_s", "ms_per_frame")  # the gate's figures
TIMING_RANGE = (1e-12, 1e15)  # a positive finite repetition of a timing figure (steps/s or ms/frame)


def check_spread(name, x, timing=False):
    """One spread {median, min, max, n, values, ...} of a measured point (`name` names the
    file, point and key): n and the values within MAX_REPS, its figures numbers or null
    within MAX_FIGURE; a timing figure's positive finite values within TIMING_RANGE (null,
    non-finite or <= 0: not measured, which the gate judges)."""
    if not isinstance(x, dict) or type(x.get("n")) is not int:
        fail(f"{name}: {json.dumps(x)[:60]}; allowed: a spread {{median, min, max, n, ...}}")
    if not 0 <= x["n"] <= MAX_REPS:
        fail(f"{name}.n: {x['n']}; allowed: an integer in [0, {MAX_REPS}] (octocd bench --repeat is at most "
             f"{MAX_REPS})")
    vals = x.get("values")
    if vals is not None and not isinstance(vals, list):
        fail(f"{name}.values: {json.dumps(vals)[:60]}; allowed: the list of repetitions")
    if isinstance(vals, list) and len(vals) > MAX_REPS:
        fail(f"{name}.values: {len(vals)} values; allowed: at most {MAX_REPS} repetitions (octocd bench --repeat is "
             f"at most {MAX_REPS})")
    # null: a non-finite figure (JSON has no NaN); the gate fails such a point, exit 4.
    figs = [(f".{f}", x.get(f)) for f in ("median", "min", "max")] + [
        (f".values[{i}]", v) for i, v in enumerate(vals or [])]
    for sub, v in figs:
        if v is None:
            continue
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            if x["n"] > 0 or sub.startswith(".values"):
                fail(f"{name}{sub}: {json.dumps(v)[:60]}; allowed: a number or null")
            continue
        if not math.isfinite(v):
            continue
        if abs(v) > MAX_FIGURE or (timing and 0 < v < TIMING_RANGE[0]):
            lo = f"{TIMING_RANGE[0]:g} to " if timing else f"-{MAX_FIGURE:g} to "
            fail(f"{name}{sub}: {v!r} is out of range; allowed: null, or a number from {lo}{MAX_FIGURE:g} (a "
                 "figure octocd bench can measure)")


def check_points(path, j):
    """The fields the report reads, checked per point: one line naming file, point and key.
    A point id twice in one file is refused (two points, or one point counted twice)."""
    if not isinstance(j.get("points"), list):
        fail(f"{path}: points: not an array; allowed: an array of points (docs/bench-format.md)")
    seen = {}
    for i, p in enumerate(j["points"]):
        where = f"{path}: points[{i}]"
        if not isinstance(p, dict):
            fail(f"{where}: not an object; allowed: a point object")
        if not isinstance(p.get("id"), str) or len(p["id"]) > MAX_NAME:
            fail(f"{where}.id: {json.dumps(p.get('id'))[:80]}; allowed: a string of at most {MAX_NAME} characters")
        if p["id"] in seen:
            fail(f"{where}.id: '{p['id']}' is also points[{seen[p['id']]}]; allowed: each point once in a result file")
        seen[p["id"]] = i
        if "index" in p and not (type(p["index"]) is int and 0 <= p["index"] <= 1 << 40):
            fail(f"{where}.index: {json.dumps(p['index'])[:40]}; allowed: an integer >= 0")
        if "status" in p and not isinstance(p["status"], str):
            fail(f"{where}.status: {json.dumps(p['status'])[:40]}; allowed: ok, skipped, failed")
        if "reason" in p and not isinstance(p["reason"], str):
            fail(f"{where}.reason: {json.dumps(p['reason'])[:60]}; allowed: a string")
        if "params" in p:
            par = p["params"]
            if not isinstance(par, dict) or any(k in par and not (isinstance(par[k], str) and len(par[k]) <= MAX_NAME)
                                                for k in ("scene", "engine")) or any(
                    k in par and not isinstance(par[k], dict) for k in ("axes", "labels")):
                fail(f"{where}.params: {json.dumps(par)[:80]}; allowed: an object with strings scene and engine and "
                     "objects axes and labels")
        la = p.get("load_average")
        if la is not None and not (isinstance(la, list) and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and 0 <= x <= 1e6
                for x in la)):
            fail(f"{where}.load_average: {json.dumps(la)[:60]}; allowed: a list of load averages in [0, 1e6]")
        section = {RSA.KIND: RSA, RDV.KIND: RDV}.get(j["sweep"].get("kind"))
        if section is not None:
            # A section's kind: its statuses, and the scene and engine it sorts points by.
            if p.get("status") not in section.STATUSES:
                fail(f"{where}.status: {p.get('status')!r}; allowed: {', '.join(section.STATUSES)}")
            par = p.get("params")
            if not isinstance(par, dict) or not isinstance(par.get("scene"), str) or not isinstance(
                    par.get("engine"), str):
                fail(f"{where}.params: {str(par)[:60]}; allowed: an object with strings scene and engine")
            section.check_point(where, p, fail)
            continue
        if p.get("status") != "ok":
            continue
        if not isinstance(p.get("params"), dict):
            fail(f"{where}.params: {p.get('params')!r}; allowed: an object")
        spreads = []
        if "windows" in p:
            if not isinstance(p["windows"], dict) or not p["windows"]:
                fail(f"{where}.windows: {json.dumps(p['windows'])[:60]}; allowed: an object of windows")
            for wn, w in p["windows"].items():
                if len(wn) > MAX_NAME:
                    fail(f"{where}.windows: a window name of {len(wn)} characters; allowed: at most {MAX_NAME}")
                if not isinstance(w, dict):
                    fail(f"{where}.windows.{wn}: {json.dumps(w)[:60]}; allowed: an object of figures")
                spreads += [(f"windows.{wn}.{k}", k, v) for k, v in w.items() if k not in ("first", "last", "frames")]
                if "steps_per_s" not in w:
                    fail(f"{where}.windows.{wn}.steps_per_s: missing; allowed: a spread object")
        elif "ms_per_frame" in p:
            spreads.append(("ms_per_frame", "ms_per_frame", p["ms_per_frame"]))
        else:
            fail(f"{where}: neither windows nor ms_per_frame; allowed: a measured point (docs/bench-format.md)")
        for k, key, v in spreads:
            if k.endswith("stage_ms") and isinstance(v, dict):
                spreads_v = list(v.items())
            else:
                spreads_v = [("", v)]
            for sub, x in spreads_v:
                check_spread(f"{where}.{k}" + (f".{sub}" if sub else ""), x, key in TIMING)


def run_identity(j):
    """What names one run of octocd bench (a shard of it): host, start time (kept by --resume),
    shard, settings (engines, repetitions) and build; None for a result without a start time."""
    if not isinstance(j.get("started"), str):
        return None
    sh = j["settings"].get("shard") if isinstance(j["settings"].get("shard"), dict) else {}
    return (j["machine"].get("hostname"), j["started"], sh.get("index", 0), sh.get("count", 1),
            json.dumps(j["settings"], sort_keys=True), j["build"].get("build_id"))


def merge(results, pool=False):
    """Groups result files of one sweep definition on one machine; points by id. With pool
    (a side of the performance gate), a point in several files (runs of one build) is kept
    once, its other runs in g["pooled"][id] (the gate pools their repetitions)."""
    groups = {}
    files, runs_seen = {}, {}
    for path, j in results:
        # Each file and each run once: a copy of a result (or the same file named twice)
        # would count its repetitions again in the gate's pool.
        try:
            st = os.stat(path)
            ident = (st.st_dev, st.st_ino)
        except OSError:
            ident = path
        if ident in files:
            fail(f"{path}: the same file as {files[ident]}; allowed: each result file once")
        files[ident] = path
        run = run_identity(j)
        if run is not None and run in runs_seen:
            fail(f"{path}: the same run as {runs_seen[run]} (host {run[0]!r}, started {run[1]}, shard "
                 f"{run[2]}/{run[3]}): a copy counts its repetitions twice; allowed: each run (each shard of it) once")
        if run is not None:
            runs_seen[run] = path
        m = j["machine"]
        definition = j["sweep"]["definition"]
        if j["sweep"].get("kind") == "speed-accuracy":
            # Its lines stand alone (each judged against its own smallest dt), so runs with other
            # engines or scenes (Bullet in a run of its own, a copy without a scene an engine
            # cannot run) join one section when their ladder of time steps is the same.
            definition = {k: j["settings"].get(k) for k in ("dts", "sim_seconds")}
        key = (j["sweep"]["name"], json.dumps(definition, sort_keys=True),
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
        # Runs of the sweep with different engine sets (e.g. Bullet in a run of its own): each
        # run's files (its shards), settings and point count; the engines are their union in
        # the sweep definition's order.
        runs = {}
        for path in g["files"]:
            j = g["json"][path]
            key = tuple(j["settings"].get("engines", []))
            runs.setdefault(key, {"files": [], "settings": j["settings"],
                                  "total": j.get("points_total", len(j["points"]))})["files"].append(path)
        g["runs"] = list(runs.values())
        present = [e for key in runs for e in key]
        order = [e for e in g["first"]["sweep"].get("definition", {}).get("engines", []) if e in present]
        g["engines"] = order + [e for e in dict.fromkeys(present) if e not in order]
        g["points_total"] = sum(r["total"] for r in g["runs"])
        out.append(g)
    return out


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
