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

from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

from cfteach.domains.model import Domain, Instance, State
from cfteach.domains.spec import ACTIONS, DomainFileError, load_toml, parse_spec

__all__ = ["ACTIONS", "Domain", "DomainFileError", "Instance", "State", "builtin_names",
           "builtin_path", "from_dict", "load"]


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


def load(path_or_name: str | Path) -> Domain:
    """Load a built-in domain by name (cached, so planning caches are shared) or a TOML file."""
    if isinstance(path_or_name, str) and path_or_name in builtin_names():
        return _load_builtin(path_or_name)
    path = Path(path_or_name)
    if not path.exists():
        raise ValueError(f"{str(path_or_name)!r} is neither a built-in domain "
                         f"({', '.join(builtin_names())}) nor an existing file")
    return Domain.from_spec(parse_spec(load_toml(path), source=str(path)))


def from_dict(data: dict[str, Any], source: str = "<dict>") -> Domain:
    """Build a domain from a dict with the TOML file's structure (same validation)."""
    return Domain.from_spec(parse_spec(data, source=source))


# Imported last: the generator builds its domains through `from_dict` above.
from cfteach.domains.random import random_gridworld, random_gridworld_dict  # noqa: E402

__all__ += ["random_gridworld", "random_gridworld_dict"]
