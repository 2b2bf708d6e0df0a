"""octocd from Python: run octocd's engines, read what each step did as NumPy arrays, and
judge another engine's frames with octocd's validators (SPEC 7, SPEC 13).

    import octocd
    scene = octocd.load_scene("datasets/scenes/box-stack.json")
    eng = octocd.Engine(scene, engine="cpu")
    eng.step(100)                      # the GIL is released while stepping
    x = eng.positions                  # (n, 3) float32 copy, metres
    rec = eng.last_frame()             # octocd.FrameRecord: pairs, contacts, stage times
    results = octocd.validate_frame(local_boxes=..., x_pre=..., ...)   # another engine

Units: metres, seconds, kilograms; states are float32 (SPEC 2).

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

Reading traces: use h5py (docs/trace-format.md, "Reading with h5py"); `octocd.Trace` is a
thin helper over it for the per-frame slices (states by frame, contacts by frame), for
octocd's traces and external ones, format version 1 or 2 (orientations, angular
velocities, inertia, materials, manifold contacts with points).
"""
from __future__ import annotations

import json as _json
import os as _os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Union

try:
    from . import _octocd
except ImportError as _e:  # pragma: no cover - depends on the build
    raise ImportError(
        "octocd: the compiled module octocd._octocd is missing or was built for another Python "
        f"({_e}); build it with CMake (OCTOCD_PYTHON=ON, Debian's python3-pybind11) and put "
        "build/python on PYTHONPATH, or `cmake --install` it (docs/python.md)") from _e

import numpy as _np

InputError = _octocd.InputError
RuntimeError = _octocd.RuntimeError  # noqa: A001 - octocd.RuntimeError subclasses the builtin
Scene = _octocd.Scene

#: Build id of the compiled module ("MAJOR.MINOR.PATCH+GITID").
build_id: str = _octocd.build_id
#: Engines built into this module: "cpu", "bullet" and, with CUDA, "cuda".
engines: List[str] = list(_octocd.engines)

__all__ = [
    "InputError", "RuntimeError", "Scene", "load_scene", "Engine", "FrameRecord", "ValidationResult",
    "ValidationCause", "ValidationExample", "ValidationResults", "ExpectationOutcome", "Validator", "validate_frame", "validate_trace", "format_results", "failures", "Trace", "engines",
    "broadphases", "tolerances", "cuda_device_status", "build_id",
]


def cuda_device_status() -> str:
    """One line about the CUDA device ("NVIDIA H100 ... (sm_90, 79.1 GiB)"), or
    "no CUDA device: REASON" (including "this octocd was built without CUDA")."""
    return _octocd.cuda_device_status()


def broadphases() -> List[str]:
    """Every broadphase name an engine accepts (octocd's and the Bullet/FCL references)."""
    return list(_octocd.broadphases())


def tolerances() -> Dict[str, float]:
    """Every validator tolerance (validation.hpp, `Tolerances`) with its default value;
    the names `tolerances={...}` of Validator / validate_frame / validate_trace accept."""
    return dict(_octocd.tolerances())


# ---- scenes ---------------------------------------------------------------------------

def load_scene(path_or_dict: Union[str, "_os.PathLike[str]", Dict[str, Any], Scene],
               data_dir: Optional[str] = None) -> Scene:
    """Loads and validates a scene (docs/scenes.md).

    path_or_dict: a scene file path (str or os.PathLike), a dict with the scene's JSON
    content (relative mesh paths then resolve against the current directory), or a Scene
    (returned as is). data_dir: where dataset meshes are looked up (default
    $OCTOCD_DATA_DIR, else datasets/cache next to the scene or of the source tree).

    Returns an octocd.Scene (read-only: name, description, path, json, dt, frames,
    gravity, domain (2, 3), body_count, broadphase, midphase).
    Raises InputError naming the file (or "<dict>"), the JSON key and the allowed range.
    """
    if isinstance(path_or_dict, Scene):
        return path_or_dict
    dd = "" if data_dir is None else _os.fspath(data_dir)
    if isinstance(path_or_dict, dict):
        try:
            text = _json.dumps(path_or_dict)
        except (TypeError, ValueError) as e:
            raise InputError(f"scene: the dict is not JSON ({e}); allowed: a dict of JSON values "
                             "(docs/scenes.md)") from None
        return _octocd.parse_scene(text, "<dict>", dd)
    if isinstance(path_or_dict, (str, bytes, _os.PathLike)):
        return _octocd.load_scene(_os.fsdecode(path_or_dict), dd)
    raise InputError(f"path_or_dict: {type(path_or_dict).__name__}; allowed: a scene file path, a dict, "
                     "or an octocd.Scene")


# ---- engines --------------------------------------------------------------------------

