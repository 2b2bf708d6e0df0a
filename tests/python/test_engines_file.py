"""octocd.load_engines_file (docs/bring-your-engine.md, docs/python.md): a process engine of
an engines file runs from Python as from the CLI's `--engines-file`. Each case runs in a
fresh interpreter (the engine registry is read once per process). Run by ctest
(`python.pytest`) with PYTHONPATH=build/python, OCTOCD_BIN and OCTOCD_SOURCE_DIR set."""
import json
import os
import select
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

octocd = pytest.importorskip(
    "octocd", reason="the octocd Python module is not built (configure with OCTOCD_PYTHON=ON and "
                     "install python3-pybind11)")
pytest.importorskip("h5py", reason="python3-h5py is not installed")

SOURCE_DIR = os.environ.get("OCTOCD_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SOURCE_DIR, "build", "octocd"))
DATA = os.path.join(SOURCE_DIR, "tests", "data", "process_engines")
ENGINES = os.path.join(DATA, "engines.json")
SCENE = os.path.join(DATA, "boxes.json")
FRAMES = 40


def python(code):
    """Runs `code` in a fresh interpreter with this one's environment; its stdout's last line
    as JSON, or the failure's stderr."""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_a_process_engine_loaded_from_python_steps_as_the_cli_runs_it(tmp_path):
    if not os.access(BIN, os.X_OK):
        pytest.skip(f"the octocd CLI is not built at {BIN} (set OCTOCD_BIN)")
    out = python(f"""
import json, octocd
listed = octocd.load_engines_file({ENGINES!r})
eng = octocd.Engine(octocd.load_scene({SCENE!r}), engine="pyboxes")
eng.step({FRAMES})
print(json.dumps({{"listed": listed, "engines": octocd.engines,
                  "x": eng.positions.tolist()}}))
""")
    assert "pyboxes" in out["listed"] and "pyboxes" in out["engines"]
    assert out["listed"][0] == "cpu" and out["listed"] == out["engines"]
    # The same engine through the CLI's --engines-file: the same state at the same frame.
    trace = str(tmp_path / "cli.h5")
    subprocess.run([BIN, "--engines-file", ENGINES, "run", SCENE, "--engine", "pyboxes", "--frames", str(FRAMES),
                    "--trace", trace, "--quiet"], check=True, capture_output=True)
    with octocd.Trace(trace) as t:
        x_cli, _ = t.state(FRAMES)
    x_py = np.asarray(out["x"], dtype=np.float32)
    assert x_py.shape == x_cli.shape
    np.testing.assert_array_equal(x_py, x_cli)
    # The boxes move (a free-falling one): the comparison is not of two initial states.
    with octocd.Trace(trace) as t:
        x0, _ = t.state(0)
    assert np.any(x_cli != x0)


def test_without_the_file_the_engine_is_unknown():
    out = python(f"""
import json, octocd
try:
    octocd.Engine(octocd.load_scene({SCENE!r}), engine="pyboxes")
    print(json.dumps("ran"))
except octocd.InputError as e:
    print(json.dumps(str(e)))
""")
    assert "unknown engine 'pyboxes'" in out, out


def test_a_malformed_file_is_an_input_error_naming_file_and_field(tmp_path):
    bad = tmp_path / "engines.json"
    bad.write_text(json.dumps({"format": "octocd-engines", "version": 1,
                               "engines": [{"name": "x", "command": "python3 x.py"}]}))
    out = python(f"""
import json, octocd
try:
    octocd.load_engines_file({str(bad)!r})
    print(json.dumps("loaded"))
except octocd.InputError as e:
    print(json.dumps(str(e)))
""")
    assert str(bad) in out and "engines[0].command" in out and "allowed:" in out, out


def test_a_second_file_after_the_registry_was_read_is_refused(tmp_path):
    out = python(f"""
import json, octocd
first = octocd.engines
try:
    octocd.load_engines_file({ENGINES!r})
    print(json.dumps("loaded"))
except octocd.RuntimeError as e:
    print(json.dumps(str(e)))
""")
    assert "read already" in out and "before the first engine is looked up" in out, out
    # The same file twice is one file: no error.
    again = python(f"""
import json, octocd
octocd.load_engines_file({ENGINES!r})
print(json.dumps(octocd.load_engines_file({ENGINES!r})))
""")
    assert "pyboxes" in again


def test_ctrl_c_inside_step_stops_the_process_engine_and_its_tree(tmp_path):
    # `pystop` hangs until stopped (timeout_s 600) after starting a grandchild that calls
    # setsid(); SIGINT while Engine.step() waits for it: KeyboardInterrupt within 1 s, the
    # interpreter exits at once (not after timeout_s), the engine and the grandchild are gone.
    ready, escaped = str(tmp_path / "engine.pid"), str(tmp_path / "grandchild.pid")
    os.mkfifo(ready + ".tmp")  # the engine writes its pid through it once it runs: an event to wait on
    code = f"""
import sys, time, octocd
octocd.load_engines_file({ENGINES!r})
eng = octocd.Engine(octocd.load_scene({SCENE!r}), engine="pystop", pystop={{"ready": {ready!r}, "escape": {escaped!r}}})
try:
    eng.step(5)
    print("finished", flush=True)
except KeyboardInterrupt:
    print("KeyboardInterrupt", flush=True)
"""
    env = dict(os.environ, TMPDIR=str(tmp_path))
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env)
    try:
        fd = os.open(ready + ".tmp", os.O_RDONLY | os.O_NONBLOCK)
        try:
            assert select.select([fd], [], [], 120)[0], p.stderr.read() if p.poll() is not None else "no engine"
            engine = int(os.read(fd, 64).decode())
        finally:
            os.close(fd)
        with open(escaped) as f:
            grandchild = int(f.read())
        t0 = time.monotonic()
        p.send_signal(signal.SIGINT)
        line = p.stdout.readline().strip()
        raised = time.monotonic() - t0
        code = p.wait(timeout=10)
        exited = time.monotonic() - t0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    print(f"KeyboardInterrupt {raised:.3f} s, exit {exited:.3f} s after SIGINT")
    assert line == "KeyboardInterrupt", (line, p.stderr.read())
    assert raised < 1.0 and exited < 5.0 and code == 0, (raised, exited, code)
    for pid in (engine, grandchild):
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    assert not [n for n in os.listdir(tmp_path) if n.startswith("octocd-")]


