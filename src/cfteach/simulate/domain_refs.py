"""Domains by reference: a built-in name, a TOML path or a random gridworld's parameters,
so worker processes can rebuild (and cache) the same Domain. Both the sweep and the
closed-loop simulation stand on this module.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

__all__ = ["domain_label", "load_domain", "parse_domain"]


def parse_domain(spec: str) -> str | tuple:
    """A domain reference: a built-in name, a TOML path, or a random gridworld written
    ``random:WxH:fF:nN:sS`` (e.g. ``random:10x10:f5:n64:s0``)."""
    if not spec.startswith("random:"):
        return spec
    parts = spec.split(":")[1:]
    try:
        if len(parts) != 4:
            raise ValueError
        w, h = (int(x) for x in parts[0].lower().split("x"))
        keys = {p[0]: int(p[1:]) for p in parts[1:]}
        return ("random", w, h, keys["f"], keys["n"], keys["s"])
    except (ValueError, KeyError):
        raise ValueError(f"bad random domain {spec!r}: write random:WxH:fF:nN:sS, e.g. "
                         "random:10x10:f5:n64:s0") from None


def domain_label(ref: str | tuple) -> str:
    """Short name used in tables and file names."""
    if isinstance(ref, tuple):
        _, w, h, f, n, s = ref
        return f"random-{w}x{h}-f{f}-n{n}-s{s}"
    return Path(ref).stem if ref.endswith(".toml") else ref


@cache
def load_domain(ref: str | tuple):
    """The Domain behind a reference (cached per process)."""
    from cfteach import domains

    if isinstance(ref, tuple):
        from cfteach.domains.random import random_gridworld

        _, w, h, f, n, s = ref
        return random_gridworld(w, h, f, n, s)
    return domains.load(ref)