@dataclass
class FrameRecord:
    """What an engine did in one step (octocd/engine.hpp, FrameRecord), as NumPy copies.

    n bodies, P candidate pairs, K confirmed pairs, C contacts. Fields that the engine
    does not record are None (record=False, or engine "bullet": then only metrics,
    x_post, v_post and the engine's contacts).

    frame: the 1-based step this describes (0 before the first step).
    metrics: dict of the step's FrameMetrics: frame, time (s), step_ms, stage_ms (dict
        stage -> ms, None for a stage the engine does not time), cell_candidates,
        aabb_pairs, dynamic_pairs, box_tests, box_pairs, vertex_tests, contacts,
        penetration_mean / penetration_max (m), penetration_share_above_slop,
        kinetic_energy (J), momentum (kg m/s, 3-tuple), memory_bytes.
    x_pre, v_pre, x_post, v_post: (n, 3) float32 states before / after the step (m, m/s).
    aabbs: (n, 2, 3) float32 world AABBs the broadphase saw; [:, 0] min, [:, 1] max (m).
    pairs: (P, 2) int32 candidate pairs (a < b, sorted); confirmed: (K, 2) int32.
    contacts: dict of arrays, one row per contact: pair (C, 2) int32, normal (C, 3)
        (unit, from b to a), depth (C,) (m), jn, jt (C,) (kg m/s); octocd's engines add
        axis (C,) int32, v_a, v_b, dx_a, dx_b, dv_a, dv_b (C, 3).
    q_pre, q_post, q_det: (n, 4) float32 (w, x, y, z); w_pre, w_post, x_det: (n, 3); None
        for octocd's engines (they translate only).
    """
    frame: int
    metrics: Dict[str, Any]
    x_post: _np.ndarray
    v_post: _np.ndarray
    contacts: Dict[str, _np.ndarray]
    x_pre: Optional[_np.ndarray] = None
    v_pre: Optional[_np.ndarray] = None
    aabbs: Optional[_np.ndarray] = None
    pairs: Optional[_np.ndarray] = None
    confirmed: Optional[_np.ndarray] = None
    q_pre: Optional[_np.ndarray] = None
    q_post: Optional[_np.ndarray] = None
    w_pre: Optional[_np.ndarray] = None
    w_post: Optional[_np.ndarray] = None
    x_det: Optional[_np.ndarray] = None
    q_det: Optional[_np.ndarray] = None
    manifolds: bool = False

    def observation(self) -> Dict[str, Any]:
        """This record as Validator.observe's keyword arguments (feeds an octocd engine's
        frames to the external-engine validators, e.g. to compare with your engine's)."""
        keys = ("aabbs", "pairs", "contacts", "x_pre", "v_pre", "x_post", "v_post", "q_pre", "q_post", "w_pre",
                "w_post", "x_det", "q_det")
        return dict(frame=self.frame, manifolds=self.manifolds, **{k: getattr(self, k) for k in keys})

    @property
    def stage_ms(self) -> Dict[str, Optional[float]]:
        """Wall time per stage (ms): integrate, aabbs, broadphase, midphase, response, metrics."""
        return self.metrics["stage_ms"]


