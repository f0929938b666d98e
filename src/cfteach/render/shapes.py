"""Turn a `Scene` into a flat list of drawing primitives in pixel coordinates.

One list feeds both the SVG writer and the raster (Pillow) painter, so the two always agree.
Each primitive carries a `role` (e.g. `agent`, `cell:mud`, `object:passenger`, `trail`) and
the grid cell it belongs to, which the SVG writer exports as attributes; tests and other
tools can find things in a picture without looking at pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cfteach.render import style as st
from cfteach.render.scene import Cell, Scene, SceneObject


@dataclass(frozen=True)
class Rect:
    x: float
    y: float
    w: float
    h: float
    fill: str | None
    role: str
    cell: Cell | None = None
    stroke: str | None = None
    stroke_width: float = 0.0


@dataclass(frozen=True)
class Circle:
    cx: float
    cy: float
    r: float
    fill: str | None
    role: str
    cell: Cell | None = None
    stroke: str | None = None
    stroke_width: float = 0.0


@dataclass(frozen=True)
class Polygon:
    points: tuple[tuple[float, float], ...]
    fill: str | None
    role: str
    cell: Cell | None = None


@dataclass(frozen=True)
class Line:
    points: tuple[tuple[float, float], ...]
    stroke: str
    width: float
    role: str
    cell: Cell | None = None


@dataclass(frozen=True)
class Text:
    x: float  # top-left corner of the text's box
    y: float
    text: str
    fill: str
    size: float
    role: str
    cell: Cell | None = None


Shape = Rect | Circle | Polygon | Line | Text


@dataclass(frozen=True)
class Canvas:
    """Pixel geometry of a grid: `cell_px` per cell, y flipped so row `height` is on top."""

    width: int
    height: int
    cell_px: int

    @property
    def size(self) -> tuple[int, int]:
        return (self.width * self.cell_px + 1, self.height * self.cell_px + 1)

    def origin(self, cell: Cell) -> tuple[float, float]:
        """Top-left pixel of a cell."""
        x, y = cell
        return ((x - 1) * self.cell_px, (self.height - y) * self.cell_px)

    def at(self, cell: Cell, fx: float, fy: float) -> tuple[float, float]:
        """Pixel at fraction (fx, fy) of a cell, measured from its top-left corner."""
        ox, oy = self.origin(cell)
        return (ox + fx * self.cell_px, oy + fy * self.cell_px)


def _hexagon(cx: float, cy: float, r: float) -> tuple[tuple[float, float], ...]:
    return tuple(
        (cx + r * math.cos(math.pi / 3 * k), cy + r * math.sin(math.pi / 3 * k)) for k in range(6)
    )


def _object_shapes(
    cv: Canvas, obj: SceneObject, ost: st.ObjectStyle, corner: str | None
) -> list[Shape]:
    """An object in its cell; `corner` ('tr' or 'bl') draws it half-size beside the agent."""
    assert obj.cell is not None
    c = cv.cell_px
    scale = 0.5 if corner else 1.0
    fx, fy = {"tr": (0.8, 0.2), "bl": (0.2, 0.8), None: (0.5, 0.5)}[corner]
    cx, cy = cv.at(obj.cell, fx, fy)
    role = f"object:{obj.name}"
    if ost.shape == "circle":
        return [Circle(cx, cy, 0.25 * c * scale, ost.color, role, obj.cell)]
    if ost.shape == "hexagon":
        return [Polygon(_hexagon(cx, cy, 0.3 * c * scale), ost.color, role, obj.cell)]
    if ost.shape == "diamond":
        r = 0.28 * c * scale
        pts = ((cx, cy - r), (cx + r, cy), (cx, cy + r), (cx - r, cy))
        return [Polygon(pts, ost.color, role, obj.cell)]
    w, h = 0.64 * c * scale, 0.24 * c * scale  # rect: a board
    return [Rect(cx - w / 2, cy - h / 2, w, h, ost.color, role, obj.cell)]


def scene_shapes(scene: Scene, cell_px: int = 48) -> tuple[Canvas, list[Shape]]:
    """All primitives of a frame, back to front."""
    lay = scene.layout
    cv = Canvas(lay.width, lay.height, cell_px)
    c = cell_px
    W, H = cv.size
    shapes: list[Shape] = [Rect(0, 0, W, H, st.BACKGROUND, "background")]

    for pos, (name, cells) in enumerate(lay.cell_sets):
        cs = st.cell_style(name, pos)
        role = f"cell:{name}"
        for cell in sorted(cells):
            if cs.shape == "fill":
                ox, oy = cv.origin(cell)
                shapes.append(Rect(ox, oy, c, c, cs.color, role, cell))
            elif cs.shape == "square":
                x0, y0 = cv.at(cell, 0.2, 0.2)
                shapes.append(Rect(x0, y0, 0.6 * c, 0.6 * c, cs.color, role, cell))
            elif cs.shape == "ring":
                cx, cy = cv.at(cell, 0.5, 0.5)
                shapes.append(
                    Circle(cx, cy, 0.3 * c, None, role, cell, cs.color, max(2.0, 0.1 * c))
                )
            else:  # dots
                for fx, fy in ((0.3, 0.3), (0.7, 0.3), (0.3, 0.7), (0.7, 0.7)):
                    cx, cy = cv.at(cell, fx, fy)
                    shapes.append(Circle(cx, cy, 0.08 * c, cs.color, role, cell))

    if lay.goal is not None:
        if lay.goal_is_destination:
            cargo_style = st.object_style(lay.cargo or "cargo", "cargo")
            x0, y0 = cv.at(lay.goal, 0.3, 0.3)
            shapes.append(Rect(x0, y0, 0.4 * c, 0.4 * c, cargo_style.color, "goal", lay.goal))
        else:
            ox, oy = cv.origin(lay.goal)
            shapes.append(Rect(ox, oy, c, c, st.GOAL_COLOR, "goal", lay.goal))

    for cell in sorted(lay.walls):
        ox, oy = cv.origin(cell)
        shapes.append(Rect(ox, oy, c, c, st.WALL_COLOR, "wall", cell))

    grid_w = 1.0
    for i in range(lay.width + 1):
        shapes.append(Line(((i * c, 0), (i * c, H - 1)), st.GRID_COLOR, grid_w, "grid"))
    for j in range(lay.height + 1):
        shapes.append(Line(((0, j * c), (W - 1, j * c)), st.GRID_COLOR, grid_w, "grid"))

    if scene.trail:
        pts = tuple(cv.at(cell, 0.5, 0.5) for cell in scene.trail)
        if len(pts) > 1:
            shapes.append(Line(pts, st.TRAIL_COLOR, max(1.0, c / 24), "trail-line"))
        first = scene.trail[0]
        x0, y0 = cv.at(first, 0.3, 0.5)
        x1, _ = cv.at(first, 0.7, 0.5)
        shapes.append(
            Line(((x0, y0), (x1, y0)), st.TRAIL_COLOR, max(2.0, c / 12), "trail-start", first)
        )
        for cell in scene.trail[1:]:
            cx, cy = cv.at(cell, 0.5, 0.5)
            shapes.append(Circle(cx, cy, max(2.0, 0.07 * c), st.TRAIL_COLOR, "trail", cell))

    n_cargo = n_cons = 0
    for obj in scene.objects:
        pos = n_cargo if obj.kind == "cargo" else n_cons
        ost = st.object_style(obj.name, obj.kind, pos)
        if obj.kind == "cargo":
            n_cargo += 1
        else:
            n_cons += 1
        if obj.cell is None:
            continue
        corner = "tr" if obj.carried else ("bl" if obj.cell == scene.agent else None)
        shapes.extend(_object_shapes(cv, obj, ost, corner))

    tri = (
        cv.at(scene.agent, 0.5, 0.18),
        cv.at(scene.agent, 0.18, 0.82),
        cv.at(scene.agent, 0.82, 0.82),
    )
    shapes.append(Polygon(tri, st.AGENT_COLOR, "agent", scene.agent))
    if scene.mark is not None:
        shapes.extend(_mark_shapes(cv, scene))
    return cv, shapes


def _mark_shapes(cv: Canvas, scene: Scene) -> list[Shape]:
    """An `exit` (a square frame round the agent: it left the grid there) or a `stay` (a
    ring: it waited), plus the action's label in the cell's top-left corner."""
    assert scene.mark is not None
    c = cv.cell_px
    cell, mark = scene.agent, scene.mark
    role = f"action:{mark.name}"
    color = st.EXIT_COLOR if mark.effect == "exit" else st.STAY_COLOR
    width = max(2.0, 0.08 * c)
    if mark.effect == "exit":
        x0, y0 = cv.at(cell, 0.06, 0.06)
        shape: Shape = Rect(x0, y0, 0.88 * c, 0.88 * c, None, role, cell, color, width)
    else:
        cx, cy = cv.at(cell, 0.5, 0.5)
        shape = Circle(cx, cy, 0.42 * c, None, role, cell, color, width)
    x, y = cv.at(cell, 0.08, 0.02)
    return [shape, Text(x, y, mark.label, color, max(8.0, 0.22 * c), "action-label", cell)]
