"""octocd.load_scene: scenes from a file, a dict or an octocd.Scene (docs/scenes.md)."""
from __future__ import annotations

import json as _json
import os as _os
from typing import Any, Dict, Optional, Union

from . import _octocd

InputError = _octocd.InputError
Scene = _octocd.Scene


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