class Engine:
    """One of octocd's engines stepping a scene (octocd/engine.hpp).

    Engine(scene, engine="cpu", broadphase=None, midphase=None, record=True, cuda=None, bullet=None)

    scene: an octocd.Scene, a scene path or a dict (load_scene).
    engine: "cpu", "cuda" or "bullet" (octocd.engines lists those built).
    broadphase: overrides the scene's broadphase.name (octocd.broadphases()); "cpu" and
        "cuda" only ("bullet" runs bullet-dbvt).
    midphase: overrides midphase.levels ("aabb-only", "2", "1,2", ...); not with "bullet".
    record: keep each step's FrameRecord for last_frame() (copies per step; the stepping
        itself is unchanged, bit for bit). False: last_frame() has metrics and states only.
    cuda: settings of the "cuda" engine as keyword arguments, e.g. {"graph": False,
        "stage_times": False} (CudaSettings; docs/settings.md lists the keys); ignored by
        the other engines.
    bullet: settings of the "bullet" engine, e.g. {"shape": "box"} (BulletSettings;
        docs/settings.md: shape "hull", the default, or "box"); ignored by the others.

    Raises InputError for a bad scene or argument and for an engine not built ("cuda"
    without CUDA), RuntimeError for "cuda" without a usable device.
    Not thread-safe: a second thread calling into a stepping engine gets RuntimeError.
    """

    def __init__(self, scene: Union[Scene, str, Dict[str, Any]], engine: str = "cpu",
                 broadphase: Optional[str] = None, midphase: Optional[str] = None, record: bool = True,
                 cuda: Optional[Dict[str, Any]] = None, bullet: Optional[Dict[str, Any]] = None):
        self.scene = load_scene(scene)
        items = [f"{k}={str(v).lower() if isinstance(v, bool) else v}" for k, v in (cuda or {}).items()]
        bullet_items = [f"{k}={v}" for k, v in (bullet or {}).items()]
        self._e = _octocd.Engine(self.scene, engine, broadphase, midphase, bool(record), items, bullet_items)

    def step(self, n: int = 1) -> Dict[str, Any]:
        """Runs n steps (SPEC 4) with the GIL released; Ctrl-C stops between steps.
        Returns the last step's metrics dict (see FrameRecord.metrics). Raises
        RuntimeError naming the body and frame when the state becomes non-finite."""
        return self._e.step(int(n))

    def last_frame(self) -> FrameRecord:
        """The last step's FrameRecord (fresh NumPy copies)."""
        return FrameRecord(**self._e.last_frame())

    def set_state(self, positions, velocities) -> None:
        """Replaces positions and velocities ((n, 3), m and m/s) before the next step
        (`cpu` and `cuda`; `bullet` raises InputError)."""
        self._e.set_state(positions, velocities)

    @property
    def positions(self) -> _np.ndarray:
        """(n, 3) float32 body positions (m, centre of the world AABB): a copy."""
        return self._e.positions

    @property
    def velocities(self) -> _np.ndarray:
        """(n, 3) float32 body velocities (m/s): a copy."""
        return self._e.velocities

    @property
    def inverse_masses(self) -> _np.ndarray:
        """(n,) float32 inverse masses (1/kg, 0 = static): a copy."""
        return self._e.inverse_masses

    @property
    def local_boxes(self) -> _np.ndarray:
        """(n, 2, 3) float32 local AABBs ([:, 0] min, [:, 1] max, m); world AABB = local + position."""
        return self._e.local_boxes

    @property
    def groups(self) -> List[str]:
        """Scene group name per body ("walls" for generated walls)."""
        return self._e.groups

    name = property(lambda self: self._e.name, doc='"cpu", "cuda" or "bullet".')
    device = property(lambda self: self._e.device, doc="The CPU model or GPU name it runs on.")
    broadphase = property(lambda self: self._e.broadphase, doc="The broadphase in use.")
    midphase = property(lambda self: self._e.midphase, doc="The midphase in use.")
    frame = property(lambda self: self._e.frame, doc="Steps taken so far.")
    body_count = property(lambda self: self._e.body_count, doc="Number of bodies n (walls included).")
    recording = property(lambda self: self._e.recording, doc="Whether last_frame() has the full record.")
    notes = property(lambda self: self._e.notes, doc="How this engine's metrics differ from cpu's.")
    state_hash = property(lambda self: self._e.state_hash,
                          doc="FNV-1a 64-bit hash of the bits of every position then velocity.")

    def __repr__(self) -> str:
        return (f"octocd.Engine({self.name!r}, scene {self.scene.name!r}, {self.body_count} bodies, "
                f"broadphase {self.broadphase!r}, midphase {self.midphase!r}, frame {self.frame})")


# ---- judging another engine -----------------------------------------------------------

@dataclass
class ValidationExample:
    """One judged item of a failing cause (SPEC 13b.13): frame (step; -1 when not a
    frame's item), item ("pair (A, B)", "body I", "group (I, J, K)", "" for the run),
    figure (in its cause's unit) and one line of text."""
    frame: int
    item: str
    figure: float
    text: str


@dataclass
class ValidationCause:
    """One cause of a row's failures (e.g. row "conservation", cause "energy"): how many
    items failed for it (count), the worst figure (in `unit`), the first examples and the
    sorted distinct failing items (complete when items_complete). A row that does not
    split its failures has one cause named like the row."""
    name: str
    unit: str
    count: int
    worst: float
    examples: List[ValidationExample] = field(default_factory=list)
    items: List[str] = field(default_factory=list)
    items_complete: bool = True


@dataclass
class ValidationResult:
    """One validator's verdict (one row of the `octocd validate` table).

    tier: "physics" (any engine, judged on the posed shapes) or "model" (octocd's SPEC 6
    response); name: e.g. "candidate-sets"; figure: what `measured` is, with its unit;
    measured, bound: the figure and the bound it is held to; passed: within the bound;
    applicable: False when there was nothing to judge (n/a, counts as a pass); verdict:
    "pass", "FAIL", "n/a" or (with expectations) "expected"; detail: the first offending
    frame/pair, or a summary; tolerances: the Tolerances names the verdict depends on
    (comma-separated); judged: items the row judged; seconds: its own time; causes: its
    failures by cause (empty when it passed).
    """
    tier: str
    name: str
    figure: str
    measured: float
    bound: float
    passed: bool
    applicable: bool
    verdict: str
    detail: str
    tolerances: str = ""
    judged: int = 0
    seconds: float = 0.0
    causes: List[ValidationCause] = field(default_factory=list)

    @property
    def failed(self) -> bool:
        """True for a FAIL (applicable and not passed; an expected failure too)."""
        return self.applicable and not self.passed

    def __str__(self) -> str:
        return (f"[{self.tier}] {self.name}: {self.verdict} ({self.figure} {self.measured:g}, "
                f"bound {self.bound:g}) {self.detail}")


