"""Untrusted inputs to the Python package, round five (issue 68), run by ctest (`python.pytest`).

- Special files: validate_trace(expect=FIFO), merge_validations([..., FIFO]) are refused at
  once as the CLI refuses them (before: they blocked until Ctrl-C); /dev/zero is refused
  without being read (before: MemoryError).
- Integer arguments: 2**63 frames or steps, 2**64 pair indices are InputError naming the
  argument and its range (before: pybind11's "incompatible function arguments"); a NaN frame
  and floats where integers belong (pair=(0.5, 1.5), step(2.7)) are refused (before: a bare
  ValueError, or silently truncated); a non-UTF-8 path is InputError naming the argument.
- Dtypes as docs/python.md says: float16 and big-endian arrays are refused.
- merge_validations('s0.json') (a string, not a list) is refused with a clear message.
Every input is generated here, small.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

octocd = pytest.importorskip(
    "octocd", reason="the octocd Python module is not built (configure with OCTOCD_PYTHON=ON and "
    "python3-pybind11, and put build/python on PYTHONPATH)")
h5py = pytest.importorskip("h5py", reason="python3-h5py is not installed")

SOURCE_DIR = os.environ.get("OCTOCD_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
SCENE = os.path.join(SOURCE_DIR, "datasets", "scenes", "box-stack.json")


def external_trace(path, n=2, frames=3):
    """A small valid external trace (version 1, states only): n boxes at rest, 2 m apart
    (as tests/python/test_hostile_input.py writes it)."""
    x = np.zeros((frames + 1, n, 3), np.float32)
    x[:, :, 0] = np.arange(n) * 2.0
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "octocd-trace"
        f.attrs["version"] = 1
        f.attrs["dt"] = 0.001
        f.attrs["gravity"] = np.zeros(3)
        f["bodies/local_aabb_min"] = np.full((n, 3), -0.5, np.float32)
        f["bodies/local_aabb_max"] = np.full((n, 3), 0.5, np.float32)
        f["bodies/inverse_mass"] = np.ones(n, np.float32)
        f["states/position"] = x
        f["states/velocity"] = np.zeros_like(x)
    return str(path)


def in_child(code, timeout=60):
    """Runs `code` in a fresh interpreter (a call that would block is then ended by the
    timeout, failing the test instead of hanging the suite); returns (rc, stdout + stderr)."""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout,
                       env=dict(os.environ))
    return r.returncode, r.stdout + r.stderr


@pytest.mark.parametrize("call", ["validate_trace({t!r}, expect={p!r})", "merge_validations([{p!r}])"])
@pytest.mark.parametrize("kind", ["fifo", "zero", "folder"])
def test_special_files_are_refused_at_once(tmp_path, call, kind):
    t = external_trace(tmp_path / "t.h5")
    if kind == "fifo":
        p = str(tmp_path / "fifo")
        os.mkfifo(p)
        want = "a FIFO"
    elif kind == "zero":
        p, want = "/dev/zero", "a character device"
    else:
        p, want = str(tmp_path), "a folder"
    code = ("import octocd\ntry:\n    octocd." + call.format(t=t, p=p) +
            "\nexcept octocd.InputError as e:\n    print('InputError:', e)\n")
    rc, out = in_child(code)
    assert rc == 0, out
    assert "InputError:" in out and p in out, out
    assert "MemoryError" not in out and "Traceback" not in out, out
    assert want.split()[-1] in out, out


@pytest.mark.parametrize("call, argument", [
    (lambda t, e: octocd.validate_trace(t, max_frames=2**63), "max_frames"),
    (lambda t, e: octocd.validate_trace(t, every=2**64), "every"),
    (lambda t, e: octocd.validate_trace(t, every=2.0), "every"),
    (lambda t, e: octocd.validate_trace(t, shard=(0.5, 2)), "shard[0]"),
    (lambda t, e: e.step(2**63), "n"),
    (lambda t, e: e.step(2.7), "n"),
    (lambda t, e: e.step(float("nan")), "n"),
    (lambda t, e: octocd.view(t, frame=float("nan")), "frame"),
    (lambda t, e: octocd.view(t, frame=2**63), "frame"),
    (lambda t, e: octocd.view(t, pair=(0.5, 1.5)), "pair[0]"),
    (lambda t, e: octocd.view(t, pair=(0, 2**64)), "pair[1]"),
    (lambda t, e: octocd.view(t, body=-1), "body"),
    (lambda t, e: octocd.Trace(t).state(float("nan")), "frame"),
    (lambda t, e: octocd.Trace(t).state(1.5), "frame"),
])
def test_integer_arguments_are_checked_naming_argument_and_range(tmp_path, call, argument):
    t = external_trace(tmp_path / "t.h5")
    e = octocd.Engine(SCENE, record=False)
    with pytest.raises(octocd.InputError) as info:
        call(t, e)
    msg = str(info.value)
    assert msg.startswith(argument + ": "), msg
    assert "allowed: an integer in [" in msg, msg
    assert e.frame == 0  # nothing stepped


def test_a_non_utf8_path_is_input_error_naming_the_argument(tmp_path):
    bad = os.fsencode(str(tmp_path)) + b"/t\xff.h5"
    for call, argument in [(lambda: octocd.validate_trace(bad), "path"), (lambda: octocd.Trace(bad), "path"),
                           (lambda: octocd.view(bad), "trace")]:
        with pytest.raises(octocd.InputError) as info:
            call()
        assert str(info.value).startswith(argument + ": ") and "is not UTF-8" in str(info.value), str(info.value)


@pytest.mark.parametrize("dtype", [np.float16, np.dtype(">f4"), np.dtype(">f8"), np.longdouble])
def test_undocumented_float_dtypes_are_refused(dtype):
    n = 2
    boxes = np.zeros((n, 2, 3), np.float32)
    boxes[:, 0] = -0.5
    boxes[:, 1] = 0.5
    with pytest.raises(octocd.InputError) as info:
        octocd.Validator(local_boxes=np.asarray(boxes, dtype=dtype), inverse_mass=np.ones(n, np.float32), dt=0.01)
    assert str(info.value).startswith("local_boxes: dtype"), str(info.value)
    # The documented dtypes pass: float32 as is, float64 rounded.
    for ok in (np.float32, np.float64):
        octocd.Validator(local_boxes=boxes.astype(ok), inverse_mass=np.ones(n, np.float32), dt=0.01)


def test_big_endian_integers_are_refused():
    n = 3
    boxes = np.zeros((n, 2, 3), np.float32)
    boxes[:, 0], boxes[:, 1] = -0.5, 0.5
    v = octocd.Validator(local_boxes=boxes, inverse_mass=np.ones(n, np.float32), dt=0.01)
    aabbs = np.zeros((n, 2, 3), np.float32)
    aabbs[:, 0, 0] = np.arange(n) * 3 - 0.5
    aabbs[:, 1, 0] = np.arange(n) * 3 + 0.5
    with pytest.raises(octocd.InputError) as info:
        v.observe(1, aabbs=aabbs, pairs=np.array([[0, 1]], dtype=">i8"))
    assert "pairs: dtype" in str(info.value) and "big-endian" in str(info.value), str(info.value)


@pytest.mark.parametrize("shards", ["s0.json", b"s0.json", {"shard": 1}])
def test_merge_validations_of_a_non_list_is_refused_clearly(shards):
    with pytest.raises(octocd.InputError) as info:
        octocd.merge_validations(shards)
    msg = str(info.value)
    assert msg.startswith("merge_validations: shards: a "), msg
    assert "allowed: a list of the shards" in msg and "cannot read '/'" not in msg, msg
