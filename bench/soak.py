#!/usr/bin/python3
"""Soak runs (issue 10): long `octocd run`s watched from outside.

    /usr/bin/python3 bench/soak.py [--build build] [--engine cpu|cuda] [--frames 100000]
        [--scenes bunny-random-400,bunny-stack-50] [--state-every 1000] [--every 10]
        [--out soak-out] [--report soak-out/soak.md]

For each scene it starts `octocd run SCENE --frames N --engine E --trace OUT/SCENE.h5
--state-every K --quiet --summary-json OUT/SCENE.json` and, every `--every` seconds until
it ends:
- samples the process's resident memory (VmRSS and VmHWM of /proc/PID/status);
- opens the trace while it is being written (h5py, SWMR) and reads the flushed frames,
  the last kinetic energy and the last /states row, which must be finite.
At the end it checks the exit code (0), that the trace holds every frame, that every
kinetic energy and every recorded position and velocity is finite, and writes the
samples (OUT/SCENE-samples.csv) and a Markdown table (--report). Memory is "bounded"
when the RSS after the first 10 % of the run grows by less than 5 % (+ 8 MiB) to its end.

The engine stops a run with exit 1 at the first non-finite state (naming body and frame),
so a NaN shows as a failed run here too. Needs h5py: the Debian python (/usr/bin/python3).
"""
import argparse
import csv
import datetime
import json
import math
import os
import platform
import subprocess
import sys
import time

import h5py
import numpy as np


