"""octocd.view (design.md section 16; docs/debugging.md): the page `octocd view` writes, by the same C++
code. Oracles: the CLI's page for the same arguments (byte for byte), a normal planted
flipped in Bullet's trace (the page shows it beside the reference, which still points the
other way), and bad input raising InputError naming the keyword argument.
"""
import json
import os
import re
import subprocess

import numpy as np
import pytest

octocd = pytest.importorskip(
    "octocd", reason="the octocd Python module is not built (configure with OCTOCD_PYTHON=ON and "
    "python3-pybind11, and put build/python on PYTHONPATH)")
h5py = pytest.importorskip("h5py", reason="python3-h5py is not installed")

SOURCE_DIR = os.environ.get("OCTOCD_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SOURCE_DIR, "build", "octocd"))
THREE = "/usr/share/javascript/three/three.min.js"


@pytest.fixture
def stack_trace(tmp_path):
    """Bullet with rotation on rot-stack-10, 30 frames, every state and contact (version 2)."""
    if not os.access(BIN, os.X_OK):
        pytest.skip(f"the octocd CLI is not built at {BIN} (set OCTOCD_BIN)")
    if not os.path.exists(THREE):
        pytest.skip(f"{THREE} is absent (apt-get install libjs-three)")
    out = str(tmp_path / "stack.h5")
    subprocess.run([BIN, "run", os.path.join(SOURCE_DIR, "datasets", "scenes", "rot-stack-10.json"), "--engine",
                    "bullet", "--rotation", "--frames", "30", "--state-every", "1", "--contacts", "--trace", out,
                    "--quiet", "--no-xdmf"], check=True)
    return out


def rows_of(path, a, b):
    """(frame, row) of every contact row of pair (a, b): rows of frame f are offsets[f-1]:offsets[f]."""
    with h5py.File(path, "r") as f:
        off = f["contacts/offsets"][:]
        pair = f["contacts/pair"][:]
    return [(k, r) for k in range(1, len(off)) for r in range(off[k - 1], off[k]) if tuple(pair[r]) == (a, b)]


def page_data(path):
    text = open(path, encoding="utf-8").read()
    m = re.search(r'<script type="application/json" id="octocd-data">(.*?)</script>', text, re.S)
    assert m, "no embedded data"
    return json.loads(m.group(1))


def test_view_writes_the_cli_page(stack_trace, tmp_path):
    frame = rows_of(stack_trace, 1, 2)[0][0]
    py = octocd.view(stack_trace, frame=frame, pair=(1, 2), out_dir=tmp_path / "py")
    cli = tmp_path / "cli"
    subprocess.run([BIN, "view", stack_trace, "--frame", str(frame), "--pair", "1,2", "-o", str(cli)], check=True,
                   stdout=subprocess.DEVNULL)
    name = f"view-f{frame}-pair-1-2.html"
    assert py["path"] == str(tmp_path / "py" / name)
    assert py["frame"] == frame and py["bodies"] >= 2 and py["frames"] >= 1 and py["note"] == ""
    assert open(py["path"], "rb").read() == open(cli / name, "rb").read()
    assert py["bytes"] == os.path.getsize(py["path"])


def test_view_shows_a_planted_flipped_normal_beside_the_reference(stack_trace, tmp_path):
    frame, row = rows_of(stack_trace, 1, 2)[-1]
    with h5py.File(stack_trace, "r+") as f:
        n = f["contacts/normal"]
        flipped = -n[row]
        n[row] = flipped
    page = octocd.view(stack_trace, frame=frame, pair=(2, 1), window=0, out_dir=tmp_path)
    data = page_data(page["path"])
    assert data["item"] == {"kind": "pair", "a": 1, "b": 2}
    [fr] = data["frames"]
    rows = [c for c in fr["contacts"] if (c["a"], c["b"]) == (1, 2)]
    match = [c for c in rows if np.allclose(c["normal"], flipped, atol=1e-6)]
    assert match, f"the flipped normal {flipped} is not among the pair's rows {rows}"
    c = match[0]
    ref = fr["references"][c["ref"]]
    assert (ref["a"], ref["b"]) == (1, 2) and ref["judge"] in ("SAT", "FCL")
    # The reference still points from body 2 to body 1: about opposite to the flipped row.
    assert float(np.dot(c["normal"], c["ref_normal"])) < -0.9
    assert c["angle_deg"] > 150


def test_view_bad_input_names_the_argument(stack_trace, tmp_path):
    for kwargs, named in [({"frame": 999}, "frame: 999"), ({"frame": 1, "pair": (1, 99)}, "pair: body 99"),
                          ({"frame": 1, "body": 11}, "body: body 11"), ({"frame": 1, "window": 99}, "window: 99"),
                          ({"frame": 1, "pair": (1, 2), "body": 3}, "pair and body")]:
        with pytest.raises(octocd.InputError, match=re.escape(named)):
            octocd.view(stack_trace, out_dir=tmp_path, **kwargs)
    with pytest.raises(octocd.InputError, match="not an HDF5 file"):
        bad = tmp_path / "bad.h5"
        bad.write_text("not a trace")
        octocd.view(bad, out_dir=tmp_path)