@pytest.mark.parametrize("path", [b"/tmp/engines\xff.json", "/tmp/engines\udcff.json", 3, None, ""])
def test_every_bad_path_of_load_engines_file_is_an_input_error(path):
    out = python(f"""
import json, octocd
try:
    octocd.load_engines_file({path!r})
    print(json.dumps("loaded"))
except octocd.InputError as e:
    print(json.dumps("InputError: " + str(e)))
except Exception as e:
    print(json.dumps(type(e).__name__ + ": " + str(e)))
""")
    assert out.startswith("InputError: path: ") and "allowed:" in out, out


@pytest.mark.parametrize("engine", ["3", "None", "b'pyboxes'", "'py\\x00boxes'"])
def test_a_bad_engine_name_of_a_process_engine_is_an_input_error(engine):
    # `engine` is Python source: an int, None, bytes, a name holding a NUL (shown escaped).
    out = python(f"""
import json, octocd
octocd.load_engines_file({ENGINES!r})
try:
    octocd.Engine(octocd.load_scene({SCENE!r}), engine={engine})
    print(json.dumps("made"))
except octocd.InputError as e:
    print(json.dumps("InputError: " + str(e)))
except Exception as e:
    print(json.dumps(type(e).__name__ + ": " + str(e)))
""")
    assert out.startswith("InputError: engine: ") and "allowed:" in out and "\0" not in out, out
