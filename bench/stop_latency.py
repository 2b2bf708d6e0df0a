#!/usr/bin/python3
"""Stop latency: seconds from SIGINT to the end of an octocd command, with busy loops beside.

    /usr/bin/python3 bench/stop_latency.py [--build build] [--busy 2] [--repeat 5]
        [--cases NAME,...] [--out stop-latency.csv]

Each case starts one command on a scene whose step or frame's checks take about a second
(so the signal lands inside one), waits for an event (the first frame flushed into its
trace, the first point in its result file, a temporary trace appearing, the judge opening
the trace), sends SIGINT and measures the wall time until the process exits. The cases:
`run` (trace flushed every frame), `validate SCENE` (a step and its checks on a worker),
`validate --trace-in` (a trace of a lattice of 15,625 boxes touching their 26 neighbours
judged: the validators refuse coincident boxes), `bench` (a point of the dense scene), and
inside a reference engine's step (Bullet on a lattice of 13,824 touching boxes, 0.4-1 s
a step on the loaded 2-core VM): `run bullet`, `validate bullet`, `validate --determinism bullet`,
`bench steps bullet`, `bench speed-accuracy bullet`. `--busy N` runs N busy loops (pure
Python spins) beside them for the whole measurement, so the figures are those of a loaded
machine; the table names the load average. It checks what each case must keep: exit 130,
the stop line's kept text true of the files (the result's finished points, the trace's
frames), for `validate` the STOPPED line with the verdict of the frames judged (`--junit`
with its 'stopped' case), and no temporary file left in the case's TMPDIR.

The tests assert the behaviour (tests/cli/test_cli_limits_and_signals.cpp) with bounds
that hold on a loaded 2-core machine; this script records the times.
"""
import argparse
import json
import os
import platform
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time

from busy_load import busy_loops, write_rows


def lattice_scene(folder, per_axis, name="lattice"):
    """per_axis^3 boxes of half 0.3 m on a cubic lattice of spacing 0.55 m: each overlaps its
    26 neighbours (13 pairs a body), a frame as dense as the validators accept (coincident
    boxes are refused: limits::kMaxPairsPerBody in octocd/exact_pairs.hpp)."""
    h = 0.55 * (per_axis - 1) / 2
    path = os.path.join(folder, name + ".json")
    with open(path, "w") as f:
        json.dump({"name": name, "domain": {"min": [-h - 2] * 3, "max": [h + 2] * 3}, "gravity": [0, 0, 0],
                   "frames": 100000000,
                   "groups": [{"name": "b", "shape": {"box": [0.3, 0.3, 0.3]}, "count": per_axis ** 3,
                               "layout": {"type": "grid", "min": [-h] * 3, "max": [h] * 3, "spacing": 0.55}}]}, f)
    return path


def dense_scene(folder, count, name="dense"):
    path = os.path.join(folder, name + ".json")
    with open(path, "w") as f:
        json.dump({"name": name, "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]}, "gravity": [0, 0, 0],
                   "frames": 100000000,
                   "groups": [{"name": "b", "shape": {"box": [0.3, 0.3, 0.3]}, "count": count,
                               "layout": {"type": "grid", "min": [-0.02, -0.02, -0.02],
                                          "max": [0.02, 0.02, 0.02], "spacing": 0.001}}]}, f)
    return path


def wait_for(predicate, proc, limit=120.0):
    """Polls `predicate` (a file's state, cheap) until true; False if proc ended or time ran out."""
    end = time.monotonic() + limit
    while time.monotonic() < end:
        if predicate():
            return True
        if proc.poll() is not None:
            return False
        time.sleep(0.005)
    return False


def trace_frames(path):
    """Frames flushed into a trace being written (0 when it cannot be read yet)."""
    try:
        import h5py
        with h5py.File(path, "r", swmr=True) as f:
            return int(f.attrs.get("committed_frames", 0))
    except Exception:
        return 0


def result_points(path):
    """Points in a bench result file (-1 when it cannot be read yet)."""
    try:
        with open(path) as f:
            return len(json.load(f)["points"])
    except Exception:
        return -1


def kept_points(err, path):
    """The stop line's "keep(s) the N ..." count equals the points the result file holds."""
    m = re.search(r"keeps? the ([0-9]+) (?:finished )?point", err)
    return m is not None and int(m.group(1)) == result_points(path)


