#!/usr/bin/python3
"""Writes a machine's record under reports/<machine>/ (reports/README.md) from raw results.

    record.py MACHINE IN_DIR OUT_DIR [--build ID] [--note TEXT]

IN_DIR holds what a run produced (scripts/record.sh makes it on this machine;
scripts/gpu-run.sh on a GPU machine):
  bench/<sweep>.json           `octocd bench` results (format octocd-bench); the shards of
                               one run, NAME-0.json .. NAME-<N-1>.json, become one NAME.csv
  validate*.txt                `octocd validate` tables (several runs in one file allowed)
  gpu-broadphase-scaling.json  `bench_gpu_broadphase --json` (optional)
  device.txt                   the machine (nvidia-smi, nproc, lscpu; optional)
  tests.txt                    test results to quote (optional; else the GoogleTest
                               totals of every test_*.txt are quoted)
  builds.txt                   `FILE.csv: BUILD` lines naming the build of a CSV whose
                               input does not name it (validate tables; optional)
OUT_DIR receives <sweep>.csv (a row per point and window; each figure as median, min, max,
n), gpu-broadphase-scaling.csv, validation.csv (a row per scene and validator), machine.txt
and README.md with the headline table. Files of OUT_DIR other than these are left alone
(scripts/record.sh clears the folder first). Exit 2 naming the file on unreadable input.
"""
import argparse
import csv
import glob
import json
import os
import re
import sys

SUMMARY_KEYS = ("median", "min", "max", "n")


def fail(msg):
    print(f"record.py: {msg}", file=sys.stderr)
    sys.exit(2)


def load_json(path):
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError) as e:
        fail(f"{path}: {e}")


def is_summary(v):
    return isinstance(v, dict) and "median" in v and "n" in v


def flatten_figures(prefix, d, row):
    """Summaries {median, min, max, n, ...} become PREFIX_median etc.; nested dicts of
    summaries (stage_ms) become PREFIX_<name>_median; scalars are copied."""
    for k, v in d.items():
        name = f"{prefix}{k}"
        if is_summary(v):
            for s in SUMMARY_KEYS:
                row[f"{name}_{s}"] = v[s]
        elif isinstance(v, dict) and v and all(is_summary(x) for x in v.values()):
            for sub, x in v.items():
                for s in SUMMARY_KEYS:
                    row[f"{name}_{sub}_{s}"] = x[s]
        elif isinstance(v, (int, float, str, bool)) or v is None:
            row[name] = v


def merged_results(paths):
    """(name, result) per input: the shards of one sweep run (files STEM-<i>.json whose
    settings.shard.count > 1, one build, one engine set) become one result named STEM whose
    points are the union, complete only when every shard is."""
    groups = {}
    for path in paths:
        result = load_json(path)
        if result.get("format") != "octocd-bench":
            fail(f"{path}: not an octocd-bench result (format {result.get('format')!r})")
        name = os.path.basename(path)[:-5]
        shard = result.get("settings", {}).get("shard", {})
        if shard.get("count", 1) > 1:
            name = re.sub(r"-\d+$", "", name)
            first = groups.get(name)
            if first is not None:
                key = lambda r: (r.get("sweep", {}).get("name"), r.get("build", {}).get("git_revision"),
                                 r.get("settings", {}).get("engines"), r.get("settings", {}).get("shard", {}).get("count"))
                if key(first) != key(result):
                    fail(f"{path}: a shard of {name} from another sweep, build, engine set or shard count; "
                         "allowed: the shards of one run")
                first["points"] = sorted(first["points"] + result.get("points", []), key=lambda p: p.get("index", 0))
                first["complete"] = first.get("complete") and result.get("complete")
                first["shards_found"] += 1
                continue
            result["shards_found"] = 1
        elif name in groups:
            fail(f"{path}: {name} appears twice")
        groups[name] = result
    for name, result in groups.items():
        if "shards_found" in result and result["shards_found"] < result["settings"]["shard"]["count"]:
            result["complete"] = False
        yield name, result


