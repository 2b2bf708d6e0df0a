"""octocd.Trace: per-frame slices of octocd's traces and external ones, read through the
CLI's hardened reader (octocd::TraceReader via the compiled module), never plain h5py."""
from __future__ import annotations

import os as _os
from typing import Any, Dict, Union

import numpy as _np

from . import _args, _octocd

InputError = _octocd.InputError

# The documented root attributes (docs/trace-format.md): what Trace.attrs holds when present.
_ROOT_ATTRIBUTES = (
    "format", "version", "scene_name", "scene", "parameters", "engine", "broadphase", "midphase", "build_id",
    "device", "start_time", "dt", "state_every", "flush_every", "body_count", "committed_frames",
    "committed_states", "stage_names", "gravity", "response_model", "detection", "mu", "restitution",
    "friction_combine", "restitution_combine", "contact_margin", "broadphase_exact", "contact_geometry",
    "collision_shape", "contact_model", "integrator", "gyroscopic", "substeps", "impulses", "speculative",
    "contacts_complete", "manifold_points", "depth_per", "velocity_at", "contact_margin_rule", "jt_direction",
    "velocity_clamp", "impulses_complete", "response_scheme", "deactivation", "impulse_points", "integrated_point",
    "friction_directions", "friction_per", "normal_reuse_deg")


