#!/usr/bin/env python3
"""Tables the batched-worlds benchmark (bench/run-worlds.sh): for every point of the result
files given (octocd bench -o ...; docs/bench-format.md) its copies, engine, bodies, steps/s and
world-steps/s (median and [min, max] over the repetitions), and, for the cuda points of K
copies that a hand-built scene of K copies matches, the ratio of the two (issue 70's
"--worlds K as fast as the hand-built scene"). Markdown on stdout.

Usage: bench/worlds_table.py worlds.json [hand-built.json ...]
"""
import json
import re
import sys


def fig(spread):
    return "%.4g [%.4g, %.4g]" % (spread["median"], spread["min"], spread["max"])


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    rows, hand = [], {}
    for path in sys.argv[1:]:
        with open(path) as f:
            res = json.load(f)
        for p in res["points"]:
            params = p.get("params", {})
            scene, engine = params.get("scene", "?"), params.get("engine", "?")
            m = re.search(r"-hand-built-x(\d+)$", scene)
            if p.get("status") != "ok":
                rows.append((scene, params.get("worlds", 1), engine, "-", p.get("status", "?") + ": " + p.get("reason", ""), "", None))
                continue
            win = next(iter(p["windows"].values()))
            sps = win["steps_per_s"]
            if m:  # a hand-built scene of K copies: one step steps K worlds
                k = int(m.group(1))
                wsps = {key: sps[key] * k for key in ("median", "min", "max")}
                hand[(engine, k)] = wsps["median"]
                rows.append((scene, k, engine, p.get("bodies"), fig(sps), fig(wsps), None))
            else:
                k = params.get("worlds", 1)
                wsps = win.get("world_steps_per_s", sps)
                rows.append((scene, k, engine, p.get("bodies"), fig(sps), fig(wsps), wsps["median"]))
    print("| scene | worlds | engine | bodies | steps/s median [min, max] | world-steps/s median [min, max] | vs hand-built |")
    print("|---|---:|---|---:|---|---|---:|")
    for scene, k, engine, bodies, sps, wsps, med in rows:
        ratio = ""
        if med is not None and (engine, k) in hand:
            ratio = "%.2fx" % (med / hand[(engine, k)])
        print("| %s | %s | %s | %s | %s | %s | %s |" % (scene, k, engine, bodies, sps, wsps, ratio))


if __name__ == "__main__":
    main()