@dataclass
class ExpectationOutcome:
    """What became of one failing cause or one expectation (SPEC 14b): outcome is
    "expected" (within its figure and items), "new" (no expectation), "grown" (beyond its
    figure, or items outside the listed ones: `outside`) or "fixed" (expected, no longer
    failing); worst: the measured figure, allowed: the expectation's (new: the row's
    bound); text: the line `octocd validate --expect` prints."""
    outcome: str
    row: str
    cause: str
    unit: str
    count: int
    worst: float
    allowed: float
    outside: List[str]
    reason: str
    text: str


class ValidationResults(list):
    """The rows of a validation (a list of ValidationResult), with what expectations made
    of them: `outcomes` (ExpectationOutcome; without expectations every failure is "new")
    and `exit_code` (0 when nothing failed beyond the expectations, 3 otherwise: what
    `octocd validate --expect` exits with); `ok` is exit_code == 0."""

    def __init__(self, rows=(), outcomes=(), exit_code: int = 0):
        super().__init__(rows)
        self.outcomes: List[ExpectationOutcome] = list(outcomes)
        self.exit_code: int = exit_code

    @property
    def ok(self) -> bool:
        return self.exit_code == 0


def _results(rows) -> List[ValidationResult]:
    out = []
    for r in rows:
        r = dict(r)
        r["causes"] = [ValidationCause(**{**c, "examples": [ValidationExample(**x) for x in c["examples"]]})
                       for c in r.get("causes", [])]
        out.append(ValidationResult(**r))
    return out


class Validator:
    """Judges another engine's frames one step at a time (octocd/external.hpp,
    ExternalValidator): feed every frame of a run with observe(), then read results().

    Bodies (constant over the run), given by a scene, by arrays, or both (then they must
    agree):
      scene: an octocd.Scene, path or dict: its parameters (dt, gravity, response alpha,
          beta, delta, mu_s, ...) are judged against; its bodies (walls first, then each
          group's bodies in order) with their meshes become the bodies.
      local_boxes: (n, 2, 3) float local AABB per body ([:, 0] min, [:, 1] max, m); the
          world AABB is this box translated by the body's position.
      inverse_mass: (n,) float, 1/kg, 0 = static (default 1 kg each).
      dt (s), gravity ((3,), m/s^2): without a scene, for integrating states into AABBs.
      domain: (2, 3) [min, max] (m) for octocd's octree/hash broadphases.
      meshes: list with one entry per body: None (the body is its box) or (vertices (V, 3)
          float, triangles (T, 3) int) in the frame of its local box; reuse one tuple
          object for bodies sharing a mesh.
      physics: dict of PhysicsBodies fields (physics.hpp): inertia (n, 3, 3),
          body_friction, body_restitution (n,), mu, restitution, combine ("product",
          "min", "max", "average", "geometric"), contact_margin (m), theta_margin,
          broadphase_exact, contact_geometry ("shape" or "aabb"), slop (m).
    Options: engine (names it in verdicts), against_fcl (Bullet/FCL broadphases beside
    `flat`, FCL normals), spec6_response (also judge the applied state against octocd's
    SPEC 6 response), tolerances ({name: value}, see octocd.tolerances()).

    Raises InputError naming the argument for inconsistent bodies.
    """

    def __init__(self, scene=None, *, local_boxes=None, inverse_mass=None, dt: float = 0.001,
                 gravity=(0.0, -9.81, 0.0), domain=None, meshes=None, physics=None,
                 engine: str = "external", against_fcl: bool = True, spec6_response: bool = False,
                 tolerances: Optional[Dict[str, float]] = None):
        scene_json = "" if scene is None else load_scene(scene).json
        self._tolerances = dict(tolerances or {})
        self._v = _octocd.Validator(local_boxes, inverse_mass, scene_json, float(dt), gravity, domain, meshes,
                                    physics, engine, bool(against_fcl), bool(spec6_response), tolerances)

    @property
    def body_count(self) -> int:
        """Number of bodies n."""
        return self._v.body_count

    def observe(self, frame: int, *, aabbs=None, pairs=None, contacts=None, x_pre=None, v_pre=None,
                x_post=None, v_post=None, q_pre=None, q_post=None, w_pre=None, w_post=None, x_det=None,
                q_det=None, manifolds: bool = False, checked: bool = True) -> "Validator":
        """Judges one step of the other engine (GIL released while judging).

        frame: the step's number (1-based), named in verdicts.
        aabbs: (n, 2, 3) world AABBs its collision detection used (m); None: derived
            from x_pre, v_pre by SPEC 4.1 (semi-implicit Euler) for non-rotating bodies.
        pairs: (P, 2) int candidate pairs (a < b < n, sorted, unique); None: the engine
            has no candidate set (candidate-sets is then not judged on this frame).
        contacts: dict pair (C, 2) int, normal (C, 3) (unit, from B to A), depth (C,)
            (m, >= 0), jn (C,) (>= 0), jt (C,) (kg m/s), optional point (C, 3) (m).
        x_pre, v_pre, x_post, v_post: (n, 3) states before / after the step: all four
            or none.
        q_pre, q_post: (n, 4) orientations (w, x, y, z), unit, body to world; w_pre,
            w_post: (n, 3) angular velocities (rad/s, world); x_det, q_det: the pose the
            detection ran at (default: octocd's rule).
        manifolds: contacts may hold several rows per pair (consecutive).
        checked: run the costly validators (candidate sets, normals) on this frame.

        Raises InputError naming the argument (shape, dtype, a non-finite value, an
        unsorted pair ...) before anything of the frame is judged. Returns self.
        """
        self._v.observe(int(frame), aabbs, pairs, contacts, x_pre, v_pre, x_post, v_post, q_pre, q_post,
                        w_pre, w_post, x_det, q_det, bool(manifolds), bool(checked))
        return self

    def results(self) -> List[ValidationResult]:
        """Every row so far (the `octocd validate` table), each with its tier."""
        return _results(self._v.results())

    def format(self) -> str:
        """The results as the `octocd validate` table."""
        return format_results(self.results(), list(self._tolerances))


