#!/usr/bin/python3
"""Writes the seeds of the JSON-reading fuzz targets of issue 57 (fuzz/fuzz_shards.cpp,
fuzz/fuzz_bench_result.cpp, fuzz/fuzz_expect.cpp) into fuzz/regressions/<target>/:

    /usr/bin/python3 scripts/fuzz_json_seeds.py [OUT_DIR]   (default: fuzz/regressions)

- shards/: shard 1 of 2 of the run fuzz_shards pairs with its shard 0 (the same two rows,
  figures, bounds and tolerances texts as rows_of in fuzz_shards.cpp; every tolerance of
  validation/src/validate.cpp by name), so a seed merges and mutations reach every field;
- bench_result/: a result of each of fuzz_bench_result.cpp's three sweeps (steps with two
  windows, max-instances, broadphase) with its settings, the fixed machine and a point of
  each status, so a seed resumes with every finished point kept;
- expect/: expectations files of every form the reader takes (scene and trace entries,
  items, a comment).
The replay programs print what each seed reached (`merged: 2 rows`, `kept N point(s)`,
`N expectation(s)`): ctest's fuzz.<target>.regressions replays them in every build.
"""
import json
import os
import re
import sys

SRC = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
OUT = sys.argv[1] if len(sys.argv) > 1 else os.path.join(SRC, "fuzz", "regressions")


def tolerance_names():
    text = open(os.path.join(SRC, "validation", "src", "validate.cpp")).read()
    table = text[text.index("const std::vector<ToleranceEntry>& tolerance_table()"):]
    table = table[:table.index("return table;")]
    return re.findall(r'\{"([a-z0-9_]+)", &Tolerances::', table)


def spread(values):
    s = sorted(values)
    n = len(s)
    med = s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])
    return {"n": n, "median": med, "min": s[0], "max": s[-1], "mean": sum(s) / n, "stdev": 0.0, "values": values}


def write(folder, name, doc):
    os.makedirs(os.path.join(OUT, folder), exist_ok=True)
    with open(os.path.join(OUT, folder, name), "w") as f:
        f.write(doc if isinstance(doc, str) else json.dumps(doc, indent=1) + "\n")


def shard_seed():
    """Shard 1 of 2 (frames 46..90 of 90), rows as fuzz_shards.cpp's rows_of(1)."""
    shard = {"index": 1, "count": 2, "first_frame": 46, "last_frame": 90, "trace": "t.h5", "trace_bytes": 12345,
             "engine": "bullet", "bodies": 8, "frames": 90, "every": 3, "against": "none",
             "tolerances": {name: 0.5 for name in tolerance_names()}}
    rows = [
        {"tier": "physics", "name": "penetration", "figure": "deepest penetration (m)", "measured": 0.002,
         "bound": 0.0005, "verdict": "fail", "detail": "frame 1: pair (0, 1)", "judged": 10, "seconds": 0.5,
         "tolerances": "penetration_slops",
         "causes": [{"name": "penetration", "unit": "m", "count": 3, "worst": 0.002,
                     "examples": [{"frame": 46, "item": "pair (0, 1)", "figure": 0.002, "text": "too deep"}],
                     "items": ["pair (0, 1)", "pair (1, 2)"], "items_complete": True}]},
        {"tier": "physics", "name": "contact-completeness", "figure": "contacts missing or false", "measured": 2,
         "bound": 0, "verdict": "fail", "detail": "frame 3: pair (1, 2)", "judged": 20, "seconds": 0,
         "tolerances": "",
         "causes": [{"name": "missing-contact", "unit": "m", "count": 2, "worst": 0.01,
                     "examples": [{"frame": 48, "item": "pair (1, 2)", "figure": 0.01, "text": "missing"}],
                     "items": ["pair (1, 2)"], "items_complete": True}]},
    ]
    return {"trace": "t.h5", "engine": "bullet", "frames": 90, "every": 3, "against": "none", "shard": shard,
            "rows": rows}


MACHINE = {"hostname": "fuzz-host", "cpu": "fuzz-cpu", "gpu": "none", "threads": 2, "omp_threads": 1}
SWEEPS = {  # the same definitions as kSweeps in fuzz/fuzz_bench_result.cpp
    "steps": {"name": "fuzz-steps", "kind": "steps", "scenes": ["pile.json", "pile-b.json"], "engines": ["cpu"],
              "axes": [{"name": "midphase", "values": ["aabb-only", "1,2"], "labels": ["L0", "B"]}],
              "windows": [{"name": "early", "first": 1, "last": 2}, {"name": "late", "first": 3, "last": 4}],
              "repeat": 2},
    "mi": {"name": "fuzz-mi", "kind": "max-instances", "scenes": ["pile.json"], "engines": ["cpu"],
           "frames": 2, "warmup": 1, "repeat": 2, "max_instances": 64},
    "bp": {"name": "fuzz-bp", "kind": "broadphase", "bodies": [100, 1000], "broadphases": ["octree", "flat"],
           "engines": ["cpu"], "frames": 2, "warmup": 1, "repeat": 2},
}
SETTINGS = {  # result_settings(sweep, 0, 1) of each
    "steps": {"engines": ["cpu"], "repeat": 2, "frames": 4, "warmup": 0, "shard": {"index": 0, "count": 1}},
    "mi": {"engines": ["cpu"], "repeat": 2, "frames": 3, "warmup": 1, "shard": {"index": 0, "count": 1},
           "probe_repeat": 1, "target_steps_per_s": 30.0, "max_instances": 64, "resolution": 0.0,
           "search_time_s": 0, "window": {"name": "settled", "first": 2, "last": 3}},
    "bp": {"engines": ["cpu"], "repeat": 2, "frames": 2, "warmup": 1, "shard": {"index": 0, "count": 1},
           "warm_replays": 1, "min_time_ms": 50.0},
}


