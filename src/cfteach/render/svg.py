"""Write a scene as a standalone SVG document (no dependencies; one element per primitive).

Every element carries `data-role` and, where it belongs to a grid cell, `data-cell="x,y"`
(1-based, y up) so a picture can be inspected by tools and tests.
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

from cfteach.render.scene import Scene
from cfteach.render.shapes import Circle, Polygon, Rect, Shape, scene_shapes


def _num(v: float) -> str:
    return f"{v:.2f}".rstrip("0").rstrip(".")


def _attrs(shape: Shape) -> str:
    out = f" data-role={quoteattr(shape.role)}"
    if shape.cell is not None:
        out += f' data-cell="{shape.cell[0]},{shape.cell[1]}"'
    return out


def _element(shape: Shape) -> str:
    if isinstance(shape, Rect):
        fill = shape.fill or "none"
        stroke = (
            f' stroke="{shape.stroke}" stroke-width="{_num(shape.stroke_width)}"'
            if shape.stroke
            else ""
        )
        return (
            f'<rect x="{_num(shape.x)}" y="{_num(shape.y)}" width="{_num(shape.w)}" '
            f'height="{_num(shape.h)}" fill="{fill}"{stroke}{_attrs(shape)}/>'
        )
    if isinstance(shape, Circle):
        fill = shape.fill or "none"
        stroke = (
            f' stroke="{shape.stroke}" stroke-width="{_num(shape.stroke_width)}"'
            if shape.stroke
            else ""
        )
        return (
            f'<circle cx="{_num(shape.cx)}" cy="{_num(shape.cy)}" r="{_num(shape.r)}" '
            f'fill="{fill}"{stroke}{_attrs(shape)}/>'
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
        from xml.sax.saxutils import escape

        body.append(f"<title>{escape(title)}</title>")
    body.extend(_element(s) for s in shapes)
    body.append("</svg>")
    return "\n".join(body)
