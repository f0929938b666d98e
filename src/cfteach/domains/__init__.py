"""Domains: families of gridworld MDP instances described by declarative TOML files.

The three study domains (`delivery`, `tiles`, `skateboard`) ship as data files in
`cfteach/domains/data/`; a user domain file loads the same way::

    from cfteach.domains import load
    dom = load("delivery")            # or load("path/to/my_domain.toml")
    inst = dom.instances()[0]
    inst.states()[:2]

File format: docs/domains.md.
"""

from __future__ import annotations

import re
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

from cfteach.domains.model import Domain, Instance, State
from cfteach.domains.random import (
    parse_random_spec,
    random_gridworld,
    random_gridworld_dict,
)
from cfteach.domains.selection import parse_envs, subset
from cfteach.domains.spec import (
    ACTION_EFFECTS,
    ACTIONS,
    BUILTIN_ACTIONS,
    ActionSpec,
    DomainFileError,
    load_toml,
    parse_spec,
)

__all__ = ["ACTIONS", "ACTION_EFFECTS", "BUILTIN_ACTIONS", "ActionSpec", "Domain",
           "DomainFileError", "Instance", "State",
           "builtin_names", "builtin_path", "from_dict", "load",
           "parse_envs", "random_gridworld", "random_gridworld_dict", "subset"]


def builtin_names() -> list[str]:
    """Names of the domains shipped with cfteach, in the study's order."""
    order = ["delivery", "tiles", "skateboard"]
    found = sorted(p.name[:-5] for p in resources.files(__package__).joinpath("data").iterdir()
                   if p.name.endswith(".toml"))
    return [n for n in order if n in found] + [n for n in found if n not in order]


def builtin_path(name: str) -> Path:
    """Path of a built-in domain's TOML file."""
    if name not in builtin_names():
        raise ValueError(f"unknown built-in domain {name!r} (known: {', '.join(builtin_names())})")
    return Path(str(resources.files(__package__).joinpath("data", f"{name}.toml")))


@cache
def _load_builtin(name: str) -> Domain:
    path = builtin_path(name)
    return Domain.from_spec(parse_spec(load_toml(path), source=str(path)))


@cache
def _load_random(spec: str) -> Domain:
    try:
        return random_gridworld(*parse_random_spec(spec))
    except TypeError as exc:  # the generator's own argument checks
        raise ValueError(str(exc)) from None


def _did_you_mean(text: str) -> str:
    import difflib

    close = difflib.get_close_matches(text, builtin_names(), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def load(path_or_name: str | Path) -> Domain:
    """Load a built-in domain by name (cached, so planning caches are shared), a TOML file,
    or a random domain written ``random:WxH:fF:nN:sS`` or by its name
    ``random-WxH-fF-nN-sS`` (as its JSON files carry it; cached too)."""
    if isinstance(path_or_name, str) and path_or_name in builtin_names():
        return _load_builtin(path_or_name)
    if isinstance(path_or_name, str) and path_or_name.startswith("random:"):
        return _load_random(path_or_name)
    path = Path(path_or_name)
    named = re.fullmatch(r"random-(\d+)x(\d+)-f(\d+)-n(\d+)-s(\d+)", str(path_or_name))
    if named and not path.exists():  # the name a random domain's JSON files carry
        return _load_random("random:{}x{}:f{}:n{}:s{}".format(*named.groups()))
    if path.is_dir():
        raise ValueError(f"{str(path_or_name)!r} is a directory, not a domain file")
    if not path.exists():
        raise ValueError(f"{str(path_or_name)!r} is neither a built-in domain "
                         f"({', '.join(builtin_names())}), a random domain "
                         f"(random:WxH:fF:nN:sS) nor an existing file"
                         + _did_you_mean(str(path_or_name)))
    return Domain.from_spec(parse_spec(load_toml(path), source=str(path)))


def from_dict(data: dict[str, Any], source: str = "<dict>") -> Domain:
    """Build a domain from a dict with the TOML file's structure (same validation)."""
    return Domain.from_spec(parse_spec(data, source=source))