def bench_rows(result):
    """One row per point and window of an octocd-bench result."""
    rev = result.get("build", {}).get("git_revision", "")
    sweep = result.get("sweep", {}).get("name") or result.get("sweep", {}).get("definition", {}).get("name", "")
    for p in result.get("points", []):
        params = p.get("params", {})
        base = {
            "sweep": sweep,
            "id": p.get("id", ""),
            "scene": params.get("scene", ""),
            "engine": params.get("engine", ""),
            "broadphase": p.get("engine_broadphase", params.get("broadphase", "")),
            "traced": params.get("traced", "off"),
        }
        for axis, value in sorted(params.get("axes", {}).items()):
            base[f"axis_{axis}"] = value
        for k in ("bodies", "role", "verdict", "status", "reason", "under_load"):
            if k in p:
                base[k] = p[k]
        base["git_revision"] = rev
        windows = p.get("windows")
        if windows:
            # A point's own figures beside its windows' (wall_s, setup_s, setup_cpu_s).
            own = {k: v for k, v in p.items() if k in ("wall_s", "setup_s", "setup_cpu_s") and is_summary(v)}
            for wname, w in windows.items():
                row = dict(base, window=wname)
                flatten_figures("", dict(own, **w), row)
                yield row
        else:
            row = dict(base, window="")
            flatten_figures("", {k: v for k, v in p.items() if k not in base and k not in (
                "params", "device", "finished", "index", "load_average", "id")}, row)
            yield row


def write_csv(path, rows):
    rows = list(rows)
    cols = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols.append(k)
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=cols, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow(r)
    return rows


VALIDATE_HEAD = re.compile(r"^validate (\S+) \(engine (\S+), (\d+) frames, checks every (\d+)")
# New tables: "tier validator measured bound verdict figure"; older ones lack the tier.
ROW = re.compile(r"^(?:(physics|model)\s+)?([a-z][a-z0-9-]+)\s+(\S+)\s+(\S+)\s+(pass|FAIL|n/a)\s+(.*)$")


def validation_rows(paths):
    for path in paths:
        scene = engine = frames = every = ""
        try:
            lines = open(path, encoding="utf-8").read().splitlines()
        except OSError as e:
            fail(f"{path}: {e}")
        for line in lines:
            m = VALIDATE_HEAD.match(line)
            if m:
                scene, engine, frames, every = m.groups()
                continue
            m = ROW.match(line)
            if m and scene and m.group(2) not in ("validator", "tier"):
                tier, name, measured, bound, verdict, figure = m.groups()
                yield {"scene": scene, "engine": engine, "frames": frames, "every": every,
                       "tier": tier or "", "validator": name, "measured": measured,
                       "bound": bound, "verdict": verdict, "figure": figure.strip()}


def gpu_bp_rows(result):
    for r in result.get("results", []):
        yield {k: r.get(k) for k in ("broadphase", "n", "ok", "median_ms", "min_ms", "max_ms",
                                     "ns_per_body", "growth_per_doubling", "pairs", "exact_tests",
                                     "device_bytes")} | {"build": result.get("octocd", "")}


def fmt(x, digits=3):
    if x is None or x == "":
        return ""
    if isinstance(x, float):
        return f"{x:,.{digits}g}" if abs(x) < 1000 else f"{x:,.0f}"
    return f"{x:,}" if isinstance(x, int) else str(x)


def spread(r):
    """A point's steps/s as median (min-max), or "" for no point."""
    return f"{fmt(r['steps_per_s_median'])} ({fmt(r['steps_per_s_min'])}-{fmt(r['steps_per_s_max'])})" if r else ""


def headline_table5(rows):
    """Table 5's steps/s medians: a row per scene and midphase, a column per engine."""
    engines, cells, keys = [], {}, []
    for r in rows:
        if r.get("status") != "ok" or "steps_per_s_median" not in r or r.get("traced", "off") != "off":
            continue
        key = (r["scene"], r.get("axis_midphase", ""))
        if key not in keys:
            keys.append(key)
        if r["engine"] not in engines:
            engines.append(r["engine"])
        cells[key + (r["engine"],)] = r
    out = ["| scene | midphase | " + " | ".join(engines) + " |", "|---|---|" + "---|" * len(engines)]
    for key in keys:
        vals = [spread(cells.get(key + (e,))) for e in engines]
        out.append(f"| {key[0]} | {key[1]} | " + " | ".join(vals) + " |")
    out += ["", "Median (min-max) over the repetitions of each point; per-stage times and counts are "
            "in the table5 CSVs (an engine may come from its own run of the sweep, named in the file "
            "table above); `octocd report` sets the paper's figures beside them."]
    return out


