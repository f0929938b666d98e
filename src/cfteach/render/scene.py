"""What is on the grid, independent of how it is drawn.

A `Layout` is the static part of one instance (size, walls, named cell sets, goal, where the
objects live); a `Scene` adds one state (agent, objects, trail). Both are plain data so every
renderer (SVG, raster, text) draws the same thing, and tests can build them by hand. The
dynamic part is read from a state's JSON form (docs/schemas.md), which is the same for
built-in and user domains: `agent`, the cargo's name -> `[x, y] | null`, `carrying`, and each
consumable's name -> `bool`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

Cell = tuple[int, int]


@dataclass(frozen=True)
class Layout:
    """The static picture of one instance. Coordinates are 1-based `(x, y)`, y up."""

    width: int
    height: int
    walls: frozenset[Cell] = frozenset()
    cell_sets: tuple[tuple[str, frozenset[Cell]], ...] = ()
    goal: Cell | None = None
    goal_is_destination: bool = False
    cargo: str | None = None
    consumables: tuple[tuple[str, Cell], ...] = ()
    title: str = ""

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise ValueError(f"layout size must be positive, got {self.width}x{self.height}")
        named = [("walls", self.walls), *self.cell_sets]
        if self.goal is not None:
            named.append(("goal", frozenset([self.goal])))
        named.extend((name, frozenset([cell])) for name, cell in self.consumables)
        for name, cells in named:
            for cell in cells:
                self.check_cell(cell, name)

    def check_cell(self, cell: Sequence[int], what: str) -> Cell:
        """Return `cell` as a tuple, or raise a ValueError naming `what` if it is off the grid."""
        if len(cell) != 2:
            raise ValueError(f"{what}: a cell is [x, y], got {list(cell)!r}")
        x, y = int(cell[0]), int(cell[1])
        if not (1 <= x <= self.width and 1 <= y <= self.height):
            raise ValueError(
                f"{what}: cell [{x}, {y}] is off the {self.width}x{self.height} grid "
                "(coordinates are 1-based)"
            )
        return (x, y)


@dataclass(frozen=True)
class SceneObject:
    """A cargo or consumable as it is in one state (`cell` None: not present)."""

    name: str
    kind: str  # "cargo" | "consumable"
    cell: Cell | None
    carried: bool = False


#: Effects of actions that a picture cannot show by the agent's position (the agent stays
#: where it is), so a frame reached by one of them carries a marker and the action's label.
MARKED_EFFECTS = ("exit", "stay")


@dataclass(frozen=True)
class ActionMark:
    """The action that led to a frame, when the picture alone would not show it."""

    name: str
    label: str
    effect: str  # one of MARKED_EFFECTS


@dataclass(frozen=True)
class Scene:
    """A layout plus one state: what a single frame shows."""

    layout: Layout
    agent: Cell
    objects: tuple[SceneObject, ...] = ()
    trail: tuple[Cell, ...] = field(default=())
    done: bool = False
    mark: ActionMark | None = None

    @property
    def carrying(self) -> bool:
        return any(o.carried for o in self.objects)


def action_mark(name: str, action_specs: Iterable[Any] = ()) -> ActionMark | None:
    """The marker for action `name` given the domain's `ActionSpec`s (built-ins by default);
    None for actions the picture shows by itself (moves, pick-up, drop)."""
    from cfteach.domains.spec import BUILTIN_ACTIONS

    specs = {s.name: s for s in action_specs} or BUILTIN_ACTIONS
    spec = specs.get(name)
    if spec is None or spec.effect not in MARKED_EFFECTS:
        return None
    return ActionMark(spec.name, spec.label, spec.effect)


def scene_from_state_json(
    layout: Layout,
    state: Mapping[str, Any],
    trail: Iterable[Sequence[int]] = (),
    *,
    done: bool = False,
) -> Scene:
    """Combine a layout with a state in its JSON form; bad states get a clear ValueError."""
    if "agent" not in state:
        raise ValueError(f"state has no 'agent' key: {dict(state)!r}")
    agent = layout.check_cell(state["agent"], "state.agent")
    objects: list[SceneObject] = []
    carrying = bool(state.get("carrying", False))
    if layout.cargo is not None:
        pos = state.get(layout.cargo)
        cell = None if pos is None else layout.check_cell(pos, f"state.{layout.cargo}")
        if carrying and cell is None:
            raise ValueError(f"state says carrying but {layout.cargo!r} is null")
        objects.append(SceneObject(layout.cargo, "cargo", agent if carrying else cell, carrying))
    for name, cell in layout.consumables:
        present = state.get(name, True)
        if not isinstance(present, bool):
            raise ValueError(f"state.{name} must be true/false, got {present!r}")
        objects.append(SceneObject(name, "consumable", cell if present else None))
    trail_cells = tuple(layout.check_cell(c, "trail") for c in trail)
    return Scene(layout, agent, tuple(objects), trail_cells, done)


def trail_of(states: Sequence[Mapping[str, Any]]) -> list[Cell]:
    """The agent's cells along a list of JSON states, consecutive repeats removed."""
    cells: list[Cell] = []
    for s in states:
        c = (int(s["agent"][0]), int(s["agent"][1]))
        if not cells or cells[-1] != c:
            cells.append(c)
    return cells
