#!/usr/bin/python3
"""The CPU engine's and the judges' threads on a shared machine: default threads against one
thread, beside 0, 1 and 2 competing busy processes (issue 77 item 1).

    /usr/bin/python3 bench/thread_load.py [--octocd build/octocd] [--busy 0,1,2] [--repeat 5]
        [--frames 300] [--out thread-load.csv] [--cases run,worlds,validate]

Cases, each a process of its own:
  run       `octocd run datasets/scenes/bunny-random-400.json --frames F`: steps/s (the
            summary's, from the steps' own times: start-up left out)
  worlds    `octocd run datasets/scenes/bunny-stack-50.json --worlds 64 --frames F`:
            world-steps/s
  validate  `octocd validate --trace-in T` of a trace of bunny-random-400 (F frames, recorded
            once at the start): frames judged per wall second of the whole process
Each runs with the default threads and with OMP_NUM_THREADS=1 (which sets the CPU engine's
and the validators' default count, docs/settings.md; an octocd built with OpenMP honours it
too, so the script measures either build). The two variants alternate within each
repetition (A/B pairs: a change of load hits both). For every busy level the script starts
that many busy processes (pure Python spins), runs every case and variant --repeat times,
and stops them. Each row records the wall time and the CPU time (user + sys, from wait4) of
the process and the 1-minute load average at its end. The summary prints, per busy level and
case, the median (min-max) of each variant and the ratio of medians default / one thread
(>= 1: more threads are not slower). The CSV has a row per process.
"""
import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

from busy_load import busy_loops, write_rows

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def timed(cmd, env):
    """Runs cmd; returns (exit status, wall s, user + sys s, stdout)."""
    t0 = time.monotonic()
    with tempfile.TemporaryFile() as out:
        p = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env, cwd=ROOT)
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.monotonic() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        text = out.read().decode(errors="replace")
    return p.returncode, wall, ru.ru_utime + ru.ru_stime, text


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--octocd", default=os.path.join(ROOT, "build", "octocd"), help="the octocd binary")
    p.add_argument("--busy", default="0,1,2", help="competing busy processes, a list")
    p.add_argument("--repeat", type=int, default=5, help="repetitions of each case and variant (>= 1)")
    p.add_argument("--frames", type=int, default=300, help="steps of each run (and frames of the judged trace)")
    p.add_argument("--cases", default="run,worlds,validate", help="a subset of run,worlds,validate")
    p.add_argument("--out", default="thread-load.csv", help="CSV: a row per process")
    args = p.parse_args()
    if args.repeat < 1 or args.frames < 1:
        sys.exit("thread_load.py: --repeat and --frames must be >= 1")
    busy_levels = [int(b) for b in args.busy.split(",")]
    cases = args.cases.split(",")
    for c in cases:
        if c not in ("run", "worlds", "validate"):
            sys.exit(f"thread_load.py: --cases: unknown case '{c}'; allowed: run, worlds, validate")
    octocd = os.path.abspath(args.octocd)
    scenes = os.path.join(ROOT, "datasets", "scenes")
    work = tempfile.mkdtemp(prefix="thread-load-")
    summary = os.path.join(work, "summary.json")
    trace = os.path.join(work, "bunny-random-400.h5")
    base_env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}
    variants = {"default": base_env, "one": dict(base_env, OMP_NUM_THREADS="1")}

    if "validate" in cases:
        rc, _, _, text = timed([octocd, "run", os.path.join(scenes, "bunny-random-400.json"), "--frames",
                                str(args.frames), "--trace", trace, "--quiet"], base_env)
        if rc != 0:
            sys.exit(f"thread_load.py: recording the trace failed ({rc}):\n{text}")

    def command(case):
        if case == "run":
            return [octocd, "run", os.path.join(scenes, "bunny-random-400.json"), "--frames", str(args.frames),
                    "--quiet", "--summary-json", summary], "steps/s"
        if case == "worlds":
            return [octocd, "run", os.path.join(scenes, "bunny-stack-50.json"), "--worlds", "64", "--frames",
                    str(args.frames), "--quiet", "--summary-json", summary], "world-steps/s"
        return [octocd, "validate", "--trace-in", trace], "frames/s"

    def rate(case, wall):
        if case == "validate":
            return args.frames / wall
        with open(summary) as f:
            j = json.load(f)
        return j["world_steps_per_s"] if case == "worlds" else j["steps_per_s"]

    rows = []
    cpus = len(os.sched_getaffinity(0))
    for busy in busy_levels:
        with busy_loops(busy):
            for rep in range(args.repeat):
                for case in cases:
                    for variant, env in variants.items():
                        cmd, unit = command(case)
                        rc, wall, cpu, text = timed(cmd, env)
                        # validate exits 3 when a validator fails: still a measured judging
                        if rc not in (0, 3):
                            sys.exit(f"thread_load.py: {' '.join(cmd)} exited {rc}:\n{text[-2000:]}")
                        row = {"machine": platform.node(), "cpu": cpu_model(), "cpus": cpus, "busy": busy,
                               "case": case, "threads": variant, "rep": rep + 1, "rate": round(rate(case, wall), 1),
                               "unit": unit, "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
                               "load1": round(os.getloadavg()[0], 2)}
                        rows.append(row)
                        print(",".join(str(v) for v in row.values()), flush=True)
    write_rows(args.out, rows)

    print(f"\n{platform.node()} ({cpu_model()}), {cpus} CPUs; {args.octocd}; median (min-max) of {args.repeat}; "
          f"ratio = default / one thread (>= 1: more threads are not slower)")
    print(f"{'busy':>4}  {'case':<9} {'unit':<14} {'default threads':>26} {'one thread':>26} {'ratio':>6} "
          f"{'load1':>11}")
    for busy in busy_levels:
        for case in cases:
            sel = {v: [r for r in rows if r["busy"] == busy and r["case"] == case and r["threads"] == v]
                   for v in variants}
            med = {v: statistics.median(r["rate"] for r in sel[v]) for v in variants}
            cell = {v: f"{med[v]:,.0f} ({min(r['rate'] for r in sel[v]):,.0f}-{max(r['rate'] for r in sel[v]):,.0f})"
                    for v in variants}
            loads = [r["load1"] for r in sel["default"] + sel["one"]]
            print(f"{busy:>4}  {case:<9} {sel['one'][0]['unit']:<14} {cell['default']:>26} {cell['one']:>26} "
                  f"{med['default'] / med['one']:>6.2f} {min(loads):>5.1f}-{max(loads):<5.1f}")
    print(f"rows: {args.out}")


if __name__ == "__main__":
    main()