def headline_small(rows):
    """small-scenes' steps/s medians: a row per scene, cpu and cuda, and cuda / cpu."""
    cells, scenes, bodies = {}, [], {}
    for r in rows:
        if r.get("status") != "ok" or "steps_per_s_median" not in r or r.get("traced", "off") != "off":
            continue
        if r["scene"] not in scenes:
            scenes.append(r["scene"])
        if r.get("bodies"):
            bodies[r["scene"]] = r["bodies"]
        cells[(r["scene"], r["engine"])] = r
    out = ["| scene | bodies | cpu | cuda | cuda / cpu |", "|---|---|---|---|---|"]
    for s in scenes:
        cpu, cuda = cells.get((s, "cpu")), cells.get((s, "cuda"))
        ratio = f"{cuda['steps_per_s_median'] / cpu['steps_per_s_median']:.2f}x" if cpu and cuda else ""
        out.append(f"| {s} | {fmt(bodies.get(s, ''))} | {spread(cpu)} | {spread(cuda)} | {ratio} |")
    out += ["", "Median (min-max) over the repetitions of each point (the ratio of the medians); the "
            "targets of [docs/gpu.md](../../docs/gpu.md): cuda >= 2x the same host's cpu engine on all "
            "its threads on every scene, bunny-stack-50 >= 60,000 steps/s."]
    return out


