"""Static layout of an instance for the page's SVG renderer.

Format: `width`, `height`, `walls` ([x, y] list), `regions` (named cell sets with a drawing
style), `markers` (single cells: goal, destination), `consumables` (objects shown while the
state's boolean of the same key is true) and `cargo` (the movable object's state key).
"""

from __future__ import annotations

from typing import Any


def instance_layout(domain_name: str, instance: Any) -> dict:
    """Layout of `instance`, read from the domain file through the `Instance` contract."""
    if hasattr(instance, "study_layout"):
        return instance.study_layout()
    return _domain_layout(domain_name, instance)


def _cells(instance: Any, name: str) -> list[list[int]]:
    try:
        return sorted([int(x), int(y)] for x, y in instance.cells(name))
    except (KeyError, ValueError, AttributeError):
        return []


def _domain_layout(domain_name: str, instance: Any) -> dict:
    dom = instance.domain
    walls = sorted([int(x), int(y)] for x, y in getattr(instance, "walls", ()))
    return {"width": int(dom.width), "height": int(dom.height), "walls": walls,
            "regions": [], "markers": [], "consumables": [], "cargo": None}
