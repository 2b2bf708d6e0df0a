"""The engine keyword arguments of `octocd.Engine` (docs/settings.md): the cuda engine's
settings as `cuda={KEY: VALUE}` (CudaSettings), checked whatever the engine, and the
options an engine cannot run refused with Python's spelling (the registry's
apply_engine_options, engines/include/octocd/engines.hpp). Run by ctest (`python.pytest`).
"""
import os

import pytest

octocd = pytest.importorskip("octocd", reason="the octocd Python module is not built")

SOURCE_DIR = os.environ.get("OCTOCD_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
BOX_STACK = os.path.join(SOURCE_DIR, "datasets", "scenes", "box-stack.json")


def test_cuda_settings_are_checked_whatever_the_engine():
    with pytest.raises(octocd.InputError, match=r"cuda: graph='maybe' is not a switch; allowed: true, false"):
        octocd.Engine(BOX_STACK, engine="cpu", cuda={"graph": "maybe"})
    with pytest.raises(octocd.InputError, match=r"cuda: unknown cuda setting 'small'; allowed: midphase_early_exit"):
        octocd.Engine(BOX_STACK, engine="cpu", cuda={"small": 1})
    with pytest.raises(octocd.InputError, match=r"resident_timeout_ms='0' is not allowed; allowed: an integer 1"):
        octocd.Engine(BOX_STACK, engine="cpu", cuda={"resident_timeout_ms": 0})
    # Valid settings leave another engine's run unchanged, bit for bit.
    plain = octocd.Engine(BOX_STACK, engine="cpu", record=False)
    tuned = octocd.Engine(BOX_STACK, engine="cpu", record=False,
                          cuda={"graph": False, "stage_times": False, "memory_limit_bytes": 4096})
    plain.step(20)
    tuned.step(20)
    assert (plain.positions == tuned.positions).all() and (plain.velocities == tuned.velocities).all()


def test_options_an_engine_cannot_run_are_refused_in_pythons_spelling():
    with pytest.raises(octocd.InputError, match=r"broadphase: engine bullet runs btDbvtBroadphase, not 'octree'; "
                                                r"allowed: bullet-dbvt, or None with engine='bullet'"):
        octocd.Engine(BOX_STACK, engine="bullet", broadphase="octree")
    with pytest.raises(octocd.InputError, match=r"broadphase: broadphase 'lbvh' exists on the device only; "
                                                r"allowed: engine='cuda' with it"):
        octocd.Engine(BOX_STACK, engine="cpu", broadphase="lbvh")


@pytest.mark.skipif("cuda" not in octocd.engines, reason="this octocd is built without CUDA")
def test_cuda_without_a_device_says_why():
    status = octocd.cuda_device_status()
    if not status.startswith("no CUDA device"):
        pytest.skip("a CUDA device is present: " + status)
    with pytest.raises(octocd.RuntimeError, match=r"engine 'cuda': no CUDA device: .*; allowed: engine='cpu' or "
                                                  r"'bullet'( or '[a-z]+')* on this machine"):
        octocd.Engine(BOX_STACK, engine="cuda", cuda={"graph": False})


def test_bullet_settings_choose_the_geometry():
    # bullet={"shape": ...} (BulletSettings): hull (the default) records every step, box
    # (boxes equal to the AABBs) records nothing; anything else is an InputError.
    with pytest.raises(octocd.InputError, match=r"bullet: shape='sphere' is not allowed; allowed: hull"):
        octocd.Engine(BOX_STACK, engine="bullet", bullet={"shape": "sphere"})
    with pytest.raises(octocd.InputError, match=r"bullet: unknown bullet setting 'margin'; allowed: shape"):
        octocd.Engine(BOX_STACK, engine="cpu", bullet={"margin": 0})
    assert octocd.Engine(BOX_STACK, engine="bullet").recording
    assert not octocd.Engine(BOX_STACK, engine="bullet", bullet={"shape": "box"}).recording