def headline_traced(rows):
    """Traced points (`bench --traced`): a row per scene (and midphase), a column per engine
    and trace mode, each traced figure with its ratio to the same engine's untraced one."""
    cells, keys, cols = {}, [], []
    for r in rows:
        if r.get("status") != "ok" or "steps_per_s_median" not in r:
            continue
        key = (r["scene"], r.get("axis_midphase", ""))
        if key not in keys:
            keys.append(key)
        col = (r["engine"], r.get("traced", "off"))
        if col not in cols:
            cols.append(col)
        cells[key + col] = r
    mid = any(k[1] for k in keys)
    head = "| scene | " + ("midphase | " if mid else "") + " | ".join(
        e if t == "off" else f"{e} {t}" for e, t in cols) + " |"
    out = [head, "|---|" + ("---|" if mid else "") + "---|" * len(cols)]
    for key in keys:
        vals = []
        for e, t in cols:
            r = cells.get(key + (e, t))
            base = cells.get(key + (e, "off"))
            v = spread(r)
            if r and base and t != "off":
                v += f" {r['steps_per_s_median'] / base['steps_per_s_median']:.2f}x"
            vals.append(v)
        out.append(f"| {key[0]} | " + (f"{key[1]} | " if mid else "") + " | ".join(vals) + " |")
    out += ["", "Median (min-max) over the repetitions; a traced point's steps/s counts the whole frame (the "
            "step, the copy-back of what the trace records, the write), `states`: a trace with the state "
            "every 10 frames, `contacts`: with every contact row; x: the ratio to the same engine untraced "
            "(docs/gpu.md, \"Traced runs\")."]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("machine")
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("--build", default="", help="the landed build the run used (commit)")
    ap.add_argument("--note", default="", help="a paragraph for the README (how it was made)")
    a = ap.parse_args()
    os.makedirs(a.output, exist_ok=True)
    made = []
    builds = {}
    table5 = []
    small = []
    for name, result in merged_results(sorted(glob.glob(os.path.join(a.input, "bench", "*.json")))):
        rows = write_csv(os.path.join(a.output, f"{name}.csv"), bench_rows(result))
        for r in rows:
            r["_file"] = name  # after the CSV is written: which run a headline reads
        sweep = result.get("sweep", {}).get("name", name)
        shards = result.get("settings", {}).get("shard", {}).get("count", 1)
        made.append((f"{name}.csv", f"`octocd bench {sweep}`: "
                     f"{len(rows)} rows, {'complete' if result.get('complete') else 'incomplete'}, "
                     f"engines {','.join(result.get('settings', {}).get('engines', []))}, "
                     f"repeat {result.get('settings', {}).get('repeat', '?')}"
                     + (f", {result['shards_found']} of {shards} shards" if shards > 1 else "")))
        builds[f"{name}.csv"] = result.get("build", {}).get("git_revision", "?")
        if sweep == "table5":  # the run named table5 first: its scenes and engines set the order
            table5 = rows + table5 if name == "table5" else table5 + rows
        if sweep == "small-scenes":
            small += rows
    gbp = os.path.join(a.input, "gpu-broadphase-scaling.json")
    gbp_rows = []
    if os.path.exists(gbp):
        result = load_json(gbp)
        gbp_rows = write_csv(os.path.join(a.output, "gpu-broadphase-scaling.csv"), gpu_bp_rows(result))
        made.append(("gpu-broadphase-scaling.csv", "`bench_gpu_broadphase`: ms per find and sort of the pair set, per broadphase and size"))
        builds["gpu-broadphase-scaling.csv"] = result.get("octocd", "?")
    vpaths = sorted(glob.glob(os.path.join(a.input, "validate*.txt")))
    vrows = []
    if vpaths:
        vrows = write_csv(os.path.join(a.output, "validation.csv"), validation_rows(vpaths))
        if not vrows:
            fail(f"{', '.join(vpaths)}: no validator rows found")
        fails = sorted({(r["scene"], r["validator"]) for r in vrows if r["verdict"] == "FAIL"})
        scenes = sorted({r["scene"] for r in vrows})
        made.append(("validation.csv", f"`octocd validate`: {len(scenes)} scenes, {len(vrows)} rows, "
                     f"{len(fails)} failing"))
    bpath = os.path.join(a.input, "builds.txt")
    if os.path.exists(bpath):
        for line in open(bpath, encoding="utf-8"):
            if ":" in line:
                k, v = line.split(":", 1)
                builds[k.strip()] = v.strip()
    machine = ""
    dev = os.path.join(a.input, "device.txt")
    if os.path.exists(dev):
        machine = open(dev, encoding="utf-8").read().strip()
    with open(os.path.join(a.output, "machine.txt"), "w", encoding="utf-8") as f:
        f.write(f"machine: {a.machine}\nbuild: {a.build or 'not stated'}\n{machine}\n")
    readme = [f"# Record: {a.machine}", "",
              f"Generated by `scripts/record.py` from the build **{a.build or 'not stated'}** "
              "(each CSV's `git_revision` / `build` column names the binary of every row). "
              "How to regenerate: [reports/README.md](../README.md).", ""]
    if a.note:
        readme += [a.note, ""]
    readme += ["| file | what | build |", "|---|---|---|", "| `machine.txt` | the machine | |"]
    for name, what in made:
        readme.append(f"| `{name}` | {what} | {builds.get(name, a.build)} |")
    if os.path.exists(os.path.join(a.output, "fuzz.md")):  # written by hand after scripts/fuzz.sh runs
        readme.append("| [`fuzz.md`](fuzz.md) | 10-minute runs of the fuzz targets under ASan + UBSan (scripts/fuzz.sh) "
                      "| named in the file |")
    if table5:
        readme += ["", "## Table 5 (paper section 4.1): steps/s", ""] + headline_table5(table5)
    if small:
        readme += ["", "## Small scenes (50 to 2048 bodies): steps/s", ""] + headline_small(small)
    for name, group in (("Small scenes", small), ("Table 5", table5)):
        traced = [r for r in group if r.get("traced", "off") != "off"]
        if traced:
            scenes = {r["scene"] for r in traced}
            same = [r for r in group if r["_file"] == traced[0]["_file"]]
            readme += ["", f"## {name}, traced (`bench --traced`): steps/s", ""] + headline_traced(same)
    if gbp_rows:
        readme += ["", "## GPU broadphase: ms to the sorted pair set", "",
                   "| broadphase | bodies | median ms (min-max) |", "|---|---|---|"]
        for r in gbp_rows:
            readme.append(f"| {r['broadphase']} | {r['n']:,} | {fmt(r['median_ms'])} ({fmt(r['min_ms'])}-{fmt(r['max_ms'])}) |")
    if vrows:
        fails = [r for r in vrows if r["verdict"] == "FAIL"]
        readme += ["", "## Validation", "",
                   f"{len({r['scene'] for r in vrows})} scenes; rows failing: "
                   + (", ".join(sorted({f"{r['scene']} {r['validator']}" for r in fails})) or "none") + "."]
    tests = os.path.join(a.input, "tests.txt")
    lines = []
    if os.path.exists(tests):
        lines = open(tests, encoding="utf-8").read().strip().splitlines()
    else:
        for path in sorted(glob.glob(os.path.join(a.input, "test_*.txt"))):
            text = open(path, encoding="utf-8", errors="replace").read()
            counts = [f"{m.group(2)} {m.group(1).lower()}" for m in
                      re.finditer(r"^\[  (PASSED|FAILED|SKIPPED) +\] (\d+) tests?", text, re.M)]
            lines.append(f"{os.path.basename(path)[:-4]}: {', '.join(counts) or 'no GoogleTest totals (read the file)'}")
    if lines:
        readme += ["", "## Tests", "", "```text"] + lines + ["```"]
    with open(os.path.join(a.output, "README.md"), "w", encoding="utf-8") as f:
        f.write("\n".join(readme) + "\n")
    print(f"record.py: {a.output}: {', '.join(n for n, _ in made)}, machine.txt, README.md")


if __name__ == "__main__":
    main()
