"""Judge every frame of your engine's run with octocd's validators, from pytest.

Copy this file into your engine's test suite and replace the two functions under "Your
engine" with calls into your engine. octocd must be importable: PYTHONPATH=build/python
(octocd's build tree) or `cmake --install` (docs/python.md).

    PYTHONPATH=build/python /usr/bin/python3 -m pytest -q examples/python/test_my_engine.py

As shipped, "your engine" is examples/python/toy_engine.py (seven boxes in pure NumPy),
run without its planted fault, so this file passes; set PLANT = True to see the failure
octocd reports (candidate-sets: engine 'my-engine' misses pair (2, 3) at frame 7).
"""
import os
import sys

import numpy as np
import pytest

octocd = pytest.importorskip("octocd", reason="octocd's Python module is not on PYTHONPATH (docs/python.md)")

# ---- Your engine -------------------------------------------------------------------------
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import toy_engine  # noqa: E402  (replace with your engine)

PLANT = False


def my_bodies():
    """The bodies, constant over the run (octocd.Validator's arguments): local boxes
    (n, 2, 3) [min, max] in metres, inverse masses (n,) 1/kg (0 = static), the time step
    and gravity. Alternatively pass scene=<your octocd scene file or dict>."""
    half, w, _, _ = toy_engine.bodies()
    return dict(local_boxes=np.stack([-half, half], axis=1), inverse_mass=w, dt=float(toy_engine.DT),
                gravity=toy_engine.GRAVITY)


def my_frames():
    """Yields one dict per step of your run (octocd.Validator.observe's arguments):
    frame (1-based), aabbs (n, 2, 3) your detection's world AABBs, pairs (P, 2) your
    candidate pairs (a < b, sorted; None if your engine has none), contacts (dict of
    pair (C, 2), normal (C, 3) from B to A, depth, jn, jt (C,)), and the states before and
    after the step x_pre, v_pre, x_post, v_post (n, 3). A rotating engine adds q_pre,
    q_post (n, 4) (w, x, y, z) and w_pre, w_post (n, 3) (rad/s)."""
    half, w, x, v = toy_engine.bodies()
    for frame in range(1, toy_engine.FRAMES + 1):
        lo, hi, pairs, contacts, x_new, v_new = toy_engine.step(frame, half, w, x, v, plant=PLANT)
        yield dict(
            frame=frame,
            aabbs=np.stack([lo, hi], axis=1),
            pairs=np.array(pairs, dtype=np.int32).reshape(-1, 2),
            contacts=dict(
                pair=np.array([c[0] for c in contacts], dtype=np.int32).reshape(-1, 2),
                normal=np.array([c[1] for c in contacts], dtype=np.float32).reshape(-1, 3),
                depth=np.array([c[2] for c in contacts], dtype=np.float32),
                jn=np.array([c[3] for c in contacts], dtype=np.float32),
                jt=np.array([c[4] for c in contacts], dtype=np.float32)),
            x_pre=x, v_pre=v, x_post=x_new, v_post=v_new)
        x, v = x_new, v_new


# ---- The test: unchanged in your suite ---------------------------------------------------

def test_every_frame_passes_octocd_validators():
    validator = octocd.Validator(engine="my-engine", **my_bodies())
    frames = 0
    for rec in my_frames():
        validator.observe(**rec)  # InputError here: your arrays break a convention (named)
        frames += 1
    results = validator.results()
    table = octocd.format_results(results)
    print(f"{frames} frames judged\n{table}")
    assert not octocd.failures(results), "octocd's validators failed:\n" + table
