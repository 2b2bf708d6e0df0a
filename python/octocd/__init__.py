"""octocd from Python: run octocd's engines, read what each step did as NumPy arrays, and
judge another engine's frames with octocd's validators (design.md section 7, design.md section 13).

    import octocd
    scene = octocd.load_scene("datasets/scenes/box-stack.json")
    eng = octocd.Engine(scene, engine="cpu")
    eng.step(100)                      # the GIL is released while stepping
    x = eng.positions                  # (n, 3) float32 copy, metres
    rec = eng.last_frame()             # octocd.FrameRecord: pairs, contacts, stage times
    results = octocd.validate_frame(local_boxes=..., x_pre=..., ...)   # another engine

Units: metres, seconds, kilograms; states are float32 (design.md section 2).

Arrays given to octocd: float arguments take float32 as is and round other float dtypes
(float64, float16) to float32, as `octocd validate --trace-in` does with float64 datasets;
integer arguments (pairs, triangles) take any integer dtype, range-checked. Any other
dtype (integers for positions, floats for pairs, bool, complex, object) is refused with
`InputError`. Non-contiguous arrays and plain sequences are converted (copied). Shapes
are checked exactly, every float must be finite: `InputError` names the argument, its
shape or row and the allowed shape.

Arrays returned by octocd are fresh copies the caller owns (never views of engine state).

Errors: `octocd.InputError` (a `ValueError`): bad scene, bad array, unknown engine or
broadphase, an engine not built (`cuda` without CUDA). `octocd.RuntimeError` (a
`RuntimeError`): no CUDA device, a NaN in the state while stepping, an unreadable trace.

Reading traces: `octocd.Trace` reads octocd's traces and external ones (format version 1
or 2: orientations, angular velocities, inertia, materials, manifold contacts with
points) through the CLI's hardened reader: a trace is untrusted input, and plain h5py
follows external links, external storage and virtual datasets into other files.
"""
from __future__ import annotations

import os
from typing import Dict, List

try:
    from . import _octocd
except ImportError as _e:  # pragma: no cover - depends on the build
    raise ImportError(
        "octocd: the compiled module octocd._octocd is missing or was built for another Python "
        f"({_e}); build it with CMake (OCTOCD_PYTHON=ON, Debian's python3-pybind11) and put "
        "build/python on PYTHONPATH, or `cmake --install` it (docs/python.md)") from _e

InputError = _octocd.InputError
RuntimeError = _octocd.RuntimeError  # noqa: A001 - octocd.RuntimeError subclasses the builtin
Scene = _octocd.Scene

#: Build id of the compiled module ("MAJOR.MINOR.PATCH+GITID").
build_id: str = _octocd.build_id


def __getattr__(name: str):
    # `octocd.engines`: the engines this octocd can build, read from the registry when asked
    # (not at import), so that load_engines_file may name the engines file first.
    if name == "engines":
        return list(_octocd.engines())
    raise AttributeError(f"module 'octocd' has no attribute '{name}'")


def load_engines_file(path: str) -> List[str]:
    """Names this process's engines file (docs/bring-your-engine.md, "The engines file"), as
    the CLI's `--engines-file FILE` does: its process engines join the built-in ones and
    those of the shipped and the user's engines files (a later same name replaces an
    earlier), and `Engine(scene, engine=NAME)` runs them. The file is read at once: a
    malformed one raises `InputError` naming the file and the field. Returns `engines`.

    Call it before the first engine is looked up (before `Engine`, `engines` or
    `validate_trace` with an engine); the registry is read once per process, so a later
    call with another file raises `RuntimeError` (the same file again is a no-op).
    A path that is not a str, bytes or os.PathLike, or not UTF-8, raises `InputError`."""
    allowed = "allowed: the path of an engines file (a str or os.PathLike, UTF-8), docs/bring-your-engine.md"
    if not isinstance(path, (str, bytes, os.PathLike)):
        raise InputError(f"path: {type(path).__name__} ({path!r}); {allowed}")
    text = os.fspath(path)
    try:
        text = text.decode("utf-8") if isinstance(text, bytes) else text
        text.encode("utf-8")
    except UnicodeError:
        raise InputError(f"path: {path!r} is not UTF-8; {allowed}") from None
    return list(_octocd.load_engines_file(text))


__all__ = [
    "InputError", "RuntimeError", "Scene", "load_scene", "Engine", "FrameRecord", "ValidationResult",
    "ValidationCause", "ValidationExample", "ValidationResults", "ExpectationOutcome", "Validator", "validate_frame", "validate_trace", "merge_validations", "format_results", "failures", "Trace", "engines",
    "broadphases", "tolerances", "cuda_device_status", "build_id", "view", "load_engines_file",
]


def cuda_device_status() -> str:
    """One line about the CUDA device ("NVIDIA H100 ... (sm_90, 79.1 GiB)"), or
    "no CUDA device: REASON" (including "this octocd was built without CUDA")."""
    return _octocd.cuda_device_status()


def broadphases() -> List[str]:
    """Every broadphase name some engine accepts: octocd's, the Bullet/FCL references, then
    the device-only ones (lbvh: engine "cuda" only), as `octocd run --broadphase` lists them."""
    return list(_octocd.broadphases())


def tolerances() -> Dict[str, float]:
    """Every validator tolerance (validation.hpp, `Tolerances`) with its default value;
    the names `tolerances={...}` of Validator / validate_frame / validate_trace accept."""
    return dict(_octocd.tolerances())


# The public names, one module per job: scenes (scene.py), engines (engine.py), judging
# another engine's frames (validate.py), traces (trace.py), the debugging page (view.py).
from .scene import load_scene  # noqa: E402
from .engine import Engine, FrameRecord  # noqa: E402
from .validate import (  # noqa: E402
    ExpectationOutcome, ValidationCause, ValidationExample, ValidationResult, ValidationResults, Validator, failures,
    format_results, merge_validations, validate_frame, validate_trace)
from .trace import Trace  # noqa: E402
from .view import view  # noqa: E402
