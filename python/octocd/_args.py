"""Checks of the package's scalar arguments and paths (docs/python.md, "Untrusted input"):
what the compiled module cannot take is an InputError naming the argument and what is
allowed, never pybind11's "incompatible function arguments", a bare ValueError or a silent
truncation (step(2.7) is refused, not two steps)."""
from __future__ import annotations

import numbers as _numbers
import os as _os

from . import _octocd

InputError = _octocd.InputError

INT64_MAX = 2**63 - 1


def integer(name, value, lo, hi):
    """`value` as an int within [lo, hi]: an integer (int, a NumPy integer; not a bool, a
    float, a string); else InputError "NAME: VALUE is not an integer; allowed: an integer in
    [LO, HI]" or "NAME: VALUE is out of range; allowed: ..."."""
    allowed = f"an integer in [{lo}, {hi}]"
    if isinstance(value, bool) or not isinstance(value, _numbers.Integral):
        shown = repr(value)
        shown = shown if len(shown) <= 80 else shown[:80] + "..."
        raise InputError(f"{name}: {shown} ({type(value).__name__}) is not an integer; allowed: {allowed}")
    v = int(value)
    if not lo <= v <= hi:
        raise InputError(f"{name}: {v} is out of range; allowed: {allowed}")
    return v


def path(name, value):
    """`value` (str, bytes or os.PathLike) as a str path the module can take: UTF-8 only; a
    path of other bytes is InputError naming the argument."""
    try:
        p = _os.fspath(value)
    except TypeError:
        raise InputError(f"{name}: {type(value).__name__}; allowed: a path (str or os.PathLike)") from None
    if isinstance(p, bytes):
        try:
            return p.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(f"{name}: {p!r} is not UTF-8; allowed: a path of UTF-8 characters") from None
    try:
        p.encode("utf-8")
    except UnicodeEncodeError:
        raise InputError(f"{name}: {p.encode('utf-8', 'surrogateescape')!r} is not UTF-8; allowed: a path of UTF-8 "
                         "characters") from None
    return p


def read_json_input(name, value, allowed):
    """The text of the JSON file `value` read as the CLI reads --expect and --merge files
    (octocd/atomic_file.hpp, read_input_file): a FIFO, a device or a folder is InputError at
    once (never a block, /dev/zero never read), at most 64 MiB, UTF-8."""
    p = path(name, value)
    data = _octocd.read_input_file(p, name, allowed)
    try:
        return p, data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{name}: {p}: byte {e.start} is not UTF-8; allowed: {allowed}") from None
