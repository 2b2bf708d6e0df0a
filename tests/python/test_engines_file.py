"""octocd.load_engines_file (docs/bring-your-engine.md, docs/python.md): a process engine of
an engines file runs from Python as from the CLI's `--engines-file`. Each case runs in a
fresh interpreter (the engine registry is read once per process). Run by ctest
(`python.pytest`) with PYTHONPATH=build/python, OCTOCD_BIN and OCTOCD_SOURCE_DIR set."""
import json
import os
import subprocess
import sys

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
