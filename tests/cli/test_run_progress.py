#!/usr/bin/python3
"""`octocd run`'s progress is true (issue 80 item 5): with a process engine (the Python
engine pyboxes of tests/data/process_engines/engines.json), stdout and stderr to one file:

- the process's start-up is said before it runs ("engine pyboxes: starting ...") and when
  it has run ("its process ran N frames in T s (S s in its step calls, U s start-up, ...)");
- its steps are said as it runs them ("frame N/40 ... (its process as it runs, ...)"),
  before it ends; every line read from its trace comes after those and before the summary
  (flush order);
- the summary's set-up includes the process's start-up U (not 0.00 s), and the stepping's
  wall time excludes it;
- the pair counts the engine does not report (its trace has no /pairs) read n/a, not 0;
- held on a FIFO (its `hold` setting) after saying frame 20 of 40, the engine's start-up
  and frame 20 are read from `run`'s and from `validate`'s output, and its start-up from
  `bench`'s, while it waits: the test waits on those lines (bounded at 60 s: a failure,
  never a wait that passes), then releases it.

Usage: test_run_progress.py OCTOCD_BIN SOURCE_DIR WORK_DIR
Exit 0 pass, 1 fail, 77 skipped (the engine's check fails: no h5py or numpy).
"""
import os
import re
import selectors
import shutil
import subprocess
import sys
import time


def fail(why):
    print(f"FAIL: {why}")
    sys.exit(1)


def held_run(args, fifo, wanted, env):
    """Runs `args` (stdout and stderr to one pipe) with the engine held on `fifo`; waits for
    a line matching each of `wanted` in order, all while the engine waits, then releases it.
    Returns (exit code, the whole output, the lines read before the release)."""
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + 60.0  # a functional bound: reaching it fails the test
    data, lines, k = b"", [], 0
    while k < len(wanted):
        left = deadline - time.monotonic()
        if left <= 0 or not sel.select(left):
            proc.kill()
            proc.wait()
            fail(f"{args[3]}: no line matching '{wanted[k]}' while the engine waits (60 s) in:\n" + "\n".join(lines))
        chunk = os.read(proc.stdout.fileno(), 65536)
        if not chunk:
            proc.wait()
            fail(f"{args[3]} ended (exit {proc.returncode}) before a line matching '{wanted[k]}':\n"
                 + "\n".join(lines))
        data += chunk
        *done, rest = data.split(b"\n")
        data = rest
        for line in done:
            lines.append(line.decode("utf-8", "replace"))
            if k < len(wanted) and re.search(wanted[k], lines[-1]):
                k += 1
    with open(fifo, "wb") as f:  # the engine goes on
        f.write(b"1")
    rest = proc.stdout.read()
    proc.wait()
    return proc.returncode, "\n".join(lines) + "\n" + (data + rest).decode("utf-8", "replace"), lines


def check_streamed(octocd, engines, data, work, env):
    """run and validate with pyboxes held after frame 20 of 40: its start-up and frame 20
    are said while it waits; bench (tests/data/process_engines/bench.json: pyboxes, 40
    frames, one repetition) says its start-up while it waits (its point's line, from the
    same progress lines)."""
    for command in ("run", "validate", "bench"):
        fifo = os.path.join(work, f"hold-{command}")
        os.mkfifo(fifo)
        if command == "bench":
            args = [octocd, "--engines-file", engines, command, os.path.join(data, "bench.json"), "--scene-dir", data,
                    "-o", os.path.join(work, "bench-held.json"), "--pyboxes", f"hold={fifo}"]
            wanted = [r"^\[1/1\] .*: engine pyboxes: its process started in [0-9.]+ s; stepping$"]
        else:
            args = [octocd, "--engines-file", engines, command, os.path.join(data, "boxes.json"), "--engine",
                    "pyboxes", "--frames", "40", "--pyboxes", f"hold={fifo}"]
            wanted = [r"^engine pyboxes: starting .* for 40 frames",
                      r"^engine pyboxes: its process started in [0-9.]+ s", r"^frame 20/40 .*\(its process as it runs"]
        rc, text, before = held_run(args, fifo, wanted, env)
        if rc not in (0, 3):
            fail(f"{command} exit {rc}:\n{text}")
        if command == "run" and not re.search(r"^engine pyboxes: its process ran 40 frames in", text, re.M):
            fail(f"run: no line for the process's end after the release:\n{text}")
        print(f"{command}: {len(before)} lines read while the engine waited, the last: {before[-1]}")


