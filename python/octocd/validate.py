"""Judging another engine's frames with octocd's validators (octocd/external.hpp):
octocd.Validator, validate_frame, validate_trace, the result types and the table."""
from __future__ import annotations

import json as _json
import os as _os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

from . import _args, _octocd
from .scene import load_scene

InputError = _octocd.InputError


@dataclass
class ValidationExample:
    """One judged item of a failing cause (design.md section 13b.13): frame (step; -1 when not a
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

    tier: "physics" (any engine, judged on the posed shapes) or "model" (octocd's design.md section 6
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
    """What became of one failing cause or one expectation (design.md section 14b): outcome is
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
        # validate_trace(..., shard=...): the shard's verdict as JSON (merge_validations).
        self.shard_json: Optional[Dict[str, Any]] = None

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
    design.md section 6 response), tolerances ({name: value}, see octocd.tolerances()).

    Raises InputError naming the argument for inconsistent bodies.
    """

    def __init__(self, scene=None, *, local_boxes=None, inverse_mass=None, dt: float = 0.001,
                 gravity=(0.0, -9.81, 0.0), domain=None, meshes=None, physics=None,
                 engine: str = "external", against_fcl: bool = True, spec6_response: bool = False,
                 tolerances: Optional[Dict[str, float]] = None):
        sc = None if scene is None else load_scene(scene)
        if sc is not None and sc.body_count > _octocd.max_judged_bodies:  # before any model is built
            raise InputError(f"scene: {sc.body_count} bodies; allowed: at most {_octocd.max_judged_bodies} bodies to "
                             "judge (the flat oracle tests every pair of bodies each frame: O(n^2)), as `octocd "
                             "validate --trace-in`")
        scene_json = "" if sc is None else sc.json
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
            from x_pre, v_pre by design.md section 4.1 (semi-implicit Euler) for non-rotating bodies.
        pairs: (P, 2) int candidate pairs (a < b < n, sorted, unique); None: the engine
            has no candidate set (candidate-sets is then not judged on this frame).
        contacts: dict pair (C, 2) int, normal (C, 3) (unit, from B to A), depth (C,)
            (m, >= 0), jn (C,) (>= 0), jt (C,) (kg m/s), optional point (C, 3) (m), with it
            optional point_b (C, 3) (m: each row's point on B, the impulse applied between the
            two witness points), and optional jt3 (C, 3) (kg m/s: each row's friction impulse
            vector on A); docs/trace-format.md's /contacts/point_b and /contacts/jt3.
        x_pre, v_pre, x_post, v_post: (n, 3) states before / after the step: all four
            or none.
        q_pre, q_post: (n, 4) orientations (w, x, y, z), unit, body to world; w_pre,
            w_post: (n, 3) angular velocities (rad/s, world); x_det, q_det: the pose the
            detection ran at (default: octocd's rule).
        manifolds: contacts may hold several rows per pair (consecutive).
        checked: run the costly validators (candidate sets, normals) on this frame.

        Raises InputError naming the argument (shape, dtype, a non-finite value, an
        unsorted pair ...) before anything of the frame is judged, and "frame F: N bodies'
        boxes crowd together: ..." for a checked frame whose boxes overlap in more than 64
        pairs a body (coincident bodies), before any pair is judged. Ctrl-C raises
        KeyboardInterrupt at once (the frame is judged on a helper thread; one cut short
        ends in the background and the next call waits for it). Returns self.
        """
        self._v.observe(_args.integer("frame", frame, 1, _args.INT64_MAX), aabbs, pairs, contacts, x_pre, v_pre, x_post, v_post, q_pre, q_post,
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
                   strict: bool = False, shard: Optional[Tuple[int, int]] = None,
                   mesh_dir: Union[None, str, "_os.PathLike[str]"] = None) -> ValidationResults:
    """Judges an external trace (docs/trace-format.md, "External traces"; what `octocd
    validate --trace-in PATH` does): the costly validators every `every`-th frame, at most
    max_frames frames (0 = all). A trace of `octocd run --state-every 1 --contacts` is one.
    Raises InputError "PATH: DATASET: [frame F: ]PROBLEM; allowed: ..." for a missing,
    unreadable or malformed trace. The GIL is released while judging.

    expect: known failures (design.md section 14b; docs/validation-output.md), a path to an
    expectations file or the same as a dict ({"expectations": [...]}); entries name the
    trace by its file name ("trace": "run.h5"). Rows whose every failure is expected read
    verdict "expected"; the returned list's `outcomes` and `exit_code` (3 for a new or
    grown failure, or with `strict` a fixed expectation) say the rest. A malformed
    expectations file raises InputError naming the entry, before the trace is judged.

    shard: (i, n) judges only shard i of n (`validate --shard i/n`: the contiguous block of
    frames floor(i F / n) + 1 .. floor((i + 1) F / n)); the result's `shard_json` is the
    verdict as `validate --shard --json` writes it, for merge_validations.

    mesh_dir: where the mesh files named by the trace's `scene` attribute are looked up
    (`validate --trace-in --mesh-dir DIR`): dataset names in the data dir, files only inside
    this folder (default None: the trace's folder), symbolic links resolved; a mesh named
    anywhere else raises InputError naming the scene key and --mesh-dir, before any frame is
    judged (a trace cannot make octocd read another file)."""
    text, origin = None, ""
    if isinstance(expect, dict):
        text, origin = _json.dumps(expect), "expect"
    elif expect is not None:
        origin, text = _args.read_json_input("expect", expect, "an expectations file (JSON)")
    share = None
    if shard is not None:
        if isinstance(shard, (str, bytes)) or not hasattr(shard, "__len__") or len(shard) != 2:
            raise InputError(f"shard: {shard!r:.80}; allowed: (i, n), shard i of n, 0 <= i < n <= 100000")
        n = _args.integer("shard[1]", shard[1], 1, 100000)
        share = f"{_args.integer('shard[0]', shard[0], 0, n - 1)}/{n}"
    rows, outcomes, code, doc = _octocd.validate_trace(_args.path("path", path), _args.integer("every", every, 1, 2**31 - 1),
                                                      _args.integer("max_frames", max_frames, 0, _args.INT64_MAX),
                                                      bool(against_fcl), tolerances, text, origin, bool(strict), share,
                                                      "" if mesh_dir is None else _args.path("mesh_dir", mesh_dir))
    out = ValidationResults(_results(rows), [ExpectationOutcome(**o) for o in outcomes], code)
    out.shard_json = _json.loads(doc) if doc else None
    return out


