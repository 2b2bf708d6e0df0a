#!/usr/bin/env python3
"""The performance gate's error rates (docs/bench-format.md, "Error rates"): runs of one
build of one sweep, gated pairwise (every choice of --runs-per-side k runs as the baseline
and k other runs as the new side; k = 1: every ordered pair of runs),
as they are (false alarms: every flagged figure is one) and with the new run's steps/s
repetitions divided by each --slowdown factor (a uniform slowdown: the share flagged is the
gate's power). Uses report/make_report.py's gate (same test, threshold and level).

    /usr/bin/python3 bench/gate_error_rates.py run-*.json [--threshold 10] [--level 0.05]
        [--slowdown 1.1 --slowdown 1.3] [--runs-per-side 2] [--timing auto|cpu|wall]
"""
import argparse
import copy
import importlib.util
import itertools
import json
import os
import sys

spec = importlib.util.spec_from_file_location(
    "make_report", os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "report", "make_report.py"))
mr = importlib.util.module_from_spec(spec)
spec.loader.exec_module(mr)


def slowed(j, factor):
    """A copy of a result with every timing repetition `factor` times slower."""
    j = copy.deepcopy(j)
    j["build"]["build_id"] = f"{j['build'].get('build_id')}+slowed{factor:g}"
    for p in j["points"]:
        if p.get("status") != "ok":
            continue
        spreads = {id(s): (s, hib) for cpu in (False, True) for _, s, hib in mr.timing_of(p, cpu)}
        for s, hib in spreads.values():
            s["values"] = [v / factor if hib else v * factor for v in s["values"]]
            s.update({k: v for k, v in zip(("median", "min", "max"), (
                float(mr.np.median(s["values"])), min(s["values"]), max(s["values"])))})
    return j


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--threshold", type=float, default=10.0)
    ap.add_argument("--level", type=float, default=0.05)
    ap.add_argument("--slowdown", type=float, action="append", default=[])
    ap.add_argument("--timing", choices=["auto", "cpu", "wall"], default="auto")
    ap.add_argument("--runs-per-side", type=int, default=1,
                    help="runs pooled on each side (the gate's --baseline R1 --baseline R2 NEW1 NEW2)")
    a = ap.parse_args()
    runs = [(p, json.load(open(p))) for p in a.runs]
    print(f"{len(runs)} runs, threshold {a.threshold:g} %, level {a.level:g}, timing {a.timing}")
    k = a.runs_per_side
    if 2 * k > len(runs):
        sys.exit(f"--runs-per-side {k}: needs at least {2 * k} runs")
    # Every choice of k baseline runs and k other runs as the new side.
    pairs = [(b, n) for b in itertools.combinations(runs, k)
             for n in itertools.combinations([r for r in runs if all(r is not x for x in b)], k)]
    print(f"{len(pairs)} (baseline, new) choices of {k} run(s) a side")
    for factor in [1.0] + (a.slowdown or [1.1, 1.3]):
        flagged = total = 0
        worst = []
        ratios = []
        for b, n in pairs:
            news = []
            for pn, jn in n:
                jn2 = slowed(jn, factor) if factor != 1.0 else copy.deepcopy(jn)
                jn2["build"]["build_id"] = "new"
                news.append((pn, jn2))
            bases = []
            for pb, jb in b:
                jb2 = copy.deepcopy(jb)
                jb2["build"]["build_id"] = "base"
                bases.append((pb, jb2))
            res = mr.gate_decide(mr.merge(bases, pool=True)[0], mr.merge(news, pool=True)[0], a.threshold, a.level,
                                 timing=a.timing)
            total += len(res["rows"])
            flagged += len(res["slower"])
            ratios += [r["ratio"] for r in res["rows"]]
            worst += [(r["ratio"], "+".join(os.path.basename(x[0]) for x in b),
                       "+".join(os.path.basename(x[0]) for x in n), r["point"]) for r in res["slower"]]
        what = "same build" if factor == 1.0 else f"{100 * (factor - 1):g} % slower"
        print(f"{what}: {flagged} of {total} figures flagged ({100.0 * flagged / max(total, 1):.1f} %); "
              f"time ratios {min(ratios):.3f}-{max(ratios):.3f} (median {float(mr.np.median(ratios)):.3f})")
        if factor == 1.0:
            for w in sorted(worst, reverse=True)[:5]:
                print(f"  false alarm: ratio {w[0]:.3f}, baseline {w[1]}, new {w[2]}: {w[3]}")

if __name__ == "__main__":
    sys.exit(main())