def rss_kib(pid):
    """VmRSS and VmHWM (KiB) of a running process, or (None, None)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            fields = dict(line.split(":", 1) for line in f if ":" in line)
        return int(fields["VmRSS"].split()[0]), int(fields["VmHWM"].split()[0])
    except (OSError, KeyError, ValueError):
        return None, None


def read_trace(path, full=False):
    """(frames, last kinetic energy, last state row finite, nonfinite count) of a trace being
    written; full=True scans every energy and state row."""
    with h5py.File(path, "r", swmr=True) as f:
        frames = min(f["frames"][k].shape[0] for k in f["frames"])
        ke = f["frames/kinetic_energy"]
        last_ke = float(ke[frames - 1]) if frames > 0 else float("nan")
        rows = min(f["states/position"].shape[0], f["states/velocity"].shape[0])
        last_ok = True
        if rows > 0:
            last_ok = bool(np.isfinite(f["states/position"][rows - 1]).all()
                           and np.isfinite(f["states/velocity"][rows - 1]).all())
        nonfinite = 0
        if full:
            nonfinite += int((~np.isfinite(ke[:frames])).sum())
            for r in range(rows):
                nonfinite += int((~np.isfinite(f["states/position"][r])).sum())
                nonfinite += int((~np.isfinite(f["states/velocity"][r])).sum())
        return frames, last_ke, last_ok, nonfinite, rows


def soak(args, scene):
    os.makedirs(args.out, exist_ok=True)
    trace = os.path.join(args.out, f"{scene}.h5")
    summary = os.path.join(args.out, f"{scene}.json")
    scene_file = os.path.join("datasets", "scenes", f"{scene}.json")
    cmd = [os.path.join(args.build, "octocd"), "run", scene_file, "--engine", args.engine,
           "--frames", str(args.frames), "--trace", trace, "--state-every", str(args.state_every),
           "--quiet", "--summary-json", summary]
    print(" ".join(cmd), flush=True)
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    samples = []  # (t_s, rss_kib, hwm_kib, frames, last_ke, last_state_finite)
    read_failures = 0
    while proc.poll() is None:
        time.sleep(args.every)
        rss, hwm = rss_kib(proc.pid)
        if rss is None:
            break
        frames, last_ke, last_ok = -1, float("nan"), False
        try:
            frames, last_ke, last_ok, _, _ = read_trace(trace)
        except Exception as e:  # noqa: BLE001 - any failure to read counts
            read_failures += 1
            print(f"  trace unreadable at {time.monotonic() - t0:.0f} s: {e}", flush=True)
        samples.append((time.monotonic() - t0, rss, hwm, frames, last_ke, last_ok))
        print(f"  {samples[-1][0]:7.0f} s  rss {rss / 1024:7.1f} MiB  frames {frames:7d}  "
              f"KE {last_ke:.4g}", flush=True)
    err = proc.stderr.read()
    proc.wait()
    wall = time.monotonic() - t0
    frames, last_ke, last_ok, nonfinite, rows = read_trace(trace, full=True)
    with open(os.path.join(args.out, f"{scene}-samples.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t_s", "rss_kib", "hwm_kib", "frames_flushed", "kinetic_energy", "last_state_finite"])
        w.writerows(samples)
    rss = [s[1] for s in samples]
    warm = [s[1] for s in samples if s[3] >= args.frames // 10] or rss or [0]
    result = {
        "scene": scene, "engine": args.engine, "frames": args.frames, "exit": proc.returncode,
        "stderr": err.strip(), "wall_s": wall, "frames_in_trace": frames, "state_rows": rows,
        "nonfinite_values": nonfinite, "last_kinetic_energy": last_ke, "samples": len(samples),
        "read_failures": read_failures,
        "unfinished_reads": sum(1 for s in samples if not s[5]),
        "rss_first_mib": (rss[0] / 1024) if rss else None,
        "rss_warm_mib": warm[0] / 1024, "rss_max_mib": max(rss or [0]) / 1024,
        "rss_last_mib": (rss[-1] / 1024) if rss else None,
        "trace_mib": os.path.getsize(trace) / 2**20,
    }
    try:
        with open(summary) as f:
            result["steps_per_s"] = json.load(f)["steps_per_s"]
    except (OSError, KeyError, ValueError):
        result["steps_per_s"] = None
    result["memory_bounded"] = bool(rss) and max(warm) <= warm[0] * 1.05 + 8 * 1024
    result["ok"] = (proc.returncode == 0 and frames == args.frames and nonfinite == 0
                    and read_failures == 0 and result["memory_bounded"])
    return result


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--build", default="build")
    p.add_argument("--engine", default="cpu", choices=["cpu", "cuda"])
    p.add_argument("--frames", type=int, default=100000)
    p.add_argument("--scenes", default="bunny-random-400,bunny-stack-50")
    p.add_argument("--state-every", type=int, default=1000)
    p.add_argument("--every", type=float, default=10.0, help="seconds between samples")
    p.add_argument("--out", default=None, help="folder for traces, samples, JSON (default soak-<engine>)")
    p.add_argument("--report", default=None, help="Markdown table to write (default soak-<engine>/soak-table.md)")
    args = p.parse_args()
    dev = args.engine
    args.out = args.out or f"soak-{dev}"
    report = args.report or os.path.join(args.out, "soak-table.md")
    results = [soak(args, s) for s in args.scenes.split(",")]
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=2)
    git = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True).stdout.strip()
    lines = [
        f"Soak runs, {datetime.datetime.utcnow():%Y-%m-%d %H:%M} UTC, git {git}, {platform.node()} "
        f"({os.cpu_count()} CPUs), engine {args.engine}, {args.frames} frames, trace state every "
        f"{args.state_every} frames, samples every {args.every:g} s.",
        "",
        "| scene | exit | frames in trace | wall (s) | steps/s | RSS first / after 10 % / max / last (MiB) | "
        "bounded | trace reads (failed) | non-finite values | last KE (J) | trace (MiB) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        sps = f"{r['steps_per_s']:.1f}" if r["steps_per_s"] else "-"
        first = f"{r['rss_first_mib']:.1f}" if r["rss_first_mib"] is not None else "-"
        last = f"{r['rss_last_mib']:.1f}" if r["rss_last_mib"] is not None else "-"
        lines.append(
            f"| {r['scene']} | {r['exit']} | {r['frames_in_trace']} | {r['wall_s']:.0f} | {sps} | "
            f"{first} / {r['rss_warm_mib']:.1f} / {r['rss_max_mib']:.1f} / {last} | "
            f"{'yes' if r['memory_bounded'] else 'NO'} | {r['samples']} ({r['read_failures']}) | "
            f"{r['nonfinite_values']} | {r['last_kinetic_energy']:.4g} | {r['trace_mib']:.1f} |")
    with open(report, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0 if all(r["ok"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