class Trace:
    """Reads a trace (docs/trace-format.md): the per-frame slices that need the trace's
    layout (states by frame, CSR contacts by frame), the /frames columns, bodies and
    materials.

        with octocd.Trace("run.h5") as t:
            x, v = t.state(100)           # (n, 3) float32 each
            q, w = t.rotation(100)        # (n, 4) (w, x, y, z) and (n, 3) rad/s
            c = t.contacts(100)           # dict of arrays, as FrameRecord.contacts
            ms = t.frames["step_ms"]      # /frames columns as NumPy arrays

    Reads octocd's own traces (`octocd run --trace`: format version 1, or 2 with `--engine
    bullet --rotation`) and external traces of version 1 or 2 (another engine's; no
    /frames, contacts by position: step f's rows are /contacts/offsets[f-1] ..
    offsets[f]-1). Version 2 adds orientations, angular velocities, inertia, materials and
    manifold contacts with points (docs/trace-format.md, "External traces, version 2"); a
    trace without rotation reads as unrotated (identity orientations, zero angular
    velocities) and its inertia is derived (a solid box of the local AABB, Bullet's rule).

    A trace is untrusted input: it is opened and read by octocd's hardened reader, the one
    `octocd validate --trace-in`, `compare` and `replay` use (docs/trace-format.md,
    "Security rules and limits"): regular files only (a FIFO, a device or a folder is
    refused without being opened); external links, external storage and virtual datasets
    refused (they read other files); every dataset checked for its type and declared size
    before it is read; corrupt files refused rather than crashing or hanging. Rows past
    the root attributes committed_frames / committed_states (a write that failed) are
    never shown. Float data is returned as float32 (pairs as int64).

    `version` (1 or 2), `external` (no /frames) and `rotating` (/states/orientation) say
    what the file is. Raises InputError "PATH: DATASET: [frame F: ][body I: ]PROBLEM;
    allowed: ..." (the CLI's messages) for a file that is not such a trace or is refused,
    and for bad values where they are read.
    """

    _V2_DATASETS = ("states/orientation", "states/angular_velocity", "bodies/inertia", "bodies/friction",
                    "bodies/restitution", "contacts/point", "contacts/point_b", "contacts/jt3")

    def __init__(self, path: Union[str, "_os.PathLike[str]"]):
        self.path = _args.path("path", path)
        self._f = _octocd.TraceFile(self.path)
        try:
            self._check()
        except BaseException:
            self._f.close()
            raise

    def _fail(self, what: str, problem: str, allowed: str) -> None:
        raise InputError(f"{self.path}: {what}: {problem}; allowed: {allowed}")

    def _has(self, name: str) -> bool:
        return self._f.has("/" + name)

    def _shape(self, name: str):
        return tuple(self._f.shape("/" + name))

    def _rows(self, name: str, first: int, count: int, dtype: str = "f4") -> _np.ndarray:
        return self._f.rows("/" + name, int(first), int(count), dtype)

    def _all(self, name: str, dtype: str = "f4") -> _np.ndarray:
        return self._rows(name, 0, self._shape(name)[0], dtype)

    def _check(self) -> None:
        self.version = int(self._f.version)
        self.external = not self._has("frames/frame")
        if self.version == 1:
            for d in self._V2_DATASETS:
                if self._has(d):
                    self._fail("/" + d, "a version 2 dataset in a version 1 trace (v1/v2 fields mixed)",
                               "/states/orientation, /states/angular_velocity, /bodies/inertia, /bodies/friction, "
                               "/bodies/restitution, /contacts/point, /contacts/point_b, /contacts/jt3 only with "
                               "the root attribute version = 2")
        has_q = self._has("states/orientation")
        has_w = self._has("states/angular_velocity")
        if has_q != has_w:
            self._fail("/states/" + ("angular_velocity" if has_q else "orientation"),
                       f"missing (/states/{'orientation' if has_q else 'angular_velocity'} present)",
                       "/states/orientation and /states/angular_velocity together, or neither (no rotation)")
        n = self.body_count
        for name, tail in (("orientation", 4), ("angular_velocity", 3)):
            if self._has("states/" + name):
                shape = self._shape("states/" + name)
                if len(shape) != 3 or shape[1] != n or shape[2] != tail:
                    self._fail(f"/states/{name}", f"shape {' x '.join(map(str, shape))}",
                               f"states x {n} bodies x {tail}")
        if self._has("contacts/point_b"):  # each row's point on B: beside /contacts/point, one per row
            if not self._has("contacts/point"):
                self._fail("/contacts/point_b", "without /contacts/point",
                           "each row's point on B with /contacts/point (the row's point on A)")
            rows = self._shape("contacts/pair")[0] if self._has("contacts/pair") else 0
            shape = tuple(self._shape("contacts/point_b"))
            if shape != (rows, 3):
                self._fail("/contacts/point_b", f"shape {' x '.join(map(str, shape))}",
                           f"{rows} x 3, one world point (m) on B per contact row (as /contacts/pair)")

    def __enter__(self) -> "Trace":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Closes the file (reading afterwards raises InputError)."""
        self._f.close()

    @property
    def attrs(self) -> Dict[str, Any]:
        """The documented root attributes present (engine, scene, dt, state_every, ...;
        docs/trace-format.md): str, int, float, or a list for an array (gravity,
        stage_names)."""
        out = {}
        for k in _ROOT_ATTRIBUTES:
            v = self._f.attribute(k)
            if v is not None:
                out[k] = v
        return out

    @property
    def body_count(self) -> int:
        """Number of bodies n (rows of /bodies/inverse_mass)."""
        if not self._has("bodies/inverse_mass"):
            self._fail("/bodies/inverse_mass", "missing", "n values (1/kg, 0 = static), one per body")
        return int(self._shape("bodies/inverse_mass")[0])

    @property
    def rotating(self) -> bool:
        """Whether the trace holds orientations (/states/orientation, version 2)."""
        return self._has("states/orientation")

    @property
    def frames(self) -> Dict[str, _np.ndarray]:
        """/frames: one array per column present, cut to the complete rows (and at most
        committed_frames); {} for an external trace, which has no /frames. Counters and
        frame numbers as int64, times and figures as float64."""
        if self.external:
            return {}
        n = self._f.complete_rows("/frames")
        out = {}
        for k in _octocd.trace_frame_columns:
            if self._has("frames/" + k):
                out[k] = self._rows("frames/" + k, 0, n, "i8" if self._f.kind("/frames/" + k) == "integer" else "f8")
        return out

    def _state_rows(self) -> int:
        return int(self._f.complete_rows("/states"))

    @property
    def state_frames(self) -> _np.ndarray:
        """Frames that have a state row (0, k, 2k, ...; an external trace without
        /states/frame: 0, 1, ..., F), complete rows only."""
        if not self._has("states/position"):
            self._fail("/states", "absent", "a trace with states (positions and velocities)")
        s = self._state_rows()
        return self._rows("states/frame", 0, s, "i8") if self._has("states/frame") else _np.arange(s, dtype=_np.int64)

    def _state_row(self, frame: int) -> int:
        frame = _args.integer("frame", frame, 0, _args.INT64_MAX)
        frames = self.state_frames
        rows = _np.flatnonzero(frames == frame)
        if rows.size == 0:
            raise InputError(f"{self.path}: /states: no state for frame {frame}; allowed: frames "
                             f"{frames[:1].tolist()}..{frames[-1:].tolist()} "
                             f"every {self._f.attribute('state_every') or 1}")
        return int(rows[0])

    def state(self, frame: int):
        """(positions, velocities) at `frame`, each (n, 3) float32. Raises InputError when
        the trace holds no state for that frame (it keeps every state_every-th)."""
        r = self._state_row(frame)
        return self._rows("states/position", r, 1)[0], self._rows("states/velocity", r, 1)[0]

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
        q = self._rows("states/orientation", r, 1)[0]
        self._check_unit(q, frame)
        return q, self._rows("states/angular_velocity", r, 1)[0]

    @property
    def orientations(self) -> _np.ndarray:
        """(S, n, 4) float32: the orientation of every state row (state_frames), complete
        rows only; identity without rotation. Raises InputError naming frame and body of a
        non-unit quaternion."""
        frames = self.state_frames
        s, n = len(frames), self.body_count
        if not self.rotating:
            q = _np.zeros((s, n, 4), _np.float32)
            q[..., 0] = 1.0
            return q
        q = self._rows("states/orientation", 0, s)
        self._check_unit(q, frames)
        return q

    @property
    def angular_velocities(self) -> _np.ndarray:
        """(S, n, 3) float32 rad/s (world frame) of every state row; zeros without rotation."""
        s, n = len(self.state_frames), self.body_count
        if not self.rotating:
            return _np.zeros((s, n, 3), _np.float32)
        return self._rows("states/angular_velocity", 0, s)

    @property
    def inertia(self) -> _np.ndarray:
        """(n, 3, 3) float32 body-frame inertia tensors (kg m^2): /bodies/inertia, else
        derived as a solid box of the local AABB at the body's mass, m/12 diag(b^2 + c^2,
        a^2 + c^2, a^2 + b^2) (Bullet's rule; zeros for static bodies)."""
        n = self.body_count
        if self._has("bodies/inertia"):
            shape = self._shape("bodies/inertia")
            if shape != (n, 3, 3):
                self._fail("/bodies/inertia", f"shape {' x '.join(map(str, shape))}",
                           f"{n} x 3 x 3 (kg m^2, body frame, one per body)")
            return self._rows("bodies/inertia", 0, n)
        for k in ("local_aabb_min", "local_aabb_max"):
            if self._shape("bodies/" + k) != (n, 3):
                self._fail("/bodies/" + k, f"shape {' x '.join(map(str, self._shape('bodies/' + k)))}",
                           f"{n} x 3 (m, one per body)")
        lo = self._rows("bodies/local_aabb_min", 0, n, "f8")
        hi = self._rows("bodies/local_aabb_max", 0, n, "f8")
        w = self._rows("bodies/inverse_mass", 0, n, "f8")
        with _np.errstate(over="ignore", invalid="ignore", divide="ignore"):
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
        out = {k: self._f.attribute(k) for k in ("mu", "restitution", "friction_combine", "restitution_combine",
                                                 "contact_margin")}
        n = self.body_count
        for k in ("friction", "restitution"):
            d = "bodies/" + k
            if not self._has(d):
                out["body_" + k] = None
                continue
            if self._shape(d) != (n,):
                self._fail("/" + d, f"shape {' x '.join(map(str, self._shape(d)))}", f"{n} values, one per body")
            out["body_" + k] = self._rows(d, 0, n)
        return out

    def _contact_rows(self, frame: int):
        frame = _args.integer("frame", frame, 0, _args.INT64_MAX)
        if not self._has("contacts/offsets"):
            raise InputError(f"{self.path}: /contacts: absent; allowed: a trace written with --contacts")
        noff = self._shape("contacts/offsets")[0]
        if self._has("contacts/frame"):
            rows = self._f.complete_rows("/contacts")  # at most committed_frames
            fr = self._rows("contacts/frame", 0, rows, "i8")
            hit = _np.flatnonzero(fr == frame)
            if hit.size == 0:
                raise InputError(f"{self.path}: /contacts/frame: no row for frame {frame}")
            i = int(hit[0])
        else:  # an external trace: step f's rows are offsets[f-1] .. offsets[f]-1
            if not 1 <= frame <= noff - 1:
                raise InputError(f"{self.path}: /contacts/offsets: no row for frame {frame}; allowed: frames 1.."
                                 f"{noff - 1}")
            i = frame - 1
        a, b = (int(x) for x in self._rows("contacts/offsets", i, 2, "i8"))
        total = self._shape("contacts/pair")[0]
        if not 0 <= a <= b <= total:
            self._fail("/contacts/offsets", f"frame {frame}: rows {a}..{b - 1}",
                       f"0 <= offsets[f-1] <= offsets[f] <= {total} (the rows of /contacts/pair)")
        return a, b

    def contacts(self, frame: int) -> Dict[str, _np.ndarray]:
        """Frame `frame`'s /contacts rows: pair (C, 2) int64, normal (C, 3), depth, jn, jt
        (C,) float32 and, when the trace has /contacts/point (version 2), point (C, 3)
        (world, m); with /contacts/point_b (two witness points per row) point_b (C, 3), the
        point on B where the engine applied B's impulse (point is then A's); with
        /contacts/jt3 jt3 (C, 3), the friction impulse vectors on A. A version 2 trace may hold several rows per pair (a manifold,
        consecutive): see contacts_by_pair. Raises InputError when the trace has no
        contacts for it."""
        a, b = self._contact_rows(frame)
        out = {}
        for k in ("pair", "normal", "depth", "jn", "jt", "point", "point_b", "jt3"):
            if self._has("contacts/" + k):
                out[k] = self._rows("contacts/" + k, a, b - a, "i8" if k == "pair" else "f4")
        return out

    def contacts_by_pair(self, frame: int) -> Dict[Any, Dict[str, _np.ndarray]]:
        """Frame `frame`'s contacts grouped by pair: {(a, b): {"normal": (k, 3), "depth",
        "jn", "jt": (k,), "point", "point_b", "jt3": (k, 3) when present}}, a pair's k rows (its manifold) in
        the order written, pairs in (a, b) order."""
        rows = self.contacts(frame)
        out: Dict[Any, Dict[str, _np.ndarray]] = {}
        pairs = [tuple(int(x) for x in p) for p in rows["pair"]]
        for key in sorted(set(pairs)):
            sel = _np.array([p == key for p in pairs], dtype=bool)
            out[key] = {k: v[sel] for k, v in rows.items() if k != "pair"}
        return out
