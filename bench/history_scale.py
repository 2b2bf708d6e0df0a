#!/usr/bin/python3
"""`octocd report --history` at scale (issue 69 item 3; docs/regression.md): a synthetic
history of NIGHTS nights x POINTS steps points (plus an engine matrix of verdict rows) is
written, then `octocd report --history` draws it; prints the wall time, the page's size and
the machine's load (`uptime` before and after: the time moves with other processes), and
with --fp-histories N the change-point test's false-positive rate over N flat histories of
POINTS series x NIGHTS nights at the default level.

    bench/history_scale.py [--octocd build/octocd] [--nights 1000] [--points 100]
                           [--work /tmp/octocd-history-scale] [--fp-histories 0]
"""
import argparse
import os
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
SRC = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(SRC, "tests", "report"))
sys.path.insert(0, os.path.join(SRC, "report"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--octocd", default=os.path.join(SRC, "build", "octocd"))
    ap.add_argument("--nights", type=int, default=1000)
    ap.add_argument("--points", type=int, default=100)
    ap.add_argument("--work", default="/tmp/octocd-history-scale")
    ap.add_argument("--fp-histories", type=int, default=0)
    ap.add_argument("--level", type=float, default=0.05)
    ap.add_argument("--keep", action="store_true", help="reuse the history already in --work")
    a = ap.parse_args()
    from history_synth import make_history
    engines = ["cpu", "bullet", "mujoco", "ode", "dart", "cuda"]
    scenes = ["rot-stack-10", "rot-slope", "rot-drop-220", "rot-pile-1000", "bunny-stack-50", "rot-spin-free"]
    rows = ["broadphase-completeness", "contact-completeness", "contact-geometry", "penetration", "friction",
            "conservation", "momentum-balance", "free-flight", "bullet-dynamics", "candidate-sets",
            "midphase-completeness", "non-penetration-eq14", "friction-monotonicity", "impulse-conservation",
            "applied-state", "analytic"]
    keys = [(e, s, r) for e in engines for s in scenes for r in rows]
    hist = os.path.join(a.work, "history")
    out = os.path.join(a.work, "out")
    if not a.keep:
        shutil.rmtree(a.work, ignore_errors=True)
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.time()
    if not (a.keep and os.path.isdir(hist)):
        make_history(hist, nights=a.nights, points=a.points, seed=1, creep=(a.nights // 2, 10, 0.02),
                     step=(3 * a.nights // 4, 0.9), rows=keys, flip=(a.nights - 30, keys[5]),
                     expected=[("mujoco", "rot-pile-1000", "conservation")])
    size = sum(os.path.getsize(os.path.join(hist, f)) for f in os.listdir(hist))
    print(f"history: {a.nights} nights x {a.points} points, {len(keys) + 1} verdict rows a night, "
          f"{size / 1e6:.1f} MB in {len(os.listdir(hist))} files (written in {time.time() - t0:.1f} s)")
    print("load before:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    import resource
    t0 = time.time()
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run([a.octocd, "report", "--history", hist, "-o", out], capture_output=True, text=True)
    wall = time.time() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)
    print("load after: ", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    if r.returncode != 0:
        print(r.stdout, r.stderr)
        sys.exit(1)
    page = os.path.getsize(os.path.join(out, "index.html"))
    csvs = sum(os.path.getsize(os.path.join(out, f)) for f in os.listdir(out) if f.endswith(".csv"))
    print(r.stdout.strip())
    print(f"report --history: {wall:.1f} s wall on {os.cpu_count()} cores, {cpu:.1f} CPU s (all its processes: "
          f"on {os.cpu_count()} idle cores about {cpu / (os.cpu_count() or 1):.1f} s); page {page / 1e6:.2f} MB "
          f"(limit 10 MB), CSV {csvs / 1e6:.1f} MB")
    if a.fp_histories:
        import numpy as np
        import report_history as H
        rng = np.random.default_rng(7)
        hit = 0
        t0 = time.time()
        for _ in range(a.fp_histories):
            if any(H.change_points(rng.normal(0, 0.03, a.nights), a.level / a.points) for _ in range(a.points)):
                hit += 1
        print(f"false positives: {hit} of {a.fp_histories} flat histories ({a.points} series x {a.nights} nights, "
              f"Gaussian noise) had a change point at level {a.level:g} ({hit / a.fp_histories:.3f}; "
              f"{time.time() - t0:.1f} s)")


if __name__ == "__main__":
    main()