def validate_frame(scene=None, *, frame: int = 1, aabbs=None, pairs=None, contacts=None, x_pre=None,
                   v_pre=None, x_post=None, v_post=None, q_pre=None, q_post=None, w_pre=None, w_post=None,
                   x_det=None, q_det=None, manifolds: bool = False, **bodies_and_options) -> List[ValidationResult]:
    """Judges one frame of another engine: Validator(scene, **bodies_and_options) then
    observe(frame, ...) and results(). See Validator for the bodies and options
    (local_boxes, inverse_mass, dt, gravity, domain, meshes, physics, engine,
    against_fcl, spec6_response, tolerances) and Validator.observe for the arrays.
    To judge a whole run, keep one Validator and observe every frame (cheaper: FCL
    geometry is built once)."""
    v = Validator(scene, **bodies_and_options)
    v.observe(frame, aabbs=aabbs, pairs=pairs, contacts=contacts, x_pre=x_pre, v_pre=v_pre, x_post=x_post,
              v_post=v_post, q_pre=q_pre, q_post=q_post, w_pre=w_pre, w_post=w_post, x_det=x_det, q_det=q_det,
              manifolds=manifolds)
    return v.results()


def validate_trace(path: Union[str, "_os.PathLike[str]"], *, every: int = 1, max_frames: int = 0,
                   against_fcl: bool = True, tolerances: Optional[Dict[str, float]] = None,
                   expect: Union[None, str, "_os.PathLike[str]", Dict[str, Any]] = None,
                   strict: bool = False) -> ValidationResults:
    """Judges an external trace (docs/trace-format.md, "External traces"; what `octocd
    validate --trace-in PATH` does): the costly validators every `every`-th frame, at most
    max_frames frames (0 = all). A trace of `octocd run --state-every 1 --contacts` is one.
    Raises InputError "PATH: DATASET: [frame F: ]PROBLEM; allowed: ..." for a missing,
    unreadable or malformed trace. The GIL is released while judging.

    expect: known failures (SPEC 14b; docs/validation-output.md), a path to an
    expectations file or the same as a dict ({"expectations": [...]}); entries name the
    trace by its file name ("trace": "run.h5"). Rows whose every failure is expected read
    verdict "expected"; the returned list's `outcomes` and `exit_code` (3 for a new or
    grown failure, or with `strict` a fixed expectation) say the rest. A malformed
    expectations file raises InputError naming the entry, before the trace is judged."""
    text, origin = None, ""
    if isinstance(expect, dict):
        text, origin = _json.dumps(expect), "expect"
    elif expect is not None:
        origin = _os.fspath(expect)
        try:
            with open(origin, encoding="utf-8") as f:
                text = f.read()
        except OSError as e:
            raise InputError(f"expect: cannot read '{origin}' ({e.strerror}); allowed: an expectations file (JSON)")
    rows, outcomes, code = _octocd.validate_trace(_os.fspath(path), int(every), int(max_frames), bool(against_fcl),
                                                 tolerances, text, origin, bool(strict))
    return ValidationResults(_results(rows), [ExpectationOutcome(**o) for o in outcomes], code)


