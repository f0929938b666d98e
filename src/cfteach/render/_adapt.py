"""Read the static picture of a `cfteach.domains.Instance`.

Kept in one place because it reads a few things beyond the architecture contract (the goal,
the cargo's name, the consumables' cells), which the domain keeps in its parsed file spec.
"""

from __future__ import annotations

from typing import Any

from cfteach.render.scene import Layout


def layout_from_instance(instance: Any) -> Layout:
    """The static picture of one instance: walls, named cell sets, goal and object homes."""
    domain = instance.domain
    spec = getattr(domain, "spec", None)
    if spec is None:
        raise TypeError(f"{instance!r} does not look like a cfteach.domains.Instance")
    names = getattr(instance, "cell_set_names", None) or tuple(n for n, _ in spec.cells)
    cell_sets = tuple((name, frozenset(instance.cells(name))) for name in names)
    consumables = tuple(
        (name, tuple(cell))
        for (name, cell), present in zip(
            spec.consumables,
            getattr(instance, "consumables_present", (True,) * len(spec.consumables)),
            strict=True,
        )
        if present
    )
    return Layout(
        width=int(domain.width),
        height=int(domain.height),
        walls=frozenset(tuple(c) for c in instance.walls),
        cell_sets=cell_sets,
        goal=tuple(spec.goal) if spec.goal is not None else None,
        goal_is_destination=spec.goal_kind == "cargo_delivered_at",
        cargo=spec.cargo.name if spec.cargo is not None else None,
        consumables=consumables,
        title=f"{domain.name} {''.join(str(b) for b in instance.env_code)}",
    )
