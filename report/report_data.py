"""The report's inputs (report/make_report.py): bench results (octocd-bench JSON) checked
and merged per sweep and machine, and traces read through `octocd trace-summary --json`
(octocd's hardened reader; never h5py here)."""

import errno
import json
import os
import stat
import subprocess
import sys

from report_common import OCTOCD, fail, np
import report_speed_accuracy as RSA  # sweeps of kind speed-accuracy (design.md section 15)


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
        if j["sweep"].get("kind") == RSA.KIND:
            RSA.check_point(where, p, fail)
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
