#!/usr/bin/env python3
"""The performance gate's error rates (docs/bench-format.md, "Error rates"): runs of one
build of one sweep, gated pairwise (every ordered pair i != j: baseline run i, new run j),
as they are (false alarms: every flagged figure is one) and with the new run's steps/s
repetitions divided by each --slowdown factor (a uniform slowdown: the share flagged is the
gate's power). Uses reports/make_report.py's gate (same test, threshold and level).

    /usr/bin/python3 bench/gate_error_rates.py run-*.json [--threshold 5] [--level 0.05]
        [--slowdown 1.1 --slowdown 1.3]
"""
import argparse
import copy
import importlib.util
import itertools
import json
import os
import sys

spec = importlib.util.spec_from_file_location(
    "make_report", os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "reports", "make_report.py"))
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
    a = ap.parse_args()
    runs = [(p, json.load(open(p))) for p in a.runs]
    print(f"{len(runs)} runs, threshold {a.threshold:g} %, level {a.level:g}, timing {a.timing}")
    for factor in [1.0] + (a.slowdown or [1.1, 1.3]):
        flagged = total = 0
        worst = []
        ratios = []
        for (pb, jb), (pn, jn) in itertools.permutations(runs, 2):
            jn2 = slowed(jn, factor) if factor != 1.0 else copy.deepcopy(jn)
            jn2["build"]["build_id"] = "new"
            res = mr.gate_decide(mr.merge([(pb, jb)])[0], mr.merge([(pn, jn2)])[0], a.threshold, a.level,
                                  timing=a.timing)
            total += len(res["rows"])
            flagged += len(res["slower"])
            ratios += [r["ratio"] for r in res["rows"]]
            worst += [(r["ratio"], os.path.basename(pb), os.path.basename(pn), r["point"]) for r in res["slower"]]
        what = "same build" if factor == 1.0 else f"{100 * (factor - 1):g} % slower"
        print(f"{what}: {flagged} of {total} figures flagged ({100.0 * flagged / max(total, 1):.1f} %); "
              f"time ratios {min(ratios):.3f}-{max(ratios):.3f} (median {float(mr.np.median(ratios)):.3f})")
        if factor == 1.0:
            for w in sorted(worst, reverse=True)[:5]:
                print(f"  false alarm: ratio {w[0]:.3f}, baseline {w[1]}, new {w[2]}: {w[3]}")


if __name__ == "__main__":
    sys.exit(main())
