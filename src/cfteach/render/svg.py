"""Write a scene as a standalone SVG document (no dependencies; one element per primitive).

Every element carries `data-role` and, where it belongs to a grid cell, `data-cell="x,y"`
(1-based, y up) so a picture can be inspected by tools and tests.
"""

from __future__ import annotations

from typing import Any
from xml.sax.saxutils import escape, quoteattr

from cfteach.render.scene import Layout, Scene, SceneObject
from cfteach.render.shapes import Circle, Polygon, Rect, Shape, Text, scene_shapes


def _num(v: float) -> str:
    return f"{v:.2f}".rstrip("0").rstrip(".")


def _attrs(shape: Shape) -> str:
    out = f" data-role={quoteattr(shape.role)}"
    if shape.cell is not None:
        out += f' data-cell="{shape.cell[0]},{shape.cell[1]}"'
    return out


def _stroke(shape: Rect | Circle) -> str:
    """The optional outline of a rectangle or circle (none without a stroke colour)."""
    if not shape.stroke:
        return ""
    return f' stroke="{shape.stroke}" stroke-width="{_num(shape.stroke_width)}"'


def _element(shape: Shape) -> str:
    if isinstance(shape, Rect):
        fill, stroke = shape.fill or "none", _stroke(shape)
        return (
            f'<rect x="{_num(shape.x)}" y="{_num(shape.y)}" width="{_num(shape.w)}" '
            f'height="{_num(shape.h)}" fill="{fill}"{stroke}{_attrs(shape)}/>'
        )
    if isinstance(shape, Circle):
        fill, stroke = shape.fill or "none", _stroke(shape)
        return (
            f'<circle cx="{_num(shape.cx)}" cy="{_num(shape.cy)}" r="{_num(shape.r)}" '
            f'fill="{fill}"{stroke}{_attrs(shape)}/>'
        )
    if isinstance(shape, Text):
        return (
            f'<text x="{_num(shape.x)}" y="{_num(shape.y + shape.size)}" '
            f'font-size="{_num(shape.size)}" font-family="sans-serif" '
            f'fill="{shape.fill}"{_attrs(shape)}>{escape(shape.text)}</text>'
        )
    if isinstance(shape, Polygon):
        pts = " ".join(f"{_num(x)},{_num(y)}" for x, y in shape.points)
        return f'<polygon points="{pts}" fill="{shape.fill or "none"}"{_attrs(shape)}/>'
    pts = " ".join(f"{_num(x)},{_num(y)}" for x, y in shape.points)
    return (
        f'<polyline points="{pts}" fill="none" stroke="{shape.stroke}" '
        f'stroke-width="{_num(shape.width)}" stroke-linecap="round"{_attrs(shape)}/>'
    )


def to_svg(scene: Scene, cell_px: int = 48, *, title: str | None = None) -> str:
    """The scene as an SVG document string."""
    cv, shapes = scene_shapes(scene, cell_px)
    w, h = cv.size
    head = (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" '
        f'viewBox="0 0 {w} {h}" shape-rendering="crispEdges">'
    )
    body = [head]
    if title:
        body.append(f"<title>{escape(title)}</title>")
    body.extend(_element(s) for s in shapes)
    body.append("</svg>")
    return "\n".join(body)


def legend_icons(layout: Layout, px: int = 22) -> list[tuple[str, str]]:
    """(label, small inline SVG) for every kind of thing a layout's pictures can show, drawn
    exactly as in the pictures: a key for reports."""
    from cfteach.render import style as st

    names = [n for n, _ in layout.cell_sets]
    items: list[tuple[str, str, Scene]] = []

    def lay(**kw: Any) -> Layout:  # any Layout fields, each of its own type
        base: dict[str, Any] = {"width": 2, "height": 1,
                                "cell_sets": tuple((n, frozenset()) for n in names)}
        base.update(kw)
        return Layout(**base)

    items.append(("robot", "agent", Scene(lay(), (1, 1))))
    trail = Scene(lay(), (2, 1), trail=((2, 1), (1, 1)))
    items.append(("path walked", "trail", trail))
    if layout.walls:
        items.append(("wall", "wall", Scene(lay(walls=frozenset({(1, 1)})), (2, 1))))
    for pos, name in enumerate(names):
        sets = tuple(
            (n, frozenset({(1, 1)}) if i == pos else frozenset()) for i, n in enumerate(names)
        )
        label = st.cell_style(name, pos).label
        items.append(
            (
                label if label == name else f"{label} ({name})",
                f"cell:{name}",
                Scene(lay(cell_sets=sets), (2, 1)),
            )
        )
    if layout.goal is not None:
        kind = "destination" if layout.goal_is_destination else "goal"
        scene = Scene(
            lay(goal=(1, 1), goal_is_destination=layout.goal_is_destination, cargo=layout.cargo),
            (2, 1),
        )
        items.append((kind, "goal", scene))
    if layout.cargo is not None:
        ost = st.object_style(layout.cargo, "cargo")
        obj = SceneObject(layout.cargo, "cargo", (1, 1))
        label = ost.label if ost.label == layout.cargo else f"{ost.label} ({layout.cargo})"
        items.append((label, f"object:{layout.cargo}", Scene(lay(), (2, 1), (obj,))))
    for pos, (name, _) in enumerate(layout.consumables):
        ost = st.object_style(name, "consumable", pos)
        others = tuple(SceneObject(n, "consumable", None) for n, _ in layout.consumables[:pos])
        obj = SceneObject(name, "consumable", (1, 1))
        label = ost.label if ost.label == name else f"{ost.label} ({name})"
        items.append((label, f"object:{name}", Scene(lay(), (2, 1), (*others, obj))))

    out = []
    for label, role, scene in items:
        _, shapes = scene_shapes(scene, px)
        keep = [
            s for s in shapes if s.role == role or (role == "trail" and s.role.startswith("trail"))
        ]
        body = "".join(_element(s) for s in keep)
        svg = (
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{px}" height="{px}" '
            f'viewBox="0 0 {px} {px}" data-key={quoteattr(role)}>'
            f'<rect x="0.5" y="0.5" width="{px - 1}" height="{px - 1}" fill="#ffffff" '
            f'stroke="#000000" stroke-width="1"/>{body}</svg>'
        )
        out.append((label, svg))
    return out
