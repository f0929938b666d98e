"""Static layout of an instance for the page's SVG renderer.

Format: `width`, `height`, `walls` ([x, y] list), `regions` (named cell sets with a drawing
style), `markers` (single cells: goal, destination), `consumables` (objects shown while the
state's boolean of the same key is true) and `cargo` (the movable object's state key).
Everything is read from the domain file through `Instance` (cells, walls, spec).
"""

from __future__ import annotations

from typing import Any

#: Drawing style of named cell sets and objects (study-platform.md §1.5); others fall back
#: to the set's own name, which the page draws as a light fill.
STYLES = {
    ("delivery", "mud"): "mud", ("delivery", "station"): "station",
    ("delivery", "passenger"): "package", ("tiles", "A"): "tile_a", ("tiles", "B"): "tile_b",
    ("skateboard", "path"): "path", ("skateboard", "skateboard"): "skateboard",
}
GENERIC = {"mud": "mud", "path": "path", "station": "station", "passenger": "package",
           "package": "package", "skateboard": "skateboard", "battery": "station"}


def _style(domain: str, name: str) -> str:
    return STYLES.get((domain, name)) or GENERIC.get(name.lower(), name)


def instance_layout(domain_name: str, instance: Any) -> dict:
    """Layout of `instance` for the page."""
    if hasattr(instance, "study_layout"):
        return instance.study_layout()
    dom = instance.domain
    spec = dom.spec
    names = getattr(instance, "cell_set_names", None) or tuple(n for n, _ in spec.cells)
    regions = [{"name": n, "style": _style(domain_name, n),
                "cells": sorted([int(x), int(y)] for x, y in instance.cells(n))}
               for n in names]
    markers = []
    if spec.goal is not None:
        kind = "destination" if spec.goal_kind == "cargo_delivered_at" else "goal"
        markers.append({"name": kind, "style": kind, "cell": [int(c) for c in spec.goal]})
    present = getattr(instance, "consumables_present", (True,) * len(spec.consumables))
    consumables = [{"key": n, "style": _style(domain_name, n), "cell": [int(c) for c in cell]}
                   for (n, cell), p in zip(spec.consumables, present, strict=True) if p]
    cargo = None
    if spec.cargo is not None and getattr(instance, "cargo_present", True):
        cargo = {"key": spec.cargo.name, "style": _style(domain_name, spec.cargo.name)}
    return {"width": int(dom.width), "height": int(dom.height),
            "walls": sorted([int(x), int(y)] for x, y in instance.walls),
            "regions": regions, "markers": markers, "consumables": consumables, "cargo": cargo}
