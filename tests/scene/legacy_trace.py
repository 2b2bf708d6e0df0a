"""Rewrites a version 2 trace as an engine following an earlier docs/trace-format.md wrote
it: the friction as the scalar `jt` only (no `/contacts/jt3`), no declarations (root
attributes `contact_model`, `gyroscopic`, `integrator`, `deactivation`, `collision_shape`,
`contact_geometry`, `broadphase_exact`, `contact_margin_rule`, `jt_direction`,
`velocity_clamp`, `impulses_complete`, `response_scheme`, `friction_directions`; datasets
`/bodies/collision_shape`, `/bodies/locked_dofs`, `/states/sleeping`), one point per row (a
row's two witness points `/contacts/point`, `/contacts/point_b` become their midpoint in
`/contacts/point`, as the earlier writer of Bullet's traces wrote it).

    /usr/bin/python3 tests/scene/legacy_trace.py CLEAN.h5 LEGACY.h5 [--drop /pairs ...]

`--drop GROUP` also removes a group (`/pairs`, `/contacts`, ...): a trace that never had it.
Used by tests/scene/test_trace_meaning.py (ctest label `corpus`).
"""
import shutil
import sys

import h5py

DECLARATIONS = ["contact_model", "gyroscopic", "integrator", "deactivation", "collision_shape", "contact_geometry",
                "broadphase_exact", "contact_margin_rule", "jt_direction", "velocity_clamp", "impulses_complete",
                "response_scheme", "friction_directions"]
DECLARED_DATASETS = ["/bodies/collision_shape", "/bodies/locked_dofs", "/states/sleeping", "/contacts/jt3"]


def make_legacy(clean, out, drop=()):
    """Copies `clean` to `out` as an earlier writer's version 2 trace; returns `out`."""
    shutil.copyfile(clean, out)
    with h5py.File(out, "r+") as f:
        assert int(f.attrs["version"]) == 2, "a version 2 trace"
        for name in DECLARATIONS:
            if name in f.attrs:
                del f.attrs[name]
        if "/contacts/point_b" in f:
            f["/contacts/point"][...] = 0.5 * (f["/contacts/point"][...] + f["/contacts/point_b"][...])
            del f["/contacts/point_b"]
        for name in DECLARED_DATASETS + list(drop):
            if name in f:
                del f[name]
    return out


if __name__ == "__main__":
    args = sys.argv[1:]
    if len(args) < 2:
        sys.exit(__doc__)
    extra = [args[i + 1] for i in range(2, len(args) - 1) if args[i] == "--drop"]
    make_legacy(args[0], args[1], extra)
