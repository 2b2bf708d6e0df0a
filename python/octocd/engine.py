"""octocd.Engine and octocd.FrameRecord: octocd's engines stepping a scene, and what each
step did as NumPy copies (octocd/engine.hpp)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Union

import numpy as _np

from . import _args, _octocd
from .scene import Scene, load_scene


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


def _passed(name: str, doc: str) -> property:
    """A read-only property of Engine that answers the compiled engine's attribute `name`."""
    return property(lambda self: getattr(self._e, name), doc=doc)


class Engine:
    """One of octocd's engines stepping a scene (octocd/engine.hpp).

    Engine(scene, engine="cpu", broadphase=None, midphase=None, record=True, **settings)

    scene: an octocd.Scene, a scene path or a dict (load_scene).
    engine: "cpu", "cuda" or "bullet" (octocd.engines lists those built).
    broadphase: overrides the scene's broadphase.name (octocd.broadphases()); "cpu" and
        "cuda" only ("bullet" runs bullet-dbvt).
    midphase: overrides midphase.levels ("aabb-only", "2", "1,2", ...); not with "bullet".
    record: keep each step's FrameRecord for last_frame() (copies per step; the stepping
        itself is unchanged, bit for bit). False: last_frame() has metrics and states only.
    **settings: an engine's settings as a keyword named after the engine, a dict of KEY:
        VALUE, e.g. cuda={"graph": False, "stage_times": False} (CudaSettings) or
        bullet={"shape": "box"} (BulletSettings); docs/settings.md lists each engine's
        keys. Every engine's settings are checked (a bad key raises InputError); an engine
        reads only its own.

    Raises InputError for a bad scene or argument and for an engine not built ("cuda"
    without CUDA), RuntimeError for "cuda" without a usable device.
    Not thread-safe: a second thread calling into a stepping engine gets RuntimeError.
    """

    def __init__(self, scene: Union[Scene, str, Dict[str, Any]], engine: str = "cpu",
                 broadphase: Optional[str] = None, midphase: Optional[str] = None, record: bool = True,
                 **settings: Optional[Dict[str, Any]]):
        if not isinstance(engine, str):
            raise _octocd.InputError(f"engine: {type(engine).__name__} ({engine!r}); allowed: an engine's name as a "
                                     f"str, one of octocd.engines")
        self.scene = load_scene(scene)
        items: Dict[str, List[str]] = {}
        for name, values in settings.items():
            if values is None:
                continue
            if not isinstance(values, dict):
                raise _octocd.InputError(f"{name}: {type(values).__name__}; allowed: a dict of the {name} engine's "
                                 f"settings, e.g. {name}={{KEY: VALUE}} (docs/settings.md)")
            items[name] = [f"{k}={str(v).lower() if isinstance(v, bool) else v}" for k, v in values.items()]
        self._e = _octocd.Engine(self.scene, engine, broadphase, midphase, bool(record), items)

    def step(self, n: int = 1) -> Dict[str, Any]:
        """Runs n steps (design.md section 4) with the GIL released; Ctrl-C raises KeyboardInterrupt
        between steps, within one step's time, leaving the engine at its last whole step
        (frame, state and last_frame() as after that step; stepping may go on). Without
        recording, the steps are promised to the engine (Engine::plan_steps): the cuda
        engine's resident small step runs up to 64 of them a host round trip, and an
        interrupt first takes the steps it already ran (frame() counts them).
        Returns the last step's metrics dict (see FrameRecord.metrics). Raises
        RuntimeError naming the body and frame when the state becomes non-finite."""
        return self._e.step(_args.integer("n", n, 0, 2**31 - 1))

    def last_frame(self) -> FrameRecord:
        """The last step's FrameRecord (fresh NumPy copies)."""
        return FrameRecord(**self._e.last_frame())

    def set_state(self, positions, velocities) -> None:
        """Replaces positions and velocities ((n, 3), m and m/s) before the next step
        (`cpu` and `cuda`; `bullet` raises InputError)."""
        self._e.set_state(positions, velocities)

    positions = _passed("positions", "(n, 3) float32 body positions (m, centre of the world AABB): a copy.")
    velocities = _passed("velocities", "(n, 3) float32 body velocities (m/s): a copy.")
    inverse_masses = _passed("inverse_masses", "(n,) float32 inverse masses (1/kg, 0 = static): a copy.")
    local_boxes = _passed("local_boxes", "(n, 2, 3) float32 local AABBs ([:, 0] min, [:, 1] max, m); world AABB = "
                                         "local + position.")
    groups = _passed("groups", 'Scene group name per body ("walls" for generated walls).')
    name = _passed("name", '"cpu", "cuda" or "bullet".')
    device = _passed("device", "The CPU model or GPU name it runs on.")
    broadphase = _passed("broadphase", "The broadphase in use.")
    midphase = _passed("midphase", "The midphase in use.")
    frame = _passed("frame", "Steps taken so far (whole steps; safe to read from another thread during step()).")
    body_count = _passed("body_count", "Number of bodies n (walls included).")
    recording = _passed("recording", "Whether last_frame() has the full record.")
    notes = _passed("notes", "How this engine's metrics differ from cpu's.")
    state_hash = _passed("state_hash", "FNV-1a 64-bit hash of the bits of every position then velocity.")

    def __repr__(self) -> str:
        return (f"octocd.Engine({self.name!r}, scene {self.scene.name!r}, {self.body_count} bodies, "
                f"broadphase {self.broadphase!r}, midphase {self.midphase!r}, frame {self.frame})")