def result(kind, points):
    return {"format": "octocd-bench", "version": 1,
            "sweep": {"name": SWEEPS[kind]["name"], "kind": SWEEPS[kind]["kind"], "description": "",
                      "origin": "fuzz-sweep.json", "definition": SWEEPS[kind]},
            "settings": SETTINGS[kind], "machine": MACHINE, "build": {"build_id": "fuzz"},
            "started": "2026-01-01T00:00:00Z", "points_total": len(points), "complete": False, "points": points}


def bench_seeds():
    steps = []
    for i, (scene, mid) in enumerate([("pile", "aabb-only"), ("pile", "1,2"), ("pile-b", "aabb-only"),
                                      ("pile-b", "1,2")]):
        p = {"id": f"{scene} | midphase={mid} | cpu", "index": i,
             "params": {"scene": scene, "engine": "cpu", "axes": {"midphase": mid}}}
        if i == 2:
            p.update(status="skipped", reason="the engine lacks it")
        elif i == 3:
            p.update(status="failed", reason="boom")
        else:
            p.update(status="ok", windows={w: {"first": f, "last": l, "steps_per_s": spread([100.0 + i, 110.0 + i]),
                                               "step_ms": spread([9.0, 10.0])}
                                           for w, f, l in (("early", 1, 2), ("late", 3, 4))})
        steps.append(p)
    mi = []
    for i, (n, status, verdict, tail) in enumerate([(1, "ok", "pass", ""), (2, "ok", "below", ""),
                                                    (2, "ok", "below", " | confirm"), (64, "skipped", "limit", "")]):
        p = {"id": f"pile | instances={n} | cpu{tail}", "index": i, "status": status, "verdict": verdict,
             "role": "confirm" if tail else "probe", "params": {"scene": "pile", "engine": "cpu",
                                                                "axes": {"instances": n}}}
        if status == "ok":
            p["windows"] = {"settled": {"first": 2, "last": 3, "steps_per_s": spread([40.0 / n, 41.0 / n])}}
            p["cut"] = {"repetitions_run": 2, "repetitions_cut": 0}
        else:
            p["reason"] = "host memory: 64 instances do not fit (std::bad_alloc)"
        mi.append(p)
    bp = []
    k = 0
    for bodies in (100, 1000):
        for b in ("octree", "flat"):
            p = {"id": f"bodies={bodies} | {b} | cpu", "index": k, "status": "ok",
                 "ms_per_frame": spread([0.5 * bodies / 100, 0.6 * bodies / 100])}
            bp.append(p)
            k += 1
    write("bench_result", "steps-2-ok-1-skipped-1-failed.json", result("steps", steps))
    write("bench_result", "max-instances-3-probes-1-limit.json", result("mi", mi))
    write("bench_result", "broadphase-4-ok.json", result("bp", bp))
    finished = result("steps", steps)
    finished["complete"] = True
    write("bench_result", "steps-finished.json", finished)


def expect_seeds():
    write("expect", "scene-and-trace-entries.json", {
        "comment": "seed of fuzz_expect: both forms, items and none",
        "expectations": [
            {"scene": "box-stack", "row": "conservation", "cause": "energy", "items": ["group (1, 2, 3)"],
             "worst": 0.3, "reason": "a known energy gain"},
            {"trace": "t.h5", "row": "non-penetration-eq14", "cause": "non-penetration-eq14", "worst": 3,
             "reason": "three contacts"},
            {"scene": "bunny-stack-50", "row": "contact-geometry", "cause": "normal-angle", "worst": 12.5,
             "reason": "vertex normals"}]})
    write("expect", "empty.json", {"expectations": []})


def hostile_seeds():
    """The cases of issue 57's hostile tester, one file each (each refused, exit 2)."""
    import copy
    s = shard_seed()
    for name, edit in (("issue57-count-2e32-wrapped", lambda d: d["shard"].update(count=4294967298)),
                       ("issue57-measured-missing-nan", lambda d: d["rows"][0].pop("measured")),
                       ("issue57-judged-a-string-type-error", lambda d: d["rows"][1].update(judged="20")),
                       ("issue57-example-frame-2e62", lambda d: d["rows"][0]["causes"][0]["examples"][0].update(
                           frame=4611686018427387904))):
        d = copy.deepcopy(s)
        edit(d)
        write("shards", name + ".json", d)
    steps = json.load(open(os.path.join(OUT, "bench_result", "steps-2-ok-1-skipped-1-failed.json")))
    for name, edit in (("issue57-hostname-an-integer", lambda d: d["machine"].update(hostname=5)),
                       ("issue57-status-an-integer", lambda d: d["points"][0].update(status=3)),
                       ("issue57-n-2e64", lambda d: d["points"][0]["windows"]["early"]["steps_per_s"].update(
                           n=18446744073709551615))):
        d = copy.deepcopy(steps)
        edit(d)
        write("bench_result", name + ".json", d)
    write("expect", "issue57-key-twice.json",
          '{"expectations": [{"scene": "a", "row": "penetration", "cause": "penetration", "worst": 1, '
          '"worst": 2, "reason": "r"}]}\n')


if __name__ == "__main__":
    write("shards", "shard-1-of-2.json", shard_seed())
    bench_seeds()
    expect_seeds()
    hostile_seeds()
    print(f"wrote the seeds under {OUT}")
