#!/usr/bin/python3
"""The smallest process engine (docs/bring-your-engine.md): reads octocd's run request and
writes a version 2 trace. Boxes only: a dynamic box resting on the static body 0 (the floor)
with zero velocity stays at rest, held by a 4-row manifold at its bottom corners (each row
m g dt / 4); every other dynamic box falls freely (semi-implicit Euler, no contact: the
scene keeps it clear of everything). Usage: boxes_engine.py [--mode MODE] REQUEST.json.

MODE plants a fault for octocd's tests (tests/cli/test_cli_process_engines.cpp): ok (the
default), crash (exit 3), signal (SIGABRT), hang (sleep), truncated, bodies, frames,
hostile (escapes and 10 MB on stderr, exit 1), no-timing, quiet (progress lines, then exit 5
with nothing on stderr), stdout (as quiet, after a line on stdout). A `ready` setting names a file
written (with the process id) once the request is read: the tests wait on it. An `escape`
setting names a file: first a grandchild is started that leaves the engine's process tree
as far as a process can (a double fork, setsid(): its own session and process group,
re-parented), sleeps, and writes its process id there; octocd must end it all the same. A
`wall_step_seconds` setting is written as that attribute instead of the measured time (a
hostile timing: 0, 5e-324, nan, ...). Progress (docs/bring-your-engine.md): a line
`octocd-progress N` on stdout once set up (N 0) and after each frame N. A `hold` setting
names a FIFO: after saying frame F // 2 the engine waits until a byte can be read from it
(the tests read octocd's progress lines meanwhile, then release it)."""
import json
import os
import signal
import sys
import time


def start_escaped_grandchild(path):
    """Double fork and setsid(): a sleeper in a new session whose parent has exited; its
    process id is written to `path` (renamed into place) before this returns."""
    r, w = os.pipe()
    if os.fork() == 0:
        os.setsid()
        if os.fork() == 0:
            os.close(r)
            with open(path + ".tmp", "w") as f:
                f.write(str(os.getpid()))
            os.rename(path + ".tmp", path)
            os.write(w, b"1")
            os.close(w)
            while True:
                time.sleep(1)
        os._exit(0)
    os.close(w)
    os.read(r, 1)  # the grandchild's pid is written
    os.close(r)