def kept_frames(err, path):
    """The stop line's "holds frames 1..N" equals the frames the trace holds."""
    m = re.search(r"holds frames 1\.\.([0-9]+)", err)
    return m is not None and int(m.group(1)) == trace_frames(path)


def measure(cmd, ready, cwd, env=None):
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    if not wait_for(ready, proc):
        proc.kill()
        out, err = proc.communicate()
        raise RuntimeError(f"{' '.join(cmd)}: no event to signal on\n{out}\n{err}")
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    return time.monotonic() - t0, proc.returncode, out, err


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--build", default="build")
    p.add_argument("--busy", type=int, default=2, help="busy loops beside the command (0 .. 64)")
    p.add_argument("--repeat", type=int, default=5, help="repetitions of each case (>= 1)")
    p.add_argument("--out", default="stop-latency.csv", help="CSV: a row per case and repetition")
    p.add_argument("--cases", default="", help="comma-separated case names (default: every case)")
    args = p.parse_args()
    if not 0 <= args.busy <= 64 or args.repeat < 1:
        sys.exit("stop_latency: --busy in 0 .. 64 and --repeat >= 1")
    octocd = os.path.abspath(os.path.join(args.build, "octocd"))
    work = tempfile.mkdtemp(prefix="octocd-stop-")
    scene = dense_scene(work, 2000)
    judged = lattice_scene(work, 25)
    trace_in = os.path.join(work, "judged.h5")
    subprocess.run([octocd, "run", judged, "--frames", "4", "--state-every", "1", "--contacts", "--quiet",
                    "--trace", trace_in], check=True, stdout=subprocess.DEVNULL)
    sweep = os.path.join(work, "sweep.json")
    with open(sweep, "w") as f:
        json.dump({"name": "stop", "kind": "steps", "scenes": ["dense.json"], "engines": ["cpu"], "warmup": 0,
                   "frames": 1000, "repeat": 1}, f)

    def case_run(k):
        t = os.path.join(work, f"run-{k}.h5")
        return ([octocd, "run", scene, "--trace", t, "--state-every", "1", "--quiet"],
                lambda: trace_frames(t) >= 1, lambda out, err: True)

    def case_validate(k):
        t, j = os.path.join(work, f"v-{k}.h5"), os.path.join(work, f"v-{k}.xml")
        return ([octocd, "validate", scene, "--frames", "5", "--every", "1000", "--against", "none", "--trace", t,
                 "--junit", j], lambda: trace_frames(t) >= 1,
                lambda out, err: "STOPPED: the table covers frames 1.." in out and "stopped" in open(j).read())

    def case_trace_in(k):
        j = os.path.join(work, f"ti-{k}.xml")
        started = time.monotonic()
        return ([octocd, "validate", "--trace-in", trace_in, "--against", "none", "--threads", "1", "--junit", j],
                lambda: time.monotonic() - started > 1.5,
                lambda out, err: "STOPPED:" in out and "stopped" in open(j).read())

    def case_bench(k):
        r = os.path.join(work, f"b-{k}.json")
        started = time.monotonic()
        return ([octocd, "bench", sweep, "-o", r, "--scene-dir", work, "--quiet"],
                lambda: time.monotonic() - started > 3.0, lambda out, err: True)

    # Inside a reference engine's step: Bullet on 24^3 touching boxes, 0.4-1 s a step (2-core VM, loaded).
    lattice_scene(work, 24, "hulls")
    with open(os.path.join(work, "small.json"), "w") as f:
        json.dump({"name": "small", "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]}, "walls": "floor", "frames": 10,
                   "groups": [{"name": "b", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 8,
                               "layout": {"type": "grid", "min": [-0.5, 0.1, -0.5], "max": [0.5, 1.5, 0.5]}}]}, f)
    sa_sweep, steps_sweep = os.path.join(work, "sa.json"), os.path.join(work, "steps.json")
    with open(sa_sweep, "w") as f:
        json.dump({"name": "stop-sa", "kind": "speed-accuracy", "engines": ["bullet"], "repeat": 1,
                   "scenes": ["small.json", "hulls.json"], "dts": [0.01], "sim_seconds": 0.2, "iterations": [5],
                   "geometries": ["hull"], "rotation": [False]}, f)
    with open(steps_sweep, "w") as f:
        json.dump({"name": "stop-steps", "kind": "steps", "scenes": ["small.json", "hulls.json"],
                   "engines": ["bullet"], "warmup": 0, "frames": 20, "repeat": 1}, f)
    hulls = os.path.join(work, "hulls.json")

    def tmp_env(k, name):
        d = os.path.join(work, f"tmp-{name}-{k}")
        os.makedirs(d, exist_ok=True)
        return d, dict(os.environ, TMPDIR=d)

    def case_run_bullet(k):
        t = os.path.join(work, f"rb-{k}.h5")
        return ([octocd, "run", hulls, "--engine", "bullet", "--trace", t, "--state-every", "1", "--quiet"],
                lambda: trace_frames(t) >= 1, lambda out, err: kept_frames(err, t))

    def case_validate_bullet(k):
        t, j = os.path.join(work, f"vb-{k}.h5"), os.path.join(work, f"vb-{k}.xml")
        return ([octocd, "validate", hulls, "--engine", "bullet", "--frames", "1000", "--every", "1000",
                 "--against", "none", "--trace", t, "--junit", j], lambda: trace_frames(t) >= 1,
                lambda out, err: kept_frames(err, t))

    def case_determinism_bullet(k):
        d, env = tmp_env(k, "det")
        return ([octocd, "validate", hulls, "--engine", "bullet", "--frames", "1000", "--determinism",
                 "--threads", "2"], lambda: len(os.listdir(d)) > 0, lambda out, err: True, env)

    def case_bench_steps_bullet(k):
        r = os.path.join(work, f"bs-{k}.json")
        return ([octocd, "bench", steps_sweep, "-o", r, "--scene-dir", work, "--quiet"],
                lambda: result_points(r) >= 1, lambda out, err: kept_points(err, r))

    def case_bench_sa_bullet(k):
        r, c = os.path.join(work, f"sa-{k}.json"), os.path.join(work, f"sa-{k}.csv")
        return ([octocd, "bench", sa_sweep, "-o", r, "--csv", c, "--scene-dir", work, "--quiet"],
                lambda: result_points(r) >= 1, lambda out, err: kept_points(err, r))

    cases = [("run", case_run), ("validate SCENE", case_validate), ("validate --trace-in", case_trace_in),
             ("bench", case_bench), ("run bullet", case_run_bullet), ("validate bullet", case_validate_bullet),
             ("validate --determinism bullet", case_determinism_bullet), ("bench steps bullet", case_bench_steps_bullet),
             ("bench speed-accuracy bullet", case_bench_sa_bullet)]
    if args.cases:
        wanted = args.cases.split(",")
        unknown = [c for c in wanted if c not in dict(cases)]
        if unknown:
            sys.exit(f"stop_latency: --cases {','.join(unknown)}: unknown; allowed: {', '.join(n for n, _ in cases)}")
        cases = [c for c in cases if c[0] in wanted]
    rows = []
    with busy_loops(args.busy):
        time.sleep(1.0)  # the spinners running before the first case
        for name, make in cases:
            for k in range(args.repeat):
                cmd, ready, kept, *env = make(k)
                seconds, code, out, err = measure(cmd, ready, work, env[0] if env else None)
                tmp = env[0]["TMPDIR"] if env else None
                ok = code == 128 + signal.SIGINT and kept(out, err) and not (tmp and os.listdir(tmp))
                if not ok:
                    print(f"{name} #{k}: exit {code}; stderr: {err.strip()[-400:]}", flush=True)
                rows.append({"case": name, "repetition": k, "seconds": round(seconds, 4), "exit": code,
                             "kept": ok, "load1": round(os.getloadavg()[0], 2), "busy": args.busy})
                print(f"{name:22s} #{k}: {seconds:.3f} s, exit {code}, kept {ok}", flush=True)
    write_rows(args.out, rows)
    print(f"\n{platform.node()}, {os.cpu_count()} CPUs, {args.busy} busy loops beside; load average "
          f"{os.getloadavg()[0]:.2f}; seconds from SIGINT to exit, median (min-max) of {args.repeat}:")
    for name, _ in cases:
        if not any(r["case"] == name for r in rows):
            continue
        t = [r["seconds"] for r in rows if r["case"] == name]
        kept = all(r["kept"] for r in rows if r["case"] == name)
        print(f"| {name} | {statistics.median(t):.3f} ({min(t):.3f}-{max(t):.3f}) | {'kept' if kept else 'LOST'} |")
    return 0 if all(r["kept"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
