"""Work on some environments (instances) of a domain: `subset(domain, envs)`.

The result is a `Domain` whose `instances()` are the chosen ones, in ascending order of
their index, so teaching, test selection and exports run on it unchanged. Each instance
keeps its own `index` and `env_code` (those of the full domain), so curricula and test sets
made on a subset name the original environments, never a renumbered one; `instance(env)`
still finds any instance of the family by original index or env code.

`parse_envs(text, domain)` reads the command line's ``--envs`` (see docs/domains.md):
comma-separated items, each an index (``5``), an env code of exactly ``n_bits`` 0/1 digits
(``000101``), or a Python-style slice of indices ``start:stop:step`` (``0::16`` is every
16th environment, ``:8`` the first eight).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, fields
from functools import cached_property

from cfteach.domains.model import Domain, Instance

__all__ = ["EnvSelectionError", "SubsetDomain", "parse_envs", "subset"]


class EnvSelectionError(ValueError):
    """An environment selection names no environment, an unknown one, or one twice."""


@dataclass(frozen=True, eq=False)
class SubsetDomain(Domain):
    """A domain restricted to some of its instances (`env_indices`, original indices)."""

    parent: Domain
    env_indices: tuple[int, ...]

    @cached_property
    def _instances(self) -> tuple[Instance, ...]:
        every = self.parent.instances()
        return tuple(every[i] for i in self.env_indices)

    def instance(self, env: int | tuple[int, ...] | list[int]) -> Instance:
        """Any instance of the family, by original index or env code (not only the chosen
        ones: a curriculum made on the full domain still names its environments)."""
        return self.parent.instance(env)


def subset(domain: Domain, envs: Iterable[int | str | tuple[int, ...] | list[int]]
           | str) -> Domain:
    """`domain` restricted to `envs`: a ``--envs`` string, or indices and env codes (bit
    strings, tuples or lists). All of them, in any order, gives a domain that teaches exactly
    like `domain`. EnvSelectionError (one line) for an empty selection, an unknown
    environment or one given twice."""
    chosen = parse_envs(envs, domain) if isinstance(envs, str) else _resolve(envs, domain)
    parent = domain.parent if isinstance(domain, SubsetDomain) else domain
    if isinstance(domain, SubsetDomain):
        if tuple(chosen) == domain.env_indices:
            return domain  # the same selection: keep the object (and its compiled arrays)
        outside = sorted(set(chosen) - set(domain.env_indices))
        if outside:
            raise EnvSelectionError(f"{domain.name}: environment {outside[0]} is not in the "
                                    "subset this domain was restricted to")
    base = {f.name: getattr(parent, f.name) for f in fields(Domain)}
    return SubsetDomain(**base, parent=parent, env_indices=tuple(chosen))


def _family_size(domain: Domain) -> int:
    """How many environments the whole family has (a subset's parent counts them all)."""
    return len(domain.parent.instances() if isinstance(domain, SubsetDomain)
               else domain.instances())


def _index_of(item: int | str | tuple[int, ...] | list[int], domain: Domain,
              shown: str) -> int:
    n = _family_size(domain)
    bits = domain.n_bits
    if isinstance(item, bool):
        raise EnvSelectionError(f"environment {shown}: not an index or env code")
    if isinstance(item, int):
        if not 0 <= item < n:
            raise EnvSelectionError(f"{domain.name}: environment index {item} is out of range "
                                    f"0..{n - 1}")
        return item
    code = item if isinstance(item, str) else "".join(str(b) for b in item)
    if re.fullmatch(r"[01]+", code) and len(code) == bits:
        return int(code, 2)
    if isinstance(item, str) and re.fullmatch(r"\d+", item):
        if int(item) < n or not re.fullmatch(r"[01]+", item):
            return _index_of(int(item), domain, shown)
        raise EnvSelectionError(f"{domain.name}: environment {shown!r} has {len(item)} bits "
                                f"but env codes have {bits} (and as an index it is past "
                                f"{n - 1})")
    raise EnvSelectionError(f"{domain.name}: environment {shown!r} is neither an index in "
                            f"0..{n - 1} nor an env code of {bits} bits (0/1)")


def _resolve(items: Iterable[int | str | tuple[int, ...] | list[int]],
             domain: Domain) -> list[int]:
    seen: dict[int, str] = {}
    for item in items:
        shown = item if isinstance(item, str) else str(item)
        i = _index_of(item, domain, shown)
        if i in seen:
            raise EnvSelectionError(f"{domain.name}: environment {i} is given twice "
                                    f"(as {seen[i]!r} and {shown!r})")
        seen[i] = shown
    if not seen:
        raise EnvSelectionError(f"{domain.name}: the selection names no environment")
    return sorted(seen)


_SLICE = re.compile(r"(\d*):(\d*)(?::(\d*))?")


def parse_envs(text: str, domain: Domain) -> list[int]:
    """The sorted original indices a ``--envs`` string selects (see the module doc)."""
    n = _family_size(domain)
    if not text.strip():
        raise EnvSelectionError("the selection is empty: give indices, env codes or a slice "
                                "such as 0::16")
    items: list[int | str] = []
    for raw in text.split(","):
        tok = raw.strip()
        if not tok:
            raise EnvSelectionError(f"{text!r} has an empty item (two commas, or a comma "
                                    "at an end)")
        m = _SLICE.fullmatch(tok)
        if m:
            start, stop, step = (int(g) if g else None for g in m.groups())
            if step == 0:
                raise EnvSelectionError(f"slice {tok!r}: the step must be at least 1")
            for bound in (start, stop):
                if bound is not None and bound > n:
                    raise EnvSelectionError(f"{domain.name}: slice {tok!r}: {bound} is past "
                                            f"the last environment {n - 1}")
            picked = list(range(n))[start:stop:step]
            if not picked:
                raise EnvSelectionError(f"slice {tok!r} selects no environment")
            items.extend(picked)
        else:
            items.append(tok)
    return _resolve(items, domain)