def main():
    args = sys.argv[1:]
    mode = "ok"
    if args[:1] == ["--mode"]:
        mode, args = args[1], args[2:]
    with open(args[0]) as f:
        req = json.load(f)
    escape = req["settings"].get("escape")
    if escape:
        start_escaped_grandchild(escape)
    ready = req["settings"].get("ready")
    if ready:
        with open(ready + ".tmp", "w") as f:
            f.write(str(os.getpid()))
        os.rename(ready + ".tmp", ready)
    if mode == "crash":
        print("boxes_engine: planted crash", file=sys.stderr)
        sys.exit(3)
    if mode == "signal":
        os.kill(os.getpid(), signal.SIGABRT)
    if mode == "hang":
        while True:
            time.sleep(1)
    if mode in ("quiet", "stdout"):  # exit 5, stderr empty: progress lines (after an error line) on stdout
        if mode == "stdout":
            print("boxes_engine: planted failure said on stdout", flush=True)
        for frame in range(4):
            print(f"octocd-progress {frame}", flush=True)
        sys.exit(5)
    if mode == "hostile":
        sys.stderr.buffer.write(b"\x1b[2J\x1b]0;pwned\x07\x9b31m \xc2\x9b31m red\n" * 10 + b"x" * (10 << 20) + b"\nlast line \x1b[0m\n")
        sys.stderr.flush()
        sys.exit(1)

    # Imported once the request is read and the `ready` and `escape` files written: the
    # tests wait on those, and these imports take a second on a loaded machine.
    import h5py
    import numpy as np

    F, dt = req["frames"], req["dt"]
    g = np.array(req["gravity"], float)
    bodies = req["bodies"]
    n = len(bodies)
    x = np.zeros((F + 1, n, 3))
    v = np.zeros((F + 1, n, 3))
    x[0] = [b["position"] for b in bodies]
    v[0] = [b["velocity"] for b in bodies]
    lo = np.array([b["local_aabb_min"] for b in bodies], float)
    hi = np.array([b["local_aabb_max"] for b in bodies], float)
    mass = np.array([b["mass"] for b in bodies], float)
    dynamic = np.array([not b["static"] for b in bodies])
    floor_top = x[0, 0, 1] + hi[0, 1]
    resting = dynamic & (np.abs(x[0, :, 1] + lo[:, 1] - floor_top) < 1e-6) & (np.abs(v[0]).sum(axis=1) == 0)
    falling = dynamic & ~resting
    rows = []  # per frame: (pair, normal, point, jn)
    hold = req["settings"].get("hold")
    held = 0.0  # seconds waiting on `hold`, not stepping

    def progress(frame):
        print(f"octocd-progress {frame}", flush=True)

    progress(0)
    t0 = time.perf_counter()
    for f in range(1, F + 1):
        v[f], x[f] = v[f - 1], x[f - 1]
        v[f, falling] = v[f - 1, falling] + dt * g
        x[f, falling] = x[f - 1, falling] + dt * v[f, falling]
        frame_rows = []
        for i in np.flatnonzero(resting):
            for cx in (lo[i, 0], hi[i, 0]):
                for cz in (lo[i, 2], hi[i, 2]):
                    p = x[f - 1, i] + [cx, lo[i, 1], cz]
                    frame_rows.append(((0, i), (0, -1, 0), p, mass[i] * -g[1] * dt / 4))
        rows.append(frame_rows)
        progress(f)
        if hold and f == F // 2:
            h0 = time.perf_counter()
            with open(hold, "rb") as fifo:
                fifo.read(1)
            held += time.perf_counter() - h0
    wall = time.perf_counter() - t0 - held

    written = F - 1 if mode == "frames" else F
    m = n - 1 if mode == "bodies" else n
    with h5py.File(req["trace"], "w") as h:
        h.attrs.update(format="octocd-trace", version=2, engine="boxes_engine 1.0", scene=req["scene_json"],
                       dt=dt, gravity=g, collision_shape="box", deactivation="off")
        if mode != "no-timing":
            told = req["settings"].get("wall_step_seconds")
            h.attrs["wall_step_seconds"] = np.float64(wall if told is None else float(told))
        h["bodies/local_aabb_min"] = np.float32(lo[:m])
        h["bodies/local_aabb_max"] = np.float32(hi[:m])
        h["bodies/inverse_mass"] = np.float32([1 / w if w > 0 else 0 for w in mass[:m]])
        h["states/position"] = np.float32(x[:written + 1, :m])
        h["states/velocity"] = np.float32(v[:written + 1, :m])
        q = np.zeros((written + 1, m, 4), np.float32)
        q[:, :, 0] = 1
        h["states/orientation"] = q
        h["states/angular_velocity"] = np.zeros((written + 1, m, 3), np.float32)
        flat = [r for fr in rows[:written] for r in fr]
        counts = [len(fr) for fr in rows[:written]]
        h["contacts/offsets"] = np.int64(np.concatenate([[0], np.cumsum(counts)]))
        h["contacts/pair"] = np.uint32([r[0] for r in flat]).reshape(-1, 2)
        h["contacts/normal"] = np.float32([r[1] for r in flat]).reshape(-1, 3)
        h["contacts/point"] = np.float32([r[2] for r in flat]).reshape(-1, 3)
        h["contacts/depth"] = np.zeros(len(flat), np.float32)
        h["contacts/jn"] = np.float32([r[3] for r in flat])
        h["contacts/jt"] = np.zeros(len(flat), np.float32)
        h["contacts/jt3"] = np.zeros((len(flat), 3), np.float32)
    if mode == "truncated":
        size = os.path.getsize(req["trace"])
        with open(req["trace"], "r+b") as f:
            f.truncate(size // 2)


if __name__ == "__main__":
    main()
