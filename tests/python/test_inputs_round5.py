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
- Out of memory inside HDF5 itself (a 48 MiB compressed chunk inflated under a memory limit
  the same trace stored plainly reads within) is "out of memory while reading it", exit 1,
  in the CLI and in octocd.Trace, never "damaged".
Every input is generated here, small.
"""
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from test_hostile_input import external_trace as hostile_external_trace

octocd = pytest.importorskip(
    "octocd", reason="the octocd Python module is not built (configure with OCTOCD_PYTHON=ON and "
    "python3-pybind11, and put build/python on PYTHONPATH)")
h5py = pytest.importorskip("h5py", reason="python3-h5py is not installed")

SOURCE_DIR = os.environ.get("OCTOCD_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
SCENE = os.path.join(SOURCE_DIR, "datasets", "scenes", "box-stack.json")
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SOURCE_DIR, "build", "octocd"))


def external_trace(path, **kw):
    """test_hostile_input.py's small valid external trace (2 boxes at rest, 2 m apart), as a
    str path."""
    return str(hostile_external_trace(path, **kw))


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


def chunked_trace(path, chunk_mib):
    """external_trace's 2 boxes, 3 frames, with /states/position compressed in one chunk of
    `chunk_mib` MiB (0: stored plainly): reading any row inflates the whole chunk, a buffer
    HDF5 allocates itself. The values are the same either way."""
    def rechunk(f):
        x = f["states/position"][...]
        del f["states/position"]
        n = x.shape[1]
        rows = (chunk_mib << 20) // (n * 3 * 4)
        f["states"].create_dataset("position", data=x, maxshape=(None, n, 3), chunks=(rows, n, 3),
                                   compression="gzip")

    return external_trace(path, extra=rechunk if chunk_mib else None)


def smallest_limit(run_under, start_mib=48, step_mib=16, last_mib=4096):
    """The smallest address-space limit (MiB, in steps of step_mib) under which run_under(limit)
    succeeds: the event that the process's own needs fit, found by trying, no timing."""
    for mib in range(start_mib, last_mib + 1, step_mib):
        if run_under(mib):
            return mib
    pytest.skip(f"nothing ran under {last_mib} MiB of address space")


def test_out_of_memory_inside_hdf5_is_never_a_damaged_file(tmp_path):
    # The hostile case: a trace whose /states/position is one 48 MiB compressed chunk (a few
    # KB on disk), read under the smallest memory limit within which the same trace stored
    # plainly is read. The only allocation that grows is HDF5's own buffer for the inflated
    # chunk, so the failure comes from inside the library (H5E_RESOURCE / H5E_CANTALLOC on
    # its error stack): the message must say out of memory, exit 1, never "damaged" or bad
    # input (exit 2). Without the limit the same file reads (it is not damaged).
    plain = chunked_trace(tmp_path / "plain.h5", 0)
    big = chunked_trace(tmp_path / "big.h5", 48)
    want = re.escape(big) + r": /states/position: out of memory while reading it \(.*the file is not known to be damaged\)"
    if os.access(BIN, os.X_OK):
        def cli(path, mib):
            return subprocess.run(["prlimit", f"--as={mib << 20}", BIN, "validate", "--trace-in", path, "--check-only"],
                                  capture_output=True, text=True, timeout=120)
        assert cli(big, 1 << 20).returncode == 0, "the chunked trace must read without a limit"
        mib = smallest_limit(lambda m: cli(plain, m).returncode == 0)
        r = cli(big, mib)
        assert r.returncode == 1 and re.search(want, r.stderr), (mib, r.returncode, r.stderr[-2000:])
        assert "damaged:" not in r.stderr and "truncated" not in r.stderr, r.stderr[-2000:]
    # octocd.Trace, in a child under the same kind of limit.
    code = """
import resource, sys
mib = int(sys.argv[1])
resource.setrlimit(resource.RLIMIT_AS, (mib << 20, mib << 20))
import octocd
try:
    octocd.Trace(sys.argv[2]).state(1)
    print("read")
except Exception as e:
    print(type(e).__name__ + ": " + str(e))
"""

    def py(path, mib):
        r = subprocess.run([sys.executable, "-c", code, str(mib), path], capture_output=True, text=True,
                           timeout=120, env=dict(os.environ))
        return (r.stdout + r.stderr).strip().splitlines()[-1:] or [""]

    assert py(big, 1 << 20) == ["read"]
    mib = smallest_limit(lambda m: py(plain, m) == ["read"], start_mib=128)
    line = py(big, mib)[0]
    assert re.fullmatch("RuntimeError: " + want, line), (mib, line)
