"""octocd.view: the page of `octocd view` (design.md section 16; docs/debugging.md) from Python."""
from __future__ import annotations

import os as _os
from typing import Any, Dict, Optional, Sequence, Union

from . import _args, _octocd

InputError = _octocd.InputError


def view(trace: Union[str, "_os.PathLike[str]"], *, frame: int = 1, pair: Optional[Sequence[int]] = None,
         body: Optional[int] = None, window: int = 5, out_dir: Union[str, "_os.PathLike[str]"] = ".") -> Dict[str, Any]:
    """Writes the page `octocd view TRACE --frame F [--pair A,B | --body I] --window K -o
    OUT_DIR` writes (design.md section 16; docs/debugging.md): one self-contained HTML file drawing the
    frame's posed shapes near the pair or body, their AABBs, the engine's contacts and the
    physics tier's reference (SAT or FCL), with a frame slider over frame +- window. The
    trace (octocd's with every state, or an external trace v1/v2) is read through the
    hardened reader. Returns {"path", "bytes", "bodies", "frames", "frame", "note"}; note
    says e.g. that the pair has no contact row in the frame (it is drawn anyway). Raises
    InputError naming the argument (frame outside the trace, a body that does not exist,
    both pair and body) or the trace's file and dataset when the reader refuses it."""
    p = None
    if pair is not None:
        if len(pair) != 2:
            raise InputError(f"pair: {pair!r}; allowed: two body indices (a, b)")
        p = (_args.integer("pair[0]", pair[0], 0, 2**32 - 1), _args.integer("pair[1]", pair[1], 0, 2**32 - 1))
    if p is not None and body is not None:
        raise InputError("pair and body: both given; allowed: one item (a pair or a body), or neither")
    return _octocd.view(_args.path("trace", trace), _args.integer("frame", frame, 1, _args.INT64_MAX), p,
                        None if body is None else _args.integer("body", body, 0, 2**32 - 1),
                        _args.integer("window", window, 0, 2**31 - 1), _args.path("out_dir", out_dir))
