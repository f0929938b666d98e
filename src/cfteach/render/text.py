"""One character per cell, for terminals, logs, Gymnasium's `ansi` mode and `teach --show`.

Top row is y = height (y up, as in the domain files). Priority inside a cell: agent, then
objects, then the goal, then the trail, then walls and static cell sets. `legend()` explains
the characters of a layout.
"""

from __future__ import annotations

from cfteach.render import style as st
from cfteach.render.scene import Layout, Scene

_ANSI = {
    "agent": "\x1b[1;34m",
    "object": "\x1b[35m",
    "goal": "\x1b[1;37m",
    "trail": "\x1b[90m",
    "wall": "\x1b[90m",
    "cell": "\x1b[33m",
    "reset": "\x1b[0m",
}


def _grid(scene: Scene) -> list[list[tuple[str, str]]]:
    lay = scene.layout
    grid = [[(st.EMPTY_CHAR, "")] * lay.width for _ in range(lay.height)]

    def put(cell: tuple[int, int], char: str, kind: str) -> None:
        x, y = cell
        grid[lay.height - y][x - 1] = (char, kind)

    for pos, (name, cells) in enumerate(lay.cell_sets):
        ch = st.cell_style(name, pos).char
        for cell in cells:
            put(cell, ch, "cell")
    for cell in lay.walls:
        put(cell, st.CELL_STYLES["walls"].char, "wall")
    for cell in scene.trail:
        put(cell, st.TRAIL_CHAR, "trail")
    if lay.goal is not None:
        put(lay.goal, st.DESTINATION_CHAR if lay.goal_is_destination else st.GOAL_CHAR, "goal")
    n = {"cargo": 0, "consumable": 0}
    for obj in scene.objects:
        ost = st.object_style(obj.name, obj.kind, n[obj.kind])
        n[obj.kind] += 1
        if obj.cell is not None and not obj.carried:
            put(obj.cell, ost.char, "object")
    put(scene.agent, st.AGENT_CARRYING_CHAR if scene.carrying else st.AGENT_CHAR, "agent")
    return grid


def to_text(scene: Scene, *, color: bool = False, border: bool = True) -> str:
    """The scene as lines of text; `color=True` adds ANSI colour codes for terminals."""
    rows = []
    for row in _grid(scene):
        if color:
            line = "".join(f"{_ANSI[k]}{c}{_ANSI['reset']}" if k else c for c, k in row)
        else:
            line = "".join(c for c, _ in row)
        rows.append(f"|{line}|" if border else line)
    if border:
        edge = "+" + "-" * scene.layout.width + "+"
        rows = [edge, *rows, edge]
    return "\n".join(rows)


def legend(layout: Layout) -> str:
    """A one-line key to the characters `to_text` uses for this layout."""
    parts = [f"{st.AGENT_CHAR} agent"]
    if layout.cargo is not None:
        parts.append(f"{st.AGENT_CARRYING_CHAR} agent carrying {layout.cargo}")
        parts.append(f"{st.object_style(layout.cargo, 'cargo').char} {layout.cargo}")
    for pos, (name, _) in enumerate(layout.consumables):
        parts.append(f"{st.object_style(name, 'consumable', pos).char} {name}")
    if layout.goal is not None:
        parts.append(
            f"{st.DESTINATION_CHAR} destination"
            if layout.goal_is_destination
            else f"{st.GOAL_CHAR} goal"
        )
    if layout.walls:
        parts.append(f"{st.CELL_STYLES['walls'].char} wall")
    for pos, (name, _) in enumerate(layout.cell_sets):
        parts.append(f"{st.cell_style(name, pos).char} {name}")
    parts.append(f"{st.TRAIL_CHAR} trail")
    return ", ".join(parts)
