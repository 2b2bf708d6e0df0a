"""Synthetic history folders for `octocd report --history` (tests/report/test_history.py,
bench/history_scale.py): octocd-history files as `octocd bench --history` and
`scripts/nightly.sh --history` write them (docs/regression.md), with planted changes.

Each night has one bench result of one steps sweep ("nightly-sweep") of `points` points,
window `all`, 5 repetitions: steps/s = base_i x level(night) x exp(night noise) x exp(rep
noise), night noise ~ N(0, noise) on the log scale (a loaded machine's night-to-night
spread), repetition noise ~ N(0, noise / 3). Planted: `creep` (first night, nights, rate a
night: steps/s falls by `rate` a night over those nights and stays there), `step` (night,
ratio) on the points listed in `step_points`, and verdict rows: `rows` engine x scene x row
keys that pass, with `flip` (night, key): that row fails as new from that night on, and
`expected` keys that fail as expected every night.
"""
import datetime
import json
import math
import os

import numpy as np


def make_history(folder, nights=60, points=4, seed=1, noise=0.03, creep=None, creep_points=(0,), step=None,
                 step_points=(1,), rows=None, flip=None, expected=(), machine="ci-runner-1", start_night=0):
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    base = 1000.0 * np.exp(rng.uniform(-1, 1, points))
    day0 = datetime.datetime(2026, 1, 1, 2, 0, 0)
    rows = rows if rows is not None else [("bullet", "rot-stack-10", "penetration"), ("ode", "rot-slope", "friction")]
    for night in range(start_night, start_night + nights):
        when = day0 + datetime.timedelta(days=night)
        commit = f"{(night * 2654435761) % (1 << 32):08x}"
        level = np.ones(points)
        if creep is not None:
            first, length, rate = creep
            k = min(max(night - first + 1, 0), length)
            for p in creep_points:
                level[p] *= (1 - rate) ** k
        if step is not None and night >= step[0]:
            for p in step_points:
                level[p] *= step[1]
        pts = []
        for i in range(points):
            med = base[i] * level[i] * math.exp(rng.normal(0, noise))
            vals = [float(med * math.exp(rng.normal(0, noise / 3))) for _ in range(5)]
            sv = sorted(vals)
            pts.append({"id": f"scene-{i % 10} | midphase={i // 10} | cpu", "index": i, "status": "ok",
                        "params": {"scene": f"scene-{i % 10}", "engine": "cpu"},
                        "windows": {"all": {"first": 31, "last": 330,
                                            "steps_per_s": {"n": 5, "median": sv[2], "min": sv[0], "max": sv[-1],
                                                            "mean": sum(vals) / 5, "stdev": 0.0, "values": vals}}}})
        bench = {"format": "octocd-bench", "version": 1,
                 "sweep": {"name": "nightly-sweep", "kind": "steps", "description": "", "origin": "x",
                           "definition": {}},
                 "settings": {}, "machine": {"hostname": machine, "cpu": "Synthetic CPU (2 threads)", "threads": 2},
                 "build": {"build_id": f"0.9.0+{commit}", "git_revision": commit}, "started": when.isoformat() + "Z",
                 "points_total": points, "complete": True, "points": pts}
        verdicts = []
        for key in rows:
            st = "pass"
            if flip is not None and key == flip[1] and night >= flip[0]:
                st = "new"
            verdicts.append({"engine": key[0], "scene": key[1], "row": key[2], "verdict": "fail" if st == "new"
                             else "pass", "status": st})
        for key in expected:
            verdicts.append({"engine": key[0], "scene": key[1], "row": key[2], "verdict": "expected",
                             "status": "expected", "expectations": [{"outcome": "expected", "cause": key[2],
                                                                     "reason": "a known fault (witness test)"}]})
        entry = {"format": "octocd-history", "version": 1, "kind": "nightly",
                 "date": when.strftime("%Y-%m-%dT%H:%M:%SZ"),
                 "build": {"build_id": f"0.9.0+{commit}", "git_revision": commit, "version": "0.9.0",
                           "commit": commit},
                 "machine": {"hostname": machine, "cpu": "Synthetic CPU (2 threads)", "threads": 2},
                 "bench": [bench], "verdicts": verdicts}
        name = f"{when.strftime('%Y%m%dT%H%M%SZ')}-{commit}-nightly.json"
        with open(os.path.join(folder, name), "w") as f:
            json.dump(entry, f, separators=(",", ":"))
    return folder


def bench_result(started, commit, points=1, sweep="nightly-sweep", scene="scene-0", level=1.0):
    """A result of `octocd bench` started at `started` by build 0.9.0+COMMIT: point i at
    (1000 + 100 i) x level steps/s, min-max 1 % either side."""
    pts = [{"id": f"{scene}-{i} | cpu", "index": i, "status": "ok", "params": {"scene": scene, "engine": "cpu"},
            "windows": {"all": {"first": 1, "last": 10, "steps_per_s": {
                "n": 3, "median": (1000.0 + 100 * i) * level, "min": (990.0 + 99 * i) * level,
                "max": (1010.0 + 101 * i) * level}}}}
           for i in range(points)]
    return {"format": "octocd-bench", "version": 1,
            "sweep": {"name": sweep, "kind": "steps", "description": "", "origin": "x", "definition": {}},
            "settings": {}, "machine": {"hostname": "h", "cpu": "c", "threads": 2},
            "build": {"build_id": f"0.9.0+{commit}", "git_revision": commit}, "started": started,
            "points_total": points, "complete": True, "points": pts}