def merge_validations(shards) -> ValidationResults:
    """Joins the verdicts of every shard of one trace's judging (`octocd validate --merge`;
    docs/validation-output.md, "Shards") into the unsharded run's rows. `shards`: a list of
    validate_trace(..., shard=(i, n)) results, their `shard_json` dicts, or paths of
    `validate --shard --json` files, in any order. Raises InputError naming the shard for
    overlapping, missing or foreign shards (another trace, engine, frames, every, against
    or tolerances). exit_code: 0 when every row passes, 3 otherwise."""
    if isinstance(shards, (str, bytes, _os.PathLike, dict, ValidationResults)) or not hasattr(shards, "__iter__"):
        raise InputError(f"merge_validations: shards: a {type(shards).__name__}; allowed: a list of the shards "
                         "(validate_trace(..., shard=(i, n)) results, their shard_json dicts or --json paths), "
                         "e.g. merge_validations(['s0.json', 's1.json'])")
    texts, names = [], []
    for k, s in enumerate(shards):
        if isinstance(s, ValidationResults):
            if s.shard_json is None:
                raise InputError(f"merge_validations: shard {k}: not a shard's result; allowed: "
                                 "validate_trace(..., shard=(i, n)) results")
            texts.append(_json.dumps(s.shard_json))
            names.append(f"shard {k}")
        elif isinstance(s, dict):
            texts.append(_json.dumps(s))
            names.append(f"shard {k}")
        else:
            name, text = _args.read_json_input(f"merge_validations: shards[{k}]", s, "a shard's --json file")
            texts.append(text)
            names.append(name)
    rows, outcomes, code = _octocd.merge_validations(texts, names)
    return ValidationResults(_results(rows), [ExpectationOutcome(**o) for o in outcomes], code)


def format_results(results: Sequence[ValidationResult], overridden: Sequence[str] = ()) -> str:
    """The `octocd validate` table of `results` (tier, name, figure, measured, bound,
    verdict, detail); bounds depending on an `overridden` tolerance are marked '*'."""
    return _octocd.format_results(list(results), list(overridden))


def failures(results: Sequence[ValidationResult]) -> List[ValidationResult]:
    """The FAIL rows of `results`."""
    return [r for r in results if r.failed]