def main():
    octocd, source, work = sys.argv[1], sys.argv[2], sys.argv[3]
    data = os.path.join(source, "tests/data/process_engines")
    engines = os.path.join(data, "engines.json")
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(os.path.join(work, "tmp"))
    listed = subprocess.run([octocd, "--engines-file", engines, "engines", "--available"], capture_output=True,
                            text=True).stdout.split()
    if "pyboxes" not in listed:
        print("SKIPPED: engine pyboxes is not available (its check: python3 with h5py and numpy)")
        sys.exit(77)
    log = os.path.join(work, "run.log")
    with open(log, "w") as out:  # stdout and stderr to one file
        rc = subprocess.run([octocd, "--engines-file", engines, "run", os.path.join(data, "boxes.json"), "--engine",
                             "pyboxes", "--frames", "40"], stdout=out, stderr=subprocess.STDOUT,
                            env={**os.environ, "TMPDIR": os.path.join(work, "tmp")}).returncode
    text = open(log).read()
    if rc != 0:
        fail(f"run exit {rc}:\n{text}")
    lines = text.splitlines()

    def index(pattern):
        for k, line in enumerate(lines):
            if re.search(pattern, line):
                return k
        fail(f"no line matching '{pattern}' in:\n{text}")

    starting = index(r"^engine pyboxes: starting .* for 40 frames")
    ran = index(r"^engine pyboxes: its process ran 40 frames in")
    m = re.search(r"ran 40 frames in ([0-9.]+) s \(([0-9.]+) s in its step calls, ([0-9.]+) s start-up", lines[ran])
    if not m:
        fail(f"the start-up line gives no figures: {lines[ran]}")
    startup = float(m.group(3))
    streamed = [k for k, line in enumerate(lines) if re.match(r"^frame \d+/40 .*\(its process as it runs", line)]
    progress = [k for k, line in enumerate(lines) if re.match(r"^frame \d+/40 .*\(read from its trace\)", line)]
    summary = index(r"^scene +")
    if not (streamed and starting < streamed[0] and streamed[-1] < ran):
        fail(f"the process's steps are not said as it runs them: starting line {starting}, lines as it runs "
             f"{streamed}, ran line {ran}:\n{text}")
    if not (starting < ran and progress and ran < progress[0] and progress[-1] < summary):
        fail(f"out of order: starting line {starting}, ran line {ran}, progress lines {progress}, summary line "
             f"{summary}:\n{text}")
    if any("pairs n/a" not in lines[k] or "(read from its trace)" not in lines[k] for k in progress):
        fail(f"progress lines of a process engine without /pairs: pairs n/a, read from its trace:\n{text}")
    setup = re.search(r"^set-up +([0-9.]+) s \(scene and bodies ([0-9.]+) s, engine ([0-9.]+) s, of which ([0-9.]+) s "
                      r"its process's start-up", text, re.M)
    if not setup:
        fail(f"the summary's set-up does not name the process's start-up:\n{text}")
    if abs(float(setup.group(4)) - startup) > 0.011 or float(setup.group(3)) + 0.011 < startup or startup <= 0:
        fail(f"set-up {setup.group(0)} against the start-up said before ({startup} s)")
    for row in ("broadphase candidates", "AABB pairs", "  dynamic pairs"):
        if not re.search(rf"^{re.escape(row)} +n/a +n/a +n/a$", text, re.M):
            fail(f"'{row}' is not n/a for an engine that reports no pairs:\n{text}")
    print(f"start-up {startup} s said before {len(progress)} progress lines, all before the summary; set-up "
          f"{setup.group(1)} s; pair rows n/a")
    check_streamed(octocd, engines, data, work, {**os.environ, "TMPDIR": os.path.join(work, "tmp")})
    print("PASS")


if __name__ == "__main__":
    main()