def format_results(results: Sequence[ValidationResult], overridden: Sequence[str] = ()) -> str:
    """The `octocd validate` table of `results` (tier, name, figure, measured, bound,
    verdict, detail); bounds depending on an `overridden` tolerance are marked '*'."""
    return _octocd.format_results(list(results), list(overridden))


def failures(results: Sequence[ValidationResult]) -> List[ValidationResult]:
    """The FAIL rows of `results`."""
    return [r for r in results if r.failed]


# ---- traces ---------------------------------------------------------------------------

class Trace:
    """A thin helper over h5py for traces (docs/trace-format.md): the per-frame slices that
    need the trace's layout (states by frame, CSR contacts by frame). For anything else use
    `trace.h5` (the open h5py.File) directly.

        with octocd.Trace("run.h5") as t:
            x, v = t.state(100)           # (n, 3) float32 each
            q, w = t.rotation(100)        # (n, 4) (w, x, y, z) and (n, 3) rad/s
            c = t.contacts(100)           # dict of arrays, as FrameRecord.contacts
            ms = t.frames["step_ms"]      # /frames datasets as NumPy arrays

    Reads octocd's own traces (`octocd run --trace`: format version 1, or 2 with `--engine
    bullet --rotation`) and external traces of version 1 or 2 (another engine's; no
    /frames, contacts by position: step f's rows are /contacts/offsets[f-1] ..
    offsets[f]-1). Version 2 adds orientations, angular velocities, inertia, materials and
    manifold contacts with points (docs/trace-format.md, "External traces, version 2"); a
    trace without rotation reads as unrotated (identity orientations, zero angular
    velocities) and its inertia is derived (a solid box of the local AABB, Bullet's rule).

    `version` (1 or 2), `external` (no /frames) and `rotating` (/states/orientation) say
    what the file is. Opened read-only with swmr=True, so killed runs read too (complete
    rows only). Raises InputError "PATH: DATASET: [frame F: ][body I: ]PROBLEM; allowed:
    ..." for a file that is not such a trace, and for bad values where they are read.
    """

    _V2_DATASETS = ("states/orientation", "states/angular_velocity", "bodies/inertia", "bodies/friction",
                    "bodies/restitution", "contacts/point")

    def __init__(self, path: Union[str, "_os.PathLike[str]"]):
        import h5py  # Debian: python3-h5py
        self.path = _os.fspath(path)
        self.h5 = h5py.File(self.path, "r", swmr=True)
        try:
            self._check()
        except BaseException:
            self.h5.close()
            raise

    def _fail(self, what: str, problem: str, allowed: str) -> None:
        raise InputError(f"{self.path}: {what}: {problem}; allowed: {allowed}")

    def _check(self) -> None:
        fmt = self.h5.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode("utf-8", "replace")
        if fmt != "octocd-trace":
            self._fail("attribute format", repr(fmt), "'octocd-trace' (docs/trace-format.md)")
        ver = self.h5.attrs.get("version")
        try:
            num = ver is not None and not isinstance(ver, (str, bytes)) and _np.asarray(ver).size == 1
            v = float(_np.asarray(ver).reshape(-1)[0]) if num else None
        except (TypeError, ValueError):
            v = None
        if v not in (1.0, 2.0):
            self._fail("attribute version", repr(ver), "1 or 2 (docs/trace-format.md)")
        self.version = int(v)
        self.external = "frames" not in self.h5
        if self.version == 1:
            for d in self._V2_DATASETS:
                if d in self.h5:
                    self._fail("/" + d, "a version 2 dataset in a version 1 trace (v1/v2 fields mixed)",
                               "/states/orientation, /states/angular_velocity, /bodies/inertia, /bodies/friction, "
                               "/bodies/restitution, /contacts/point only with the root attribute version = 2")
        st = self.h5.get("states")
        has_q = st is not None and "orientation" in st
        has_w = st is not None and "angular_velocity" in st
        if has_q != has_w:
            self._fail("/states/" + ("angular_velocity" if has_q else "orientation"),
                       f"missing (/states/{'orientation' if has_q else 'angular_velocity'} present)",
                       "/states/orientation and /states/angular_velocity together, or neither (no rotation)")
        n = self.body_count
        for name, tail in (("orientation", 4), ("angular_velocity", 3)):
            if st is not None and name in st:
                shape = st[name].shape
                if len(shape) != 3 or shape[1] != n or shape[2] != tail:
                    self._fail(f"/states/{name}", f"shape {' x '.join(map(str, shape))}",
                               f"states x {n} bodies x {tail}")

    def __enter__(self) -> "Trace":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.h5.close()

    @property
    def attrs(self) -> Dict[str, Any]:
        """Root attributes (engine, scene, dt, state_every, ...)."""
        return dict(self.h5.attrs)

    @property
    def body_count(self) -> int:
        """Number of bodies n (rows of /bodies/inverse_mass)."""
        if "bodies/inverse_mass" not in self.h5:
            self._fail("/bodies/inverse_mass", "missing", "n values (1/kg, 0 = static), one per body")
        return int(self.h5["bodies/inverse_mass"].shape[0])

    @property
    def rotating(self) -> bool:
        """Whether the trace holds orientations (/states/orientation, version 2)."""
        return "states/orientation" in self.h5

    @property
    def frames(self) -> Dict[str, _np.ndarray]:
        """/frames: one array per dataset, cut to the complete rows ({} for an external
        trace, which has no /frames)."""
        if "frames" not in self.h5:
            return {}
        fr = self.h5["frames"]
        n = min(d.shape[0] for d in fr.values())
        return {k: d[:n] for k, d in fr.items()}

    def _state_rows(self) -> int:
        st = self.h5["states"]
        s = min(st[k].shape[0] for k in ("frame", "position", "velocity", "orientation", "angular_velocity")
                if k in st)
        c = self.h5.attrs.get("committed_states")
        return s if c is None else min(s, int(c))

    @property
    def state_frames(self) -> _np.ndarray:
        """Frames that have a state row (0, k, 2k, ...; an external trace without
        /states/frame: 0, 1, ..., F), complete rows only."""
        if "states" not in self.h5:
            self._fail("/states", "absent", "a trace with states (positions and velocities)")
        s = self._state_rows()
        st = self.h5["states"]
        return st["frame"][:s] if "frame" in st else _np.arange(s, dtype=_np.int64)

    def _state_row(self, frame: int) -> int:
        frames = self.state_frames
        rows = _np.flatnonzero(frames == frame)
        if rows.size == 0:
            raise InputError(f"{self.path}: /states: no state for frame {frame}; allowed: frames "
                             f"{frames[:1].tolist()}..{frames[-1:].tolist()} "
                             f"every {self.h5.attrs.get('state_every', 1)}")
        return int(rows[0])

    def state(self, frame: int):
        """(positions, velocities) at `frame`, each (n, 3) float32. Raises InputError when
        the trace holds no state for that frame (it keeps every state_every-th)."""
        r = self._state_row(frame)
        st = self.h5["states"]
        return st["position"][r], st["velocity"][r]

    def _check_unit(self, q: _np.ndarray, frames) -> None:
        norm = _np.sqrt(_np.sum(_np.asarray(q, _np.float64) ** 2, axis=-1))
        bad = ~(_np.abs(norm - 1.0) <= 1e-3)
        if bad.any():
            idx = tuple(int(i) for i in _np.argwhere(bad)[0])
            row = idx[0] if q.ndim == 3 else None
            body = idx[-1]
            frame = frames if row is None else int(frames[row])
            self._fail("/states/orientation", f"frame {frame}: body {body}: {q[idx].tolist()}, |q| = {norm[idx]:g}",
                       "unit quaternions (w, x, y, z), body to world, | |q| - 1 | <= 1e-3")

    def rotation(self, frame: int):
        """(orientations, angular_velocities) at `frame`: (n, 4) float32 unit quaternions
        (w, x, y, z), body to world, and (n, 3) float32 rad/s in the world frame. A trace
        without rotation gives the identity and zeros. Raises InputError when the trace
        holds no state for that frame, or naming the body of a non-unit quaternion."""
        r = self._state_row(frame)
        n = self.body_count
        if not self.rotating:
            q = _np.zeros((n, 4), _np.float32)
            q[:, 0] = 1.0
            return q, _np.zeros((n, 3), _np.float32)
        st = self.h5["states"]
        q = st["orientation"][r].astype(_np.float32, copy=False)
        self._check_unit(q, frame)
        return q, st["angular_velocity"][r].astype(_np.float32, copy=False)

    @property
    def orientations(self) -> _np.ndarray:
        """(S, n, 4) float32: the orientation of every state row (state_frames), complete
        rows only; identity without rotation. Raises InputError naming frame and body of a
        non-unit quaternion."""
        s, n = len(self.state_frames), self.body_count
        if not self.rotating:
            q = _np.zeros((s, n, 4), _np.float32)
            q[..., 0] = 1.0
            return q
        q = self.h5["states/orientation"][:s].astype(_np.float32, copy=False)
        self._check_unit(q, self.state_frames)
        return q

    @property
    def angular_velocities(self) -> _np.ndarray:
        """(S, n, 3) float32 rad/s (world frame) of every state row; zeros without rotation."""
        s, n = len(self.state_frames), self.body_count
        if not self.rotating:
            return _np.zeros((s, n, 3), _np.float32)
        return self.h5["states/angular_velocity"][:s].astype(_np.float32, copy=False)

    @property
    def inertia(self) -> _np.ndarray:
        """(n, 3, 3) float32 body-frame inertia tensors (kg m^2): /bodies/inertia, else
        derived as a solid box of the local AABB at the body's mass, m/12 diag(b^2 + c^2,
        a^2 + c^2, a^2 + b^2) (Bullet's rule; zeros for static bodies)."""
        n = self.body_count
        if "bodies/inertia" in self.h5:
            d = self.h5["bodies/inertia"]
            if d.shape != (n, 3, 3):
                self._fail("/bodies/inertia", f"shape {' x '.join(map(str, d.shape))}",
                           f"{n} x 3 x 3 (kg m^2, body frame, one per body)")
            return d[:].astype(_np.float32, copy=False)
        lo = self.h5["bodies/local_aabb_min"][:].astype(_np.float64)
        hi = self.h5["bodies/local_aabb_max"][:].astype(_np.float64)
        w = self.h5["bodies/inverse_mass"][:].astype(_np.float64)
        m = _np.where(w > 0, 1.0 / _np.where(w > 0, w, 1.0), 0.0)
        a, b, c = (hi - lo).T
        out = _np.zeros((n, 3, 3))
        out[:, 0, 0] = m / 12 * (b * b + c * c)
        out[:, 1, 1] = m / 12 * (a * a + c * c)
        out[:, 2, 2] = m / 12 * (a * a + b * b)
        return out.astype(_np.float32)

    @property
    def materials(self) -> Dict[str, Any]:
        """The materials a version 2 trace states (docs/trace-format.md, "Materials"): mu,
        restitution, friction_combine, restitution_combine, contact_margin (the root
        attributes, None when absent) and body_friction, body_restitution ((n,) float32 per
        body: /bodies/friction, /bodies/restitution, or None); the names of PhysicsBodies
        (Validator's physics=)."""
        at = self.h5.attrs

        def attr(k):
            v = at.get(k)
            if isinstance(v, bytes):
                return v.decode("utf-8", "replace")
            if isinstance(v, _np.generic):
                return v.item()
            return v
        out = {k: attr(k) for k in ("mu", "restitution", "friction_combine", "restitution_combine",
                                    "contact_margin")}
        for k in ("friction", "restitution"):
            d = self.h5.get("bodies/" + k)
            out["body_" + k] = None if d is None else d[:].astype(_np.float32)
        return out

    def _contact_rows(self, frame: int):
        if "contacts" not in self.h5:
            raise InputError(f"{self.path}: /contacts: absent; allowed: a trace written with --contacts")
        c = self.h5["contacts"]
        off = c["offsets"]
        if "frame" in c:
            rows = _np.flatnonzero(c["frame"][:] == frame)
            if rows.size == 0:
                raise InputError(f"{self.path}: /contacts/frame: no row for frame {frame}")
            i = int(rows[0])
        else:  # an external trace: step f's rows are offsets[f-1] .. offsets[f]-1
            if not 1 <= frame <= off.shape[0] - 1:
                raise InputError(f"{self.path}: /contacts/offsets: no row for frame {frame}; allowed: frames 1.."
                                 f"{off.shape[0] - 1}")
            i = frame - 1
        a, b = int(off[i]), int(off[i + 1])
        if not 0 <= a <= b <= c["pair"].shape[0]:
            self._fail("/contacts/offsets", f"frame {frame}: rows {a}..{b - 1}",
                       f"0 <= offsets[f-1] <= offsets[f] <= {c['pair'].shape[0]} (the rows of /contacts/pair)")
        return c, a, b

    def contacts(self, frame: int) -> Dict[str, _np.ndarray]:
        """Frame `frame`'s /contacts rows: pair (C, 2), normal (C, 3), depth, jn, jt (C,)
        and, when the trace has /contacts/point (version 2), point (C, 3) (world, m). A
        version 2 trace may hold several rows per pair (a manifold, consecutive): see
        contacts_by_pair. Raises InputError when the trace has no contacts for it."""
        c, a, b = self._contact_rows(frame)
        return {k: c[k][a:b] for k in ("pair", "normal", "depth", "jn", "jt", "point") if k in c}

    def contacts_by_pair(self, frame: int) -> Dict[Any, Dict[str, _np.ndarray]]:
        """Frame `frame`'s contacts grouped by pair: {(a, b): {"normal": (k, 3), "depth",
        "jn", "jt": (k,), "point": (k, 3) when present}}, a pair's k rows (its manifold) in
        the order written, pairs in (a, b) order."""
        rows = self.contacts(frame)
        out: Dict[Any, Dict[str, _np.ndarray]] = {}
        pairs = [tuple(int(x) for x in p) for p in rows["pair"]]
        for key in sorted(set(pairs)):
            sel = _np.array([p == key for p in pairs], dtype=bool)
            out[key] = {k: v[sel] for k, v in rows.items() if k != "pair"}
        return out
